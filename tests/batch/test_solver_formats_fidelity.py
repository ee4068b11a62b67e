"""Every format writes what it read (docs/engineers.md): SU2 marker names and records, Gmsh
names, version, encoding and $Periodic pairs, sections that would be lost refused,
conversions that work or are refused before any writing, meshio's own reasons as one line,
volume cells and periodic pairs held, Abaqus node sets as groups. Written files are checked
with the small SU2 and Gmsh 2.2 ASCII parsers of tests/solver_parsers.py, not with meshio;
meshio's own test meshes are read in place from build/meshio_sdist when that folder holds
them."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from eegt_blender.fileio import solver_mesh
from eegt_blender.fileio.solver_mesh import SolverMeshError
from solver_meshes import CHANNEL_TRIANGLES, channel_msh, every_format
from solver_parsers import parse_msh22, parse_su2

pytest.importorskip("meshio", reason="meshio is not installed")

ROOT = Path(__file__).resolve().parents[2]
MESHIO_MESHES = ROOT / "build" / "meshio_sdist" / "meshio-5.3.5" / "tests" / "meshes"
NUMPY2_PYTHON = "EEGT_NUMPY2_PYTHON"


# files ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("fidelity")
    msh = channel_msh(folder / "channel.msh")
    out = {"msh41": msh, "msh22": channel_msh(folder / "channel22.msh", "2.2")}
    out.update(every_format(msh, folder))
    out["periodic22"] = periodic_msh(folder / "periodic22.msh", "2.2")
    out["periodic41"] = periodic_msh(folder / "periodic41.msh", "4.1")
    return out


def periodic_msh(path: Path, version: str) -> Path:
    """A 2 x 1 rectangle meshed by Gmsh, its right side periodic with its left."""
    gmsh = pytest.importorskip("gmsh", reason="the gmsh package is not installed")
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("periodic")
        occ = gmsh.model.occ
        rect = occ.addRectangle(0, 0, 0, 2, 1)
        occ.synchronize()
        sides = {}
        for _, tag in gmsh.model.getBoundary([(2, rect)], oriented=False):
            x, y, _ = occ.getCenterOfMass(1, abs(tag))
            sides["left" if x < 1e-9 else "right" if x > 2 - 1e-9 else
                  "bottom" if y < 0.5 else "top"] = abs(tag)
        gmsh.model.mesh.setPeriodic(1, [sides["right"]], [sides["left"]],
                                    [1, 0, 0, 2, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1])
        for name, tag in sides.items():
            gmsh.model.addPhysicalGroup(1, [tag], name=name)
        gmsh.model.addPhysicalGroup(2, [rect], name="domain")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.25)
        gmsh.model.mesh.generate(2)
        gmsh.option.setNumber("Mesh.MshFileVersion", float(version))
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


def meshio_mesh(rel: str) -> Path:
    path = MESHIO_MESHES / rel
    if not path.is_file():
        pytest.skip(f"meshio's test mesh {path} is absent (`pip download meshio==5.3.5 "
                    "--no-deps --no-binary :all:` and unpack it in build/meshio_sdist)")
    return path


# SU2 ----------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["su2/square.su2", "su2/mixgrid.su2"])
def test_su2_written_back_keeps_markers_elements_and_points(tmp_path, name):
    src = meshio_mesh(name)
    a = parse_su2(src)
    if a["ndime"] == 3:  # 3D files: nothing to untangle, but the records come back
        mesh, layout = solver_mesh.su2.read(str(src))
        out = tmp_path / "back.su2"
        solver_mesh.su2.write(str(out), mesh, layout)
    else:
        sm = solver_mesh.read(str(src))
        assert sm.group_names()[:4] == ["lower", "right", "upper", "left"]
        out = tmp_path / "back.su2"
        solver_mesh.write(sm, str(out))
    b = parse_su2(out)
    assert b == a


def test_su2_markers_are_groups_by_name(files, tmp_path):
    sm = solver_mesh.read(str(meshio_mesh("su2/square.su2")))
    lower = sm.group_nodes("lower")
    assert np.all(sm.points3d()[lower, 1] == 0.0) and lower.sum() == 3
    assert np.array_equal(lower, sm.group_nodes("1"))  # the marker's tag still works
    ch = solver_mesh.node_choice(sm, "free", np.zeros(sm.n_points, bool),
                                 fixed_groups=("left",))
    assert np.array_equal(ch.pinned, sm.group_nodes("left"))


def test_su2_from_gmsh_names_its_markers(files, tmp_path):
    sm = solver_mesh.read(str(files["msh41"]))
    out = tmp_path / "c.su2"
    assert solver_mesh.can_write(sm, "su2") is None
    solver_mesh.write(sm, str(out))
    p = parse_su2(out)
    assert [m for m, _ in p["markers"]] == ["cylinder", "walls", "inlet", "outlet"]
    assert p["ndime"] == 2 and len(p["elems"]) == sm.n_faces
    assert np.array_equal(np.array(p["points"]), sm.points3d()[:, :2])
    back = solver_mesh.read(str(out))
    assert np.array_equal(back.group_nodes("cylinder"), sm.group_nodes("cylinder"))



def test_su2_whose_triangles_carry_a_tag_writes_them_as_its_elements(files):
    # every_format's SU2 file gives every cell its Gmsh physical tag, the triangles too
    p = parse_su2(files["su2"])
    assert p["ndime"] == 2 and len(p["elems"]) == CHANNEL_TRIANGLES
    assert [m for m, _ in p["markers"]] == ["4", "1", "2", "3"]


# Gmsh ---------------------------------------------------------------------------------

def test_gmsh22_ascii_with_point_data_reads_back(files, tmp_path):
    import meshio

    src = tmp_path / "data22.msh"
    m = meshio.read(files["msh22"])
    m.point_data["temperature"] = m.points[:, 0] * 3.0
    meshio.gmsh.write(str(src), m, "2.2", binary=False)
    sm = solver_mesh.read(str(src))
    moved = np.zeros(sm.n_points, bool)
    moved[sm.corners[::7]] = True
    new = sm.points3d() + 1e-3
    out = tmp_path / "out22.msh"
    solver_mesh.write(sm, str(out), new, moved)
    a, b = parse_msh22(src), parse_msh22(out)
    assert b["format"] == ["2.2", "0"] and b["names"] == a["names"]
    assert b["elements"] == a["elements"] and b["sections"] == a["sections"]
    want = sm.points3d()
    want[moved] = new[moved]
    assert np.array_equal(np.array([b["nodes"][k] for k in sorted(b["nodes"])]), want)
    assert b["nodedata"] == a["nodedata"]


@pytest.mark.parametrize("version", ["22", "41"])
def test_gmsh_periodic_pairs_are_held_and_kept(files, tmp_path, version):
    sm = solver_mesh.read(str(files[f"periodic{version}"]))
    pairs = sm.periodic_nodes()
    pts = sm.points3d()
    assert len(pairs) >= 3
    assert np.allclose(pts[pairs[:, 0], 0] - pts[pairs[:, 1], 0], 2.0)
    ch = solver_mesh.node_choice(sm, "free", np.zeros(sm.n_points, bool))
    assert ch.pinned[pairs.ravel()].all() and "$Periodic" in ch.notes[0]
    out = tmp_path / "o.msh"
    solver_mesh.write(sm, str(out), pts + 1e-3, ~ch.pinned)
    back = solver_mesh.read(str(out))
    assert np.array_equal(back.periodic_nodes(), pairs)
    bp = back.points3d()
    assert np.array_equal(bp[pairs.ravel()], pts[pairs.ravel()])
    if version == "22":
        assert len(parse_msh22(out)["periodic"]) == len(pairs)
    why = solver_mesh.can_write(sm, "vtu", "o.vtu")
    assert why is not None and "$Periodic" in why and "'o.vtu'" in why


def test_gmsh_section_meshio_drops_is_refused(files, tmp_path):
    text = files["msh22"].read_text()
    bad = tmp_path / "interp.msh"
    bad.write_text(text + "$InterpolationScheme\n\"s\"\n0\n$EndInterpolationScheme\n")
    with pytest.raises(SolverMeshError, match=r"interp\.msh.*\$InterpolationScheme section"):
        solver_mesh.read(str(bad))


@pytest.mark.parametrize("rel", ["msh/insulated-2.2.msh", "msh/insulated-4.1.msh"])
def test_meshio_gmsh_files_round_trip(tmp_path, rel):
    src = meshio_mesh(rel)
    sm = solver_mesh.read(str(src))
    assert "insulation" in sm.group_names()
    out = tmp_path / "o.msh"
    solver_mesh.write(sm, str(out))
    head = [f.read_text().split("\n")[1].split()[:2] for f in (src, out)]
    assert head[0] == head[1]
    if rel.endswith("2.2.msh"):
        a, b = parse_msh22(src), parse_msh22(out)
        assert (b["names"], b["elements"], b["nodes"]) == (a["names"], a["elements"], a["nodes"])


# conversions and reasons ---------------------------------------------------------------

# .inp with node sets -> .msh is refused (tests/fileio/test_solver_write_keeps.py)
CONVERSIONS = [("msh41", "su2"), ("vtu", "su2"), ("msh41", "mesh"), ("msh41", "inp"),
               ("vtu", "msh"), ("su2", "msh"), ("mesh", "msh"), ("inp", "su2")]


@pytest.mark.parametrize(("src", "dst"), CONVERSIONS)
def test_conversions_work(files, tmp_path, src, dst):
    sm = solver_mesh.read(str(files[src]))
    assert solver_mesh.can_write(sm, dst) is None
    out = tmp_path / f"o.{dst}"
    solver_mesh.write(sm, str(out))
    assert solver_mesh.check_written(sm, str(out)) is None
    back = solver_mesh.read(str(out))
    assert np.array_equal(back.points3d(), sm.points3d())
    if dst == "msh":
        p = parse_msh22(out)
        assert sum(len(e[2]) == 3 for e in p["elements"]) == sm.n_faces
    if dst == "su2":
        assert len(parse_su2(out)["elems"]) == sm.n_faces


def test_refusals_are_one_line_with_the_users_path(files, tmp_path):
    import meshio

    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.5]])
    src = tmp_path / "v.vtu"
    meshio.write(src, meshio.Mesh(pts, [("triangle", [[0, 1, 2], [1, 3, 2]]),
                                        ("vertex", [[0]])],
                                  point_data={"uv": pts[:, :2]}))
    sm = solver_mesh.read(str(src))
    for fmt, why in (("su2", "no element type for vertex"),
                     ("msh", "Gmsh only permits 1, 3, or 9 components")):
        got = solver_mesh.can_write(sm, fmt, f"/x/out.{fmt}")
        assert got is not None and why in got and f"'/x/out.{fmt}'" in got, got
        assert "eegt-can-write" not in got and "\n" not in got
    bad = tmp_path / "bad.inp"
    bad.write_text("*NODE\n1, 0, 0\n*ELEMENT, TYPE=NOPE\n1, 1\n")
    why = solver_mesh.check_written(sm, str(bad))  # meshio exits on it: a reason here
    assert why and why.startswith("the written file does not read back")


# volume cells and node sets ------------------------------------------------------------

def test_volume_cells_hold_their_nodes_and_inversions_are_counted(tmp_path):
    import meshio

    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1.0]])
    src = tmp_path / "mixed.vtu"
    meshio.write(src, meshio.Mesh(pts, [("triangle", [[0, 1, 2], [1, 3, 2]]),
                                        ("tetra", [[0, 1, 2, 4]])]))
    sm = solver_mesh.read(str(src))
    ch = solver_mesh.node_choice(sm, "free", np.zeros(sm.n_points, bool))
    assert np.array_equal(ch.pinned, [True, True, True, False, True])
    assert any("4 nodes shared with volume cells held" in n for n in ch.notes)
    moved = pts.copy()
    assert solver_mesh.volume_cells_inverted(sm, moved) == 0
    moved[4, 2] = -1.0  # through the base: inverted
    assert solver_mesh.volume_cells_inverted(sm, moved) == 1
    moved[4, 2] = 0.0  # flat
    assert solver_mesh.volume_cells_inverted(sm, moved[:, :3]) == 1


def test_abaqus_node_sets_are_groups(files):
    sm = solver_mesh.read(str(files["inp"]))
    left = sm.group_nodes("left")
    assert left.sum() >= 3 and np.all(sm.points3d()[left, 0] < 1e-9)
    assert "left" in sm.group_names() and "left" not in sm.face_groups()
    ch = solver_mesh.node_choice(sm, "free", np.zeros(sm.n_points, bool),
                                 fixed_groups=("left",))
    assert np.array_equal(ch.pinned, left)


# NumPy 2 -------------------------------------------------------------------------------

CHILD = r"""
import json, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from checkout_package import register
register()
from eegt_blender.fileio import solver_mesh
out = {"numpy": np.__version__}
for src, dst in zip(sys.argv[2::2], sys.argv[3::2]):
    sm = solver_mesh.read(src)
    solver_mesh.write(sm, dst)
    out[dst] = solver_mesh.check_written(sm, dst)
print(json.dumps(out))
"""


def test_writes_read_back_under_numpy_2(files, tmp_path):
    """The Gmsh ASCII writes (2.2 and 4.1 with point data) and the SU2 and conversion
    writes under NumPy >= 2 (meshio 5.3 wrote np.float64(...) into Gmsh ASCII data)."""
    other = os.environ.get(NUMPY2_PYTHON) or str(ROOT / "build" / "numpy2" / "bin" / "python")
    if not Path(other).exists():
        pytest.skip(f"no NumPy 2 interpreter ({NUMPY2_PYTHON} unset, `make numpy2` builds "
                    "build/numpy2)")
    if subprocess.run([other, "-c", "import meshio"], capture_output=True).returncode:
        pytest.skip(f"{other} has no meshio (`{Path(other).parent}/pip install meshio`)")
    import meshio

    jobs = []
    for version in ("2.2", "4.1"):
        m = meshio.read(files["msh22"])
        m.point_data["temperature"] = m.points[:, 0] * 3.0
        if version == "4.1":
            m = meshio.read(files["msh41"])
            m.point_data["temperature"] = m.points[:, 0] * 3.0
        src = tmp_path / f"data{version}.msh"
        meshio.gmsh.write(str(src), m, version, binary=False)
        jobs += [str(src), str(tmp_path / f"out{version}.msh")]
    jobs += [str(files["su2"]), str(tmp_path / "out.su2"), str(files["vtu"]),
             str(tmp_path / "conv.msh"), str(files["msh41"]), str(tmp_path / "conv.su2")]
    done = subprocess.run([other, "-c", CHILD, str(ROOT / "tests"), *jobs],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    res = json.loads(done.stdout.strip().splitlines()[-1])
    assert int(res.pop("numpy").split(".")[0]) >= 2
    assert res == {k: None for k in jobs[1::2]}
    a, b = parse_msh22(Path(jobs[0])), parse_msh22(Path(jobs[1]))
    assert b["nodedata"] == a["nodedata"] and b["nodes"] == a["nodes"]
