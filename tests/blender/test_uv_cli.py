"""``blender -b -c eegt FILE --uv [MAP]``: the command handler called with argv lists."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from .conftest import positions
from .uvkept import pin_one_inverted_face
from .uvtools import (
    inverted_uv_faces,
    jitter_uv_vertices,
    loop_faces,
    one_ulp_apart,
    primitive,
    tangled,
    uv_border_loops,
    uv_values,
    uv_vertex_groups,
)

pytestmark = pytest.mark.blender


def cli(ext):
    return ext.operators.command.entry


@pytest.fixture
def blend(bpy, tmp_path):
    """A .blend with a tangled sphere, a tangled organic surface with a second UV map
    (active) and a mesh without UV map; the arrays before."""
    from bench import uv_assets
    s = tangled(bpy, "sphere", "jitter")
    o = uv_assets.make_asset(bpy, "organic", n=16)
    extra = o.data.uv_layers.new(name="Second")  # a copy of the clean unwrap
    o.data.uv_layers.active = o.data.uv_layers["UVMap"]
    uv_assets.tangle(bpy, o, "rotate")
    o.data.uv_layers.active = extra  # the active map is the clean copy
    bpy.ops.mesh.primitive_plane_add()
    plain = bpy.context.active_object
    plain.name = "Plain"
    plain.data.uv_layers.remove(plain.data.uv_layers[0])
    path = tmp_path / "in.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    before = {"Sphere": uv_values(s), "Organic": uv_values(o, "UVMap"),
              "Second": uv_values(o, "Second"), "co": positions(o)}
    return path, before


def test_uv_active_maps_of_every_object_report_and_output(bpy, ext, blend, tmp_path):
    path, before = blend
    out, rep = tmp_path / "out.blend", tmp_path / "r.json"
    code = cli(ext).execute([str(path), "--uv", "-o", str(out), "--report", str(rep),
                             "--quiet"])
    assert code == 0
    report = json.loads(rep.read_text())
    objs = {o["object"]: o for o in report["objects"]}
    assert set(objs) == {"Sphere", "Organic"}
    assert report["skipped"] == [{"object": "Plain",
                                  "reason": "mesh has no UV map (unwrap it first)"}]
    s = objs["Sphere"]
    assert s["uv_map"] == "UVMap" and s["status"] == "untangled" and s["written"]
    assert s["before"]["flipped"] > 20 and s["after"]["flipped"] == 0
    assert s["after"]["inverted"] == 0 and s["after"]["overlapping"] == 0
    assert s["after"]["distortion_mean"] > s["before"]["distortion_mean"]
    assert 0 < s["after"]["distortion_worst"] <= s["after"]["distortion_mean"] <= 1
    assert s["targets"] == "3D" and s["islands"] == 1
    o = objs["Organic"]  # the active map, "Second", is untangled already
    assert o["uv_map"] == "Second" and o["before"]["flipped"] == 0
    bpy.ops.wm.open_mainfile(filepath=str(out))
    sphere, org = bpy.data.objects["Sphere"], bpy.data.objects["Organic"]
    assert not np.array_equal(uv_values(sphere), before["Sphere"])
    assert np.array_equal(uv_values(org, "UVMap"), before["Organic"])  # other map untouched
    assert np.array_equal(positions(org), before["co"])
    assert sphere.eegt_last_uv_run.flipped_after == 0


def test_uv_named_map_and_object_filter(bpy, ext, blend, tmp_path):
    path, before = blend
    out, rep = tmp_path / "out.blend", tmp_path / "r.json"
    code = cli(ext).execute([str(path), "--uv", "UVMap", "--object", "Organic", "-o",
                             str(out), "--report", str(rep), "--quiet"])
    assert code == 0
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["object"] == "Organic" and o["uv_map"] == "UVMap"
    assert o["before"]["flipped"] > 0 and o["after"]["flipped"] == 0
    assert o["before"]["overlapping"] > o["after"]["overlapping"] == 0
    bpy.ops.wm.open_mainfile(filepath=str(out))
    org = bpy.data.objects["Organic"]
    assert np.array_equal(uv_values(org, "Second"), before["Second"])
    assert not np.array_equal(uv_values(org, "UVMap"), before["Organic"])
    assert np.array_equal(uv_values(bpy.data.objects["Sphere"]), before["Sphere"])


@pytest.mark.parametrize("args, needle", [
    (["--uv", "NoSuchMap"], "no chosen mesh object has a UV map named 'NoSuchMap' (UV maps: "
                            "Second, UVMap)"),
    (["--uv", "--object", "Plain"], "no chosen mesh object has a UV map"),
])
def test_uv_unknown_map_exit_2_nothing_written(bpy, ext, blend, tmp_path, capfd, args,
                                               needle):
    path, _ = blend
    out, rep = tmp_path / "out.blend", tmp_path / "r.json"
    assert cli(ext).execute([str(path), *args, "-o", str(out), "--report", str(rep)]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert err[-1].startswith("eegt: ") and needle in err[-1] and len(err[-1]) < 200
    assert not out.exists()
    report = json.loads(rep.read_text())
    assert report["exit_code"] == 2 and report["written"] is False


def test_uv_zero_area_map_exit_3_unchanged(bpy, ext, tmp_path):
    s = tangled(bpy, "sphere", "jitter")
    me = s.data
    me.attributes["UVMap"].data.foreach_set("vector", np.zeros(2 * len(me.loops), np.float32))
    path = tmp_path / "flat.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    out, rep = tmp_path / "out.blend", tmp_path / "r.json"
    assert cli(ext).execute([str(path), "--uv", "-o", str(out), "--report", str(rep),
                             "--quiet"]) == 3
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["status"] == "error" and not o["written"]
    assert "has no area" in o["message"] and "unwrap it first" in o["message"]
    bpy.ops.wm.open_mainfile(filepath=str(out))
    assert not uv_values(bpy.data.objects["Sphere"]).any()


def test_uv_progress_lines_name_the_island(bpy, ext, blend, capfd):
    path, _ = blend
    assert cli(ext).execute([str(path), "--uv", "--object", "Sphere"]) == 0
    out = capfd.readouterr().out
    # the jitter reaches most of the island: the whole island runs at once
    assert re.search(r"EEGT Sphere: island 1/1 untangle iteration 0: inverted \d+", out)
    assert "EEGT Sphere UV 'UVMap': flipped " in out
    assert "EEGT Plain" not in out


def _save_uv(bpy, obj, uv, path):
    obj.data.attributes[obj.data.uv_layers.active.name].data.foreach_set(
        "vector", np.ascontiguousarray(uv, np.float32).ravel())
    obj.data.update()
    bpy.ops.wm.save_as_mainfile(filepath=str(path))


def test_uv_grid_with_loops_a_float32_step_apart_exit_0_none_inverted(bpy, ext, tmp_path):
    """Blender's Grid with the UVs of one loop of every UV vertex one float32 step off (as
    4.2-4.5 store part of them), interior jittered: exit 0 means no inverted face left."""
    obj = primitive(bpy, "grid")
    uv0 = uv_values(obj)
    groups = uv_vertex_groups(obj, uv0)
    border = uv_border_loops(obj, groups)
    free = np.ones(groups.max() + 1, bool)
    free[groups[border]] = False
    uv1 = one_ulp_apart(jitter_uv_vertices(obj, uv0, groups, free, 0.6, seed=3), groups, 4)
    path, out, rep = tmp_path / "grid.blend", tmp_path / "out.blend", tmp_path / "r.json"
    _save_uv(bpy, obj, uv1, path)
    assert cli(ext).execute([str(path), "--uv", "-o", str(out), "--report", str(rep),
                             "--quiet"]) == 0
    (o,) = json.loads(rep.read_text())["objects"]
    assert (o["status"], o["n_uv_vertices"], o["n_free"]) == ("untangled", 121, 81)
    assert (o["before"]["inverted"], o["after"]["inverted"]) == (11, 0)
    bpy.ops.wm.open_mainfile(filepath=str(out))
    uv2 = uv_values(bpy.data.objects["Grid"])
    assert not inverted_uv_faces(bpy.data.objects["Grid"], uv2, groups).any()
    assert np.array_equal(uv2[border], uv1[border])


def test_uv_pins_holding_an_inverted_face_exit_3_failed(bpy, ext, tmp_path, capfd):
    """Every corner of one inverted face pinned: exit 3, "failed" and why, the rest
    untangled and written."""
    obj = tangled(bpy, "sphere", "jitter")
    me = obj.data
    uv0 = uv_values(obj)
    groups = uv_vertex_groups(obj, uv0)
    lf = loop_faces(obj)
    inside = np.ones(len(me.polygons), bool)
    np.logical_and.at(inside, lf, ~uv_border_loops(obj, groups))
    bad = inverted_uv_faces(obj, uv0, groups)
    face, pins = pin_one_inverted_face(ext, obj, groups, bad, inside)
    path, out, rep = tmp_path / "pinned.blend", tmp_path / "out.blend", tmp_path / "r.json"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    assert cli(ext).execute([str(path), "--uv", "-o", str(out), "--report", str(rep),
                             "--quiet"]) == 3
    report = json.loads(rep.read_text())
    (o,) = report["objects"]
    assert report["exit_code"] == 3
    assert o["status"] == "failed" and o["written"]
    assert o["message"] == "1 face stays inverted: every corner of it is pinned"
    assert (o["before"]["inverted"], o["after"]["inverted"]) == (
        int(bad.sum()) - o["before"]["kept"], 1)  # faces kept as given once pinned: valid
    assert "FAILED: 1 face stays inverted: every corner of it is pinned" in \
        capfd.readouterr().out
    bpy.ops.wm.open_mainfile(filepath=str(out))
    obj = bpy.data.objects["Sphere"]
    uv1 = uv_values(obj)
    assert np.flatnonzero(inverted_uv_faces(obj, uv1, groups)).tolist() == [face]
    assert np.array_equal(uv1[pins], uv0[pins])
    assert code_without_pins(ext, path, tmp_path) == 0


def code_without_pins(ext, path, tmp_path) -> int:
    """The same file with --no-pinned: the face is free again and untangles."""
    return cli(ext).execute([str(path), "--uv", "--no-pinned", "-o",
                             str(tmp_path / "free.blend"), "--quiet"])
