"""The command's solver path on real public meshes (SU2 tutorials, gmsh's own benchmarks,
meshio's, scikit-fem's, SfePy's and Mmg's example meshes), fetched, not generated:
``python scripts/fetch_public_meshes.py`` puts them under build/public_meshes (git-ignored);
without them every test here skips with that one reason.

Each file is run as a user would (``eegt FILE -o OUT.EXT``) and checked on what was written:
read back, the same points and cells, only free interior nodes changed (every other node
keeps its bits), the same groups with the same nodes, the same point and cell data, SU2
markers (names, order, records) and Gmsh 2.2 ASCII names and element tags by the independent
parsers of tests/solver_parsers.py, the exit code as documented (0: valid at the end; 3: not;
2: refused before the run with one line, nothing written). Files whose element nodes run
clockwise, all or some (FEM meshes), run too: the report's note says how many faces were read
clockwise, and the written cells keep the file's own node order. docs/engineers.md's table
*Checked on public files* lists the files and what they gave."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from solver_parsers import parse_msh22, parse_su2

meshio = pytest.importorskip("meshio", reason="meshio is not installed")

ROOT = Path(__file__).resolve().parents[2]
PUBLIC = ROOT / "build" / "public_meshes"
sys.path.insert(0, str(ROOT / "scripts"))
try:
    from fetch_public_meshes import MESHES, local_name
finally:
    sys.path.pop(0)

# file (OWNER+NAME/PATH) -> the exit-2 line's words, for the files the command refuses
ZERO_AREA = "mesh has zero total area"  # closed surfaces and volume meshes' skins
NOTHING_MOVES = "every node is pinned or on the fixed boundary"
REFUSED = {
    "nschloe+meshio/tests/meshes/su2/mixgrid.su2": ZERO_AREA,
    "live-clones+gmsh/benchmarks/misc/partitions.msh":
        "its elements carry 3 tags (physical, elementary and 1 more",
    "live-clones+gmsh/benchmarks/misc/multimodel23.msh": NOTHING_MOVES,  # 2 faces, 1 clockwise
    "live-clones+gmsh/benchmarks/misc/interpolation_scheme2.msh":
        "its $InterpolationScheme section would be lost",
    "live-clones+gmsh/benchmarks/misc/adaptive_tri6.msh": "its elements carry 3 tags",
    "live-clones+gmsh/benchmarks/3d/CubeAniso2D.msh": ZERO_AREA,  # a cube's skin, mixed
    "MmgTools+mmg/libexamples/mmg3d/io_generic_and_get_adja/cube.msh": ZERO_AREA,
    "MmgTools+mmg/libexamples/mmg3d/io_generic_and_get_adja/cube.vtu": ZERO_AREA,
    "nschloe+meshio/tests/meshes/vtu/00_raw_binary.vtu": "volume cells only",
    "nschloe+meshio/tests/meshes/vtu/02_raw_compressed.vtu": "volume cells only",
    "sfepy+sfepy/meshes/various_formats/small2d.vtk": NOTHING_MOVES,
    "nschloe+meshio/tests/meshes/vtk/gh-935.vtk": NOTHING_MOVES,
    "nschloe+meshio/tests/meshes/vtk/rbc_001.vtk": ZERO_AREA,
    "sfepy+sfepy/meshes/various_formats/abaqus_hex.inp": "volume cells only",
    "nschloe+meshio/tests/meshes/abaqus/element_elset.inp": NOTHING_MOVES,  # 2 faces, 1 clockwise
    "MmgTools+mmg/libexamples/mmg2d/adaptation_example0/example0_a/init.mesh":
        "Unknown keyword 'RequiredEdges'",
    "nschloe+meshio/tests/meshes/medit/cube86.mesh": ZERO_AREA,
}
# file -> faces read clockwise, for the files that run and have any (the report's note)
CLOCKWISE = {
    "su2code+Tutorials/multiphysics/steady_fsi/mesh_cantilever.su2": 1000,  # all of them
    "su2code+Tutorials/multiphysics/contact_resistance_cht/solid_mesh_1.su2": 1521,  # all
    "su2code+TestCases/aeroelastic/mesh_NACA64A010_hybrid_inv.su2": 9313,  # all
    "su2code+TestCases/harmonic_balance/hb_rans_preconditioning/n64a010_turb.su2": 12288,  # all
    "su2code+TestCases/disc_adj_rans/cylinder/mesh_cylinder.su2": 3061,  # of 3783
    "su2code+TestCases/deformation/naca4412/mesh_NACA4412_turb.su2": 767,  # of 60398
    "kinnala+scikit-fem/docs/examples/meshes/oriented_squares.msh": 250,  # of 266
    "kinnala+scikit-fem/docs/examples/meshes/backward-facing_step.vtu": 1925,  # of 4218
    "sfepy+sfepy/meshes/2d/helmholtz_apartment.vtk": 524,  # of 752
    "kinnala+scikit-fem/docs/examples/meshes/troublesome_mesh.vtk": 724,  # all
}
FILES = [local_name(repo, path) for (repo, _), path, _ in MESHES]


@pytest.fixture(scope="module")
def public() -> Path:
    if not (PUBLIC / "manifest.json").is_file():
        pytest.skip("no public meshes in build/public_meshes (run `python "
                    "scripts/fetch_public_meshes.py`)")
    return PUBLIC


@pytest.fixture
def cli(ext):
    return ext.operators.command.cli


def _movable(ext, sm) -> np.ndarray:
    """(N,) bool: the nodes a run with the default flags may move (free interior nodes of
    the faces, none the file holds; whatever way round the file's faces run)."""
    core = ext.core
    fs = core.faces_from_csr(sm.offsets[:-1], sm.counts(), sm.corners, sm.n_points)
    on_boundary = core.boundary_nodes(sm.n_points, fs)
    choice = ext.fileio.solver_mesh.node_choice(sm, "fixed", on_boundary)
    return fs.used_nodes(sm.n_points) & ~on_boundary & ~choice.pinned


def _same_arrays(a: dict, b: dict) -> bool:
    if list(a) != list(b):
        return False
    for k in a:
        x, y = a[k], b[k]
        pairs = zip(x, y) if isinstance(x, list) else [(x, y)]
        if isinstance(x, list) and len(x) != len(y):
            return False
        for u, v in pairs:  # a legacy VTK one-component array comes back as (n,)
            u, v = (np.asarray(w).reshape(len(w), -1) for w in (u, v))
            if u.shape != v.shape or not np.array_equal(u, v):
                return False
    return True


def _cells_by_type(mesh) -> dict[str, np.ndarray]:
    out: dict[str, list] = {}
    for b in mesh.cells:
        out.setdefault(b.type, []).append(np.asarray(b.data, dtype=np.int64))
    return {k: np.concatenate(v) for k, v in out.items()}


@pytest.mark.parametrize("name", FILES)
def test_public_mesh_through_the_command(bpy, ext, cli, public, tmp_path, capfd, name):
    src = public / name
    out = tmp_path / ("out" + src.suffix)
    rep_path = tmp_path / "report.json"
    capfd.readouterr()
    code, _ = cli.run([str(src), "-o", str(out), "--report", str(rep_path), "--quiet"])
    err = [ln for ln in capfd.readouterr().err.splitlines() if ln.strip()]
    rep = json.loads(rep_path.read_text())
    if name in REFUSED:
        assert code == 2, (code, err)
        assert len(err) == 1 and REFUSED[name] in err[0], err
        assert f"'{src}'" in err[0] or f"output '{out}'" in err[0], err
        assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == [
            "report.json"]
        return
    assert code in (0, 3), (code, err)
    assert rep["solver_mesh"]["clockwise_faces"] == CLOCKWISE.get(name, 0)
    noted = [n for n in rep["solver_mesh"]["notes"] if "read clockwise" in n]
    assert len(noted) == (1 if name in CLOCKWISE else 0), rep["solver_mesh"]["notes"]
    assert not noted or (f"{CLOCKWISE[name]} " in noted[0] and "own node order" in noted[0])
    entry = rep["objects"][0]
    assert code == (0 if entry["after"]["n_inverted"] == 0 else 3), entry
    assert entry["after"]["n_inverted"] <= entry["before"]["n_inverted"], entry

    sm_mod = ext.fileio.solver_mesh
    a, b = sm_mod.read(str(src)), sm_mod.read(str(out))
    assert b.n_points == a.n_points and b.options == a.options
    pa, pb = np.asarray(a.mesh.points), np.asarray(b.mesh.points)
    assert pa.shape == pb.shape
    changed = (pa != pb).any(axis=1)
    assert not (changed & ~_movable(ext, a)).any(), "a node the run must hold changed"
    ca, cb = _cells_by_type(a.mesh), _cells_by_type(b.mesh)
    assert list(ca) == list(cb) and all(np.array_equal(ca[k], cb[k]) for k in ca)
    assert b.group_names() == a.group_names()
    for g in a.group_names():
        assert np.array_equal(b.group_nodes(g), a.group_nodes(g)), g
    assert _same_arrays(a.mesh.point_data, b.mesh.point_data)
    assert _same_arrays(a.mesh.cell_data, b.mesh.cell_data)
    assert {k: np.asarray(v).tolist() for k, v in a.mesh.field_data.items()} == \
        {k: np.asarray(v).tolist() for k, v in b.mesh.field_data.items()}
    assert {k: np.asarray(v).ravel().tolist() for k, v in a.mesh.point_sets.items()} == \
        {k: np.asarray(v).ravel().tolist() for k, v in b.mesh.point_sets.items()}

    if src.suffix == ".su2":  # independent: marker names, order and records, element index
        x, y = parse_su2(src, index=True), parse_su2(out, index=True)
        assert y["ndime"] == x["ndime"] and y["markers"] == x["markers"]
        assert y["elems"] == x["elems"]
        keep = ~changed
        assert np.array_equal(np.array(y["points"])[keep], np.array(x["points"])[keep])
    head = src.read_bytes()[:64]
    if src.suffix == ".msh" and b"\n2" in head[:20] and b" 0 " in head[:24]:
        x, y = parse_msh22(src), parse_msh22(out)  # independent: names and element tags
        assert y["names"] == x["names"] and y["elements"] == x["elements"]
        assert y["sections"] == x["sections"]
        same = [k for k, v in x["nodes"].items() if y["nodes"][k] == v]
        assert len(same) == int(np.count_nonzero(~changed))
