"""The command and the import/export operators on solver meshes (Gmsh-made and Mesquite's):
round trips that change only moved nodes, pins and groups from the file, per-group metrics,
bad files as exit 2 with one line and nothing written."""

from __future__ import annotations

import json

import numpy as np
import pytest
from solver_meshes import CHANNEL_TRIANGLES, channel_msh, mesquite_vtk

meshio = pytest.importorskip("meshio", reason="meshio is not installed")


@pytest.fixture
def cli(ext):
    return ext.operators.command.cli


def test_msh_in_msh_out_untangles_and_keeps_everything_else(bpy, cli, tmp_path):
    src = channel_msh(tmp_path / "wing.msh", shift=0.15)
    out, rep = tmp_path / "fixed.msh", tmp_path / "r.json"
    code = cli.run([str(src), "-o", str(out), "--report", str(rep), "--quiet",
                    "--metrics", "min_angle"])[0]
    report = json.loads(rep.read_text())
    assert code == 0, report
    a, b = meshio.read(src), meshio.read(out)
    moved = (a.points != b.points).any(axis=1)
    assert 0 < moved.sum() < len(a.points)
    boundary = np.unique(np.concatenate([c.data.ravel() for c in a.cells if c.type == "line"]))
    assert not moved[boundary].any()
    for x, y in zip(a.cells, b.cells):
        assert x.type == y.type and np.array_equal(x.data, y.data)
    for k in a.cell_data:
        assert all(np.array_equal(u, v) for u, v in zip(a.cell_data[k], b.cell_data[k]))
    assert out.read_bytes().split(b"\n")[1] == b"4.1 0 8"
    groups = report["solver_mesh"]["metrics"]
    assert list(groups) == ["fluid"] and groups["fluid"]["faces"] == CHANNEL_TRIANGLES
    assert groups["fluid"]["min_angle"]["after"]["min"] > groups["fluid"]["min_angle"][
        "before"]["min"]


def test_slide_and_fixed_groups_move_only_the_slide_group(bpy, cli, tmp_path):
    src = channel_msh(tmp_path / "c.msh", shift=0.15)
    out = tmp_path / "o.msh"
    code = cli.run([str(src), "-o", str(out), "--quiet", "--slide-groups", "walls",
                    "--fixed-groups", "cylinder"])[0]
    assert code == 0
    a, b = meshio.read(src), meshio.read(out)
    moved = (a.points != b.points).any(axis=1)
    walls = np.zeros(len(a.points), bool)
    inlet = np.zeros(len(a.points), bool)
    phys = a.cell_data["gmsh:physical"]
    tags = {n: v[0] for n, v in a.field_data.items()}
    for c, t in zip(a.cells, phys):
        if c.type == "line":
            walls[c.data[t == tags["walls"]].ravel()] = True
            inlet[c.data[t == tags["inlet"]].ravel()] = True
    assert not moved[inlet].any()
    assert moved[walls].any()
    assert np.abs(b.points[walls, 1] - a.points[walls, 1]).max() < 1e-6  # along y = 0, 1


def test_mesquite_vtk_with_its_fixed_field(bpy, cli, tmp_path):
    src = mesquite_vtk()
    out = tmp_path / "o.vtk"
    code = cli.run([str(src), "-o", str(out), "--quiet", "--pin-field", "fixed"])[0]
    assert code in (0, 3)
    a, b = meshio.read(src), meshio.read(out)
    fixed = a.point_data["fixed"].ravel() != 0
    moved = (a.points != b.points).any(axis=1)
    assert moved.any() and not moved[fixed].any()
    assert np.all(b.points[:, 2] == -5.0)


@pytest.mark.parametrize(("make", "flags", "needle"), [
    ("cut", [], "cannot read"),
    ("tet", [], "volume cells only"),
    ("lines", [], "no 2D cells"),
    ("ok", ["--fixed-groups", "nozzle"], "no group 'nozzle'"),
    ("ok", ["--pin-field", "pins"], "no point data 'pins'"),
])
def test_bad_files_exit_2_one_line_nothing_written(bpy, cli, tmp_path, capfd, make, flags,
                                                   needle):
    src = channel_msh(tmp_path / "ok.msh")
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    if make == "cut":
        text = src.read_bytes()
        src = tmp_path / "cut.msh"
        src.write_bytes(text[: len(text) // 2])
    elif make == "tet":
        src = tmp_path / "tet.msh"
        meshio.gmsh.write(src, meshio.Mesh(pts, [("tetra", [[0, 1, 2, 3]])]), "2.2", binary=False)
    elif make == "lines":
        src = tmp_path / "lines.vtk"
        meshio.write(src, meshio.Mesh(pts, [("line", [[0, 1], [1, 2]])]))
    out = tmp_path / ("out" + src.suffix)
    capfd.readouterr()
    code = cli.run([str(src), "-o", str(out), "--quiet", *flags])[0]
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and needle in err[0], err
    assert not out.exists()


def test_import_operator_then_export_changes_only_moved(bpy, ext, tmp_path):
    src = channel_msh(tmp_path / "c.msh", shift=0.15)
    assert bpy.ops.eegt.import_solver_mesh(filepath=str(src)) == {"FINISHED"}
    obj = bpy.context.active_object
    assert len(obj.data.vertices) == len(meshio.read(src).points)
    assert {"walls", "inlet", "outlet", "cylinder"} <= set(obj.vertex_groups.keys())
    assert "gmsh:physical" in obj.data.attributes
    res = ext.operators.mesh.runner.run_object(obj, ext.core.EEGTParams())
    assert res.ok
    out = tmp_path / "o.msh"
    assert bpy.ops.eegt.export_solver_mesh(filepath=str(out)) == {"FINISHED"}
    a, b = meshio.read(src), meshio.read(out)
    moved = (a.points != b.points).any(axis=1)
    assert 0 < moved.sum() < len(a.points)
    assert sorted(a.cell_data) == sorted(b.cell_data)
