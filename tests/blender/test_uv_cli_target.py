"""``blender -b -c eegt FILE --uv --uv-target TARGET``: the command's UV target flag (the
headless side of target "Keep Shapes"), called with argv lists as the command handler."""

from __future__ import annotations

import json

import numpy as np
import pytest

from .test_uv_keep_target import counts, graded_grid, margin_loops
from .uvtools import uv_values

pytestmark = pytest.mark.blender


def cli(ext):
    return ext.operators.command.entry


def _folded(bpy, ext, tmp_path):
    """A .blend with the graded grid whose UV map has a fold (two faces inverted, six
    tangled); its path, its UVs and the loops the repair may move."""
    obj = graded_grid(bpy)
    uv0 = uv_values(obj)
    inside = margin_loops(ext, obj, uv0)
    path = tmp_path / "folded.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path, uv0, inside


def test_uv_target_flag_choices_and_default_come_from_the_choice_list(ext):
    ch = ext.core.choices
    actions = {a.dest: a for a in ext.operators.command.parser.build_parser()._actions}
    assert list(actions["uv_target"].choices) == list(ch.ids(ch.UV_TARGET))
    assert actions["uv_target"].default == ch.UV_TARGET[0].id
    for c in ch.UV_TARGET:
        assert f"{c.id} ({c.label})" in " ".join(actions["uv_target"].help.split())


def test_uv_target_keep_repairs_the_fold_and_keeps_every_other_loop(bpy, ext, tmp_path):
    path, uv0, inside = _folded(bpy, ext, tmp_path)
    out, rep = tmp_path / "out.blend", tmp_path / "r.json"
    code = cli(ext).execute([str(path), "--uv", "--uv-target", "KEEP", "-o", str(out),
                             "--report", str(rep), "--quiet"])
    assert code == 0
    report = json.loads(rep.read_text())
    assert report["argv"][report["argv"].index("--uv-target") + 1] == "KEEP"
    (o,) = report["objects"]
    assert o["targets"] == "KEEP" and o["status"] == "untangled" and o["written"]
    assert (o["before"]["inverted"], o["after"]["inverted"]) == (2, 0)
    assert o["after"]["flipped"] == 0 and o["after"]["overlapping"] == 0
    assert "6 tangled faces took the shape of: 6 a neighbour's" in o["notes"]
    assert o["after"]["distortion_worst"] > 0.99  # as laid out (the operator's test: 0.9993)
    bpy.ops.wm.open_mainfile(filepath=str(out))
    obj = bpy.data.objects["Graded"]
    uv1 = uv_values(obj)
    assert counts(ext, obj) == {"FLIPPED": 0, "INVERTED": 0, "OVERLAPPING": 0}
    assert uv1[~inside].tobytes() == uv0[~inside].tobytes()  # bit for bit outside the margin
    assert np.any(uv1[inside] != uv0[inside])
    # the Python entry with the same target gives the same bits
    bpy.ops.wm.open_mainfile(filepath=str(path))
    obj = bpy.data.objects["Graded"]
    res = ext.operators.uv.uv_runner.run_object(obj, ext.core.EEGTParams(), targets="KEEP")
    assert res.targets == "KEEP" and uv_values(obj).tobytes() == uv1.tobytes()


def test_uv_target_default_is_the_first_choice(bpy, ext, tmp_path):
    """Without the flag the run is target 3D Faces (the choice list's first): distortion is
    measured against the 3D faces (unit squares, far from the 4:1 to 8.6:1 layout)."""
    path, uv0, _ = _folded(bpy, ext, tmp_path)
    out, rep = tmp_path / "out.blend", tmp_path / "r.json"
    assert cli(ext).execute([str(path), "--uv", "-o", str(out), "--report", str(rep),
                             "--quiet"]) == 0
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["targets"] == ext.core.choices.UV_TARGET[0].id == "3D"
    assert o["after"]["inverted"] == 0 and o["after"]["distortion_mean"] < 0.5  # measured 0.375
    bpy.ops.wm.open_mainfile(filepath=str(out))
    assert np.any(uv_values(bpy.data.objects["Graded"]) != uv0)


def test_uv_target_bogus_exit_2_one_line_nothing_written(bpy, ext, tmp_path, capfd):
    path, _, _ = _folded(bpy, ext, tmp_path)
    before = path.read_bytes()
    out, rep = tmp_path / "out.blend", tmp_path / "r.json"
    code = cli(ext).execute([str(path), "--uv", "--uv-target", "bogus", "-o", str(out),
                             "--report", str(rep)])
    assert code == 2
    cap = capfd.readouterr()
    err = cap.err.strip().splitlines()
    assert len(err) == 1 and "argument --uv-target: invalid choice: 'bogus'" in err[0]
    assert "EEGT" not in cap.out
    assert not out.exists() and not rep.exists()
    assert path.read_bytes() == before
