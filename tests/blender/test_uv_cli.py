"""``blender -b -c eegt FILE --uv [MAP]``: the command handler called with argv lists."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from .conftest import positions
from .uvtools import tangled, uv_values

pytestmark = pytest.mark.blender


def cli(ext):
    return ext.operators.cli


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
