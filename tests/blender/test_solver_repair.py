"""Solver meshes are repaired by default (target "keep", region "folds"): only the folded
faces and a margin move, every other node keeps its bits; `--target regular --region mesh`
gives the whole-mesh smoothing."""

from __future__ import annotations

import json

import numpy as np
import pytest
from solver_meshes import channel_msh

meshio = pytest.importorskip("meshio", reason="meshio is not installed")


def _moved(src, out) -> np.ndarray:
    return (meshio.read(src).points != meshio.read(out).points).any(axis=1)


def _run(ext, src, out, *flags: str) -> tuple[int, dict]:
    """The command on `src` into `out` (quiet, its JSON report beside it): (exit code, the
    report's one object)."""
    rep = out.with_suffix(".json")
    code = ext.operators.command.cli.run([str(src), "-o", str(out), "--report", str(rep),
                                          "--quiet", *flags])[0]
    (o,) = json.loads(rep.read_text())["objects"]
    return code, o


def test_solver_mesh_default_is_a_repair_that_keeps_every_node_outside_the_margin(
        bpy, ext, tmp_path):
    src = channel_msh(tmp_path / "c.msh", shift=0.15)
    out = tmp_path / "r.msh"
    code, o = _run(ext, src, out)
    assert code == 0, o
    assert o["status"] == "untangled" and o["after"]["n_inverted"] == 0
    assert o["message"].startswith("folds only: ")
    moved = _moved(src, out)
    n_points = moved.size
    assert 0 < moved.sum() < 0.25 * n_points  # the margin around the cylinder only
    whole_out = tmp_path / "w.msh"
    code, w = _run(ext, src, whole_out, "--target", "regular", "--region", "mesh")
    assert code == 0 and w["after"]["n_inverted"] == 0
    assert not w["message"].startswith("folds only")
    assert _moved(src, whole_out).sum() > 0.5 * n_points  # every free node moved
    # the repair reports against its own targets and against regular polygons beside them;
    # the whole-mesh run's targets are regular polygons: no second block
    reg = o["regular"]
    assert reg["before"]["n_inverted"] == o["before"]["n_inverted"] > 0
    assert reg["after"]["n_inverted"] == 0 and 0.0 < reg["after"]["q_min"] <= 1.0
    assert "regular" not in w


def test_repair_report_line_gives_the_regular_mean_ratio_beside_the_targets(bpy, ext, tmp_path,
                                                                           capfd):
    src = channel_msh(tmp_path / "c.msh", shift=0.15)
    code = ext.operators.command.cli.run([str(src), "-o", str(tmp_path / "r.msh")])[0]
    assert code == 0
    line = [ln for ln in capfd.readouterr().out.splitlines()
            if ln.startswith("EEGT c: inverted ")][-1]
    assert "; against regular polygons: q_min 0.0000 -> " in line


def test_repair_of_a_valid_solver_mesh_writes_it_unchanged(bpy, ext, tmp_path):
    src = channel_msh(tmp_path / "v.msh", shift=0.0)
    out = tmp_path / "o.msh"
    code, o = _run(ext, src, out)
    assert code == 0 and o["status"] == "valid"
    assert not _moved(src, out).any()


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_gmsh41_file_without_physical_groups_is_repaired_and_written_back(bpy, ext, tmp_path,
                                                                         binary):
    """A folded Gmsh 4.1 file as Gmsh saves it when no physical group is defined: exit 0,
    no face inverted, the file's bytes but the moved nodes' coordinates (meshio's 4.1
    writer refused it: 'gmsh:physical')."""
    src = channel_msh(tmp_path / "p.msh", binary=binary, shift=0.15, groups=False)
    out = tmp_path / "r.msh"
    code, o = _run(ext, src, out)
    assert code == 0, o
    assert o["before"]["n_inverted"] > 0 and o["after"]["n_inverted"] == 0
    moved = _moved(src, out)
    assert 0 < moved.sum() < 0.25 * moved.size
    a, b = src.read_bytes(), out.read_bytes()
    if binary:
        assert len(a) == len(b) and sum(x != y for x, y in zip(a, b)) <= 24 * moved.sum()
    else:
        la, lb = a.splitlines(), b.splitlines()
        assert len(la) == len(lb)
        assert sum(x != y for x, y in zip(la, lb)) == moved.sum()


def test_cylinder_moved_through_the_outlet_exits_3_at_once_naming_where(bpy, ext, tmp_path):
    """The cylinder's held wall slid across the held outlet: the boundary winds -1 times
    inside the part of the cylinder beyond the outlet, so no positions make the mesh valid
    (core/run/hopeless_winding.py). The repair says so before any iteration and moves
    nothing."""
    src = channel_msh(tmp_path / "c.msh", shift=2.95)
    out = tmp_path / "r.msh"
    code, o = _run(ext, src, out)
    assert code == 3, o
    assert o["status"] == "failed" and o["after"]["n_inverted"] == o["before"]["n_inverted"] > 0
    assert "crosses itself (its edges " in o["message"], o["message"]
    assert ") and winds -1 times beside that crossing" in o["message"]
    assert o["untangle_iterations"] == o["global_iterations"] == 0
    assert not _moved(src, out).any()
