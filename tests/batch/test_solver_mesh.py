"""Solver meshes through meshio without Blender: round trips through every format change only
the moved nodes' coordinates (every other array bit for bit), groups by name or tag, pin
fields, node choices, and bad files as one-line errors."""

from __future__ import annotations

import numpy as np
import pytest
from eegt_blender.fileio import solver_mesh
from eegt_blender.fileio.solver_mesh import SolverMeshError
from solver_meshes import (
    CHANNEL_NODES,
    CHANNEL_TRIANGLES,
    channel_msh,
    every_format,
    mesquite_vtk,
)

from core import boundary_nodes, faces_from_csr, quality, untangle_and_smooth

pytest.importorskip("meshio", reason="meshio is not installed")


def rows(a) -> np.ndarray:
    a = np.asarray(a)
    return a.reshape(a.shape[0], -1) if a.ndim else a


def assert_same_but_points(a, b, moved: np.ndarray, new: np.ndarray,
                           digits: int | None = None) -> None:
    """Every block, data array and group of meshio meshes `a` and `b` equal bit for bit
    (one-component arrays compared as columns: legacy VTK reads them back as (N,)); points
    equal except the `moved` rows, which are `new`'s (to `digits` significant digits when
    the writer keeps no more)."""
    expect = np.array(a.points, copy=True)
    expect[moved] = new[moved, :expect.shape[1]]
    assert b.points.dtype == a.points.dtype
    if digits is None:
        assert np.array_equal(b.points, expect)
    else:
        assert np.allclose(b.points, expect, rtol=10.0 ** (1 - digits), atol=1e-300)
        assert not np.array_equal(b.points, expect)  # the writer's limit, documented
    assert [c.type for c in a.cells] == [c.type for c in b.cells]
    for x, y in zip(a.cells, b.cells):
        assert np.array_equal(x.data, y.data)
    for mine, theirs in ((a.point_data, b.point_data), (a.field_data, b.field_data),
                         (a.point_sets, b.point_sets)):
        assert sorted(mine) == sorted(theirs)
        for k in mine:
            assert rows(mine[k]).dtype == rows(theirs[k]).dtype
            assert np.array_equal(rows(mine[k]), rows(theirs[k]))
    assert sorted(a.cell_data) == sorted(b.cell_data)
    for k in a.cell_data:
        for x, y in zip(a.cell_data[k], b.cell_data[k]):
            assert x.dtype == y.dtype and np.array_equal(x, y)
    assert sorted(a.cell_sets) == sorted(b.cell_sets)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("solver")
    msh = channel_msh(folder / "channel.msh")
    out = {"msh41": msh}
    for version, binary in (("2.2", False), ("2.2", True), ("4.1", True)):
        name = f"msh{version.replace('.', '')}{'b' if binary else ''}"
        out[name] = channel_msh(folder / f"{name}.msh", version, binary)
    out.update(every_format(msh, folder))
    return out


ALL = ("msh41", "msh22", "msh22b", "msh41b", "vtk", "vtk_ascii", "vtu", "vtu_ascii", "inp",
       "mesh", "su2")


@pytest.mark.parametrize("name", ALL)
def test_round_trip_changes_only_the_moved_nodes(files, tmp_path, name):
    src = files[name]
    sm = solver_mesh.read(str(src))
    assert (sm.n_points, sm.n_faces) == (CHANNEL_NODES, CHANNEL_TRIANGLES)
    moved = np.zeros(sm.n_points, dtype=bool)
    moved[sm.corners[::5]] = True
    new = sm.points3d() + np.array([1e-3, -2e-3, 0.0])
    out = tmp_path / ("out" + src.suffix)
    solver_mesh.write(sm, str(out), new, moved)
    back = solver_mesh.read(str(out))
    assert back.options == sm.options
    # meshio writes VTU ASCII floats with 12 significant digits (docs/engineers.md)
    assert_same_but_points(sm.mesh, back.mesh, moved, new, 12 if name == "vtu_ascii" else None)
    assert solver_mesh.check_written(sm, str(out)) is None


@pytest.mark.parametrize(("name", "head"), [("msh41", b"4.1 0 8"), ("msh22", b"2.2 0 8"),
                                            ("msh22b", b"2.2 1 8"), ("msh41b", b"4.1 1 8")])
def test_gmsh_version_and_encoding_are_kept(files, tmp_path, name, head):
    sm = solver_mesh.read(str(files[name]))
    out = tmp_path / "o.msh"
    solver_mesh.write(sm, str(out))
    assert out.read_bytes().split(b"\n")[1] == head


def test_vtu_ascii_stays_ascii_and_compressed_stays_compressed(files, tmp_path):
    for name, ascii_ in (("vtu_ascii", True), ("vtu", False)):
        sm = solver_mesh.read(str(files[name]))
        out = tmp_path / f"{name}.vtu"
        solver_mesh.write(sm, str(out))
        text = out.read_bytes()
        assert (b'format="ascii"' in text) is ascii_
        assert (b"vtkZLibDataCompressor" in text) is not ascii_


def test_groups_by_name_and_by_tag(files):
    sm = solver_mesh.read(str(files["msh41"]))
    cyl = sm.group_nodes("cylinder")
    assert np.array_equal(cyl, sm.group_nodes("4"))  # the fourth physical group
    pts = sm.points3d()
    r = np.hypot(pts[cyl, 0] - 1.08, pts[cyl, 1] - 0.5)
    assert cyl.sum() >= 10 and np.allclose(r, 0.2, atol=1e-9)
    inlet = sm.group_nodes("inlet")
    assert np.all(pts[inlet, 0] == 0.0)
    assert sm.group_faces("fluid").all()
    assert list(sm.face_groups()) == ["fluid"]
    with pytest.raises(SolverMeshError, match=r"no group 'nozzle'.*walls, inlet"):
        sm.group_nodes("nozzle")


def test_pin_field_and_node_choice(files):
    sm = solver_mesh.read(str(files["vtu"]))
    fixed = sm.pin_field("fixed")
    assert np.array_equal(fixed, sm.points3d()[:, 0] < 0.5)
    with pytest.raises(SolverMeshError, match=r"no point data 'pins'.*fixed, temperature"):
        sm.pin_field("pins")
    g = solver_mesh.read(str(files["msh41"]))
    fs = faces_from_csr(g.offsets[:-1], g.counts(), g.corners, g.n_points)
    on_b = boundary_nodes(g.n_points, fs)
    ch = solver_mesh.node_choice(g, "fixed", on_b, slide_groups=("walls",),
                                 fixed_groups=("cylinder",))
    walls = g.group_nodes("walls")
    assert ch.boundary == "slide"
    assert np.array_equal(ch.pinned, (on_b & ~walls) | g.group_nodes("cylinder"))
    with pytest.raises(SolverMeshError, match="--slide-groups needs"):
        solver_mesh.node_choice(g, "free", on_b, slide_groups=("walls",))


def test_tangled_channel_untangles_with_the_file_faces(files):
    sm = solver_mesh.read(str(files["msh41"]))
    fs = faces_from_csr(sm.offsets[:-1], sm.counts(), sm.corners, sm.n_points)
    p = sm.points3d()[:, :2]
    assert (quality(p, fs) <= 0).sum() >= 1
    res = untangle_and_smooth(p, fs)
    assert res.status in ("valid", "untangled") and quality(res.points, fs).min() > 0.3


def test_mesquite_vtk_reads_with_its_fixed_field():
    sm = solver_mesh.read(str(mesquite_vtk()))
    assert (sm.n_points, sm.n_faces) == (168, 140)
    assert sm.pin_field("fixed").sum() == 56
    assert np.all(sm.points3d()[:, 2] == -5.0)


def bad_files(tmp_path, files):
    text = files["msh22"].read_bytes()
    (tmp_path / "cut.msh").write_bytes(text[: len(text) // 2])
    vtk = files["vtk_ascii"].read_bytes()
    (tmp_path / "cut.vtk").write_bytes(vtk[: len(vtk) // 3])
    import meshio
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    meshio.write(tmp_path / "tet.vtu", meshio.Mesh(pts, [("tetra", [[0, 1, 2, 3]])]))
    meshio.write(tmp_path / "lines.vtk", meshio.Mesh(pts, [("line", [[0, 1], [1, 2]])]))
    return {"cut.msh": "cannot read", "cut.vtk": "cannot read",
            "tet.vtu": "volume cells only \\(tetra\\)", "lines.vtk": "no 2D cells \\(line\\)"}


def test_bad_files_are_one_line_errors(files, tmp_path):
    for name, why in bad_files(tmp_path, files).items():
        with pytest.raises(SolverMeshError, match=why) as err:
            solver_mesh.read(str(tmp_path / name))
        assert "\n" not in str(err.value)
