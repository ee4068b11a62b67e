"""The ``eegt`` command handler called with argv lists (as ``blender -b -c eegt`` would)."""

from __future__ import annotations

import json
import os
import shutil

import meshdata
import numpy as np
import pytest

from core.mesh.topology import boundary_nodes

from .conftest import DATA, import_obj, positions

pytestmark = pytest.mark.blender


def cli(ext):
    return ext.operators.command.entry


def read_obj_vertices(path) -> np.ndarray:
    return meshdata.read(path)[0]


def test_obj_in_obj_out_with_report(bpy, ext, tmp_path):
    out, rep = tmp_path / "out.obj", tmp_path / "r.json"
    code = cli(ext).execute([str(DATA / "quad_hole.obj"), "-o", str(out), "--report", str(rep),
                             "--quiet"])
    assert code == 0
    report = json.loads(rep.read_text())
    assert report["exit_code"] == 0 and report["written"] is True
    assert report["params"]["a"] == pytest.approx(0.2)
    (o,) = report["objects"]
    assert o["object"] == "quad_hole" and o["status"] == "untangled" and o["written"]
    assert o["before"]["n_inverted"] == 23 and o["after"]["n_inverted"] == 0
    assert o["after"]["q_min"] > 0.5 and o["after"]["q_avg"] > o["before"]["q_avg"]
    assert o["untangle_iterations"] + o["global_iterations"] > 0
    assert o["seconds"] > 0 and o["backend"] == "numpy"
    assert (o["n_nodes"], o["n_faces"]) == (168, 140)
    # the written OBJ has the same vertex count, every boundary vertex kept its bits (the
    # positions written, in this session, against the input as Blender reads it), the
    # inside moved, no inverted face
    src, dst = read_obj_vertices(DATA / "quad_hole.obj"), read_obj_vertices(out)
    assert src.shape == dst.shape
    assert np.allclose(dst[:, 2], 0.0)
    written = positions(bpy.data.objects["quad_hole"])
    bpy.ops.wm.read_homefile(use_empty=True)
    given = positions(import_obj(bpy, "quad_hole"))
    faces = meshdata.load("quad_hole")[1]
    boundary = boundary_nodes(len(src), faces)
    assert boundary.dtype == bool and boundary.sum() == 56
    assert np.array_equal(written[boundary].view(np.uint32), given[boundary].view(np.uint32))
    assert (written[~boundary] != given[~boundary]).any(axis=1).sum() > 50
    bpy.ops.wm.read_homefile(use_empty=True)
    obj = import_obj(bpy, "out", out)
    from .conftest import mesh_quality
    assert (mesh_quality(ext, obj) > 0).all()


def test_failed_mesh_exit_3_best_written_unless_no_write(bpy, ext, tmp_path):
    inp = str(DATA / "quad_hole.obj")
    out, rep = tmp_path / "out.blend", tmp_path / "r.json"
    args = ["--untangle", "eegt", "--max-untangle-iterations", "1", "--report", str(rep),
            "--quiet"]
    assert cli(ext).execute([inp, "-o", str(out), *args]) == 3
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["status"] == "failed" and o["written"] is True
    assert 0 < o["after"]["n_inverted"] < 23 and "failed" in o["message"]
    bpy.ops.wm.open_mainfile(filepath=str(out))
    written = positions(bpy.data.objects["quad_hole"])
    assert json.loads(rep.read_text())["exit_code"] == 3
    # --no-write-on-fail leaves the mesh as it was
    out2 = tmp_path / "out2.blend"
    assert cli(ext).execute([inp, "-o", str(out2), "--no-write-on-fail", *args]) == 3
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["written"] is False and o["status"] == "failed"
    bpy.ops.wm.open_mainfile(filepath=str(out2))
    kept = positions(bpy.data.objects["quad_hole"])
    src = read_obj_vertices(DATA / "quad_hole.obj").astype(np.float32)
    assert np.array_equal(kept, src)
    assert not np.array_equal(written, src)


def test_blend_input_object_filter_and_bad_mesh(bpy, ext, tmp_path):
    a = import_obj(bpy, "quad_hole")
    b = import_obj(bpy, "tilted_plane")
    co = positions(b)
    co[0, 2] += 1.0  # no longer planar
    b.data.attributes["position"].data.foreach_set("vector", co.ravel())
    a.name, b.name = "good", "bent"
    src = tmp_path / "in.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(src))
    rep = tmp_path / "r.json"
    out = tmp_path / "out.blend"
    code = cli(ext).execute([str(src), "-o", str(out), "--report", str(rep), "--quiet"])
    assert code == 3
    objs = {o["object"]: o for o in json.loads(rep.read_text())["objects"]}
    assert objs["good"]["status"] == "untangled" and objs["good"]["after"]["n_inverted"] == 0
    assert objs["bent"]["status"] == "error" and "not planar" in objs["bent"]["message"]
    assert objs["bent"]["written"] is False
    bpy.ops.wm.open_mainfile(filepath=str(out))
    assert np.array_equal(positions(bpy.data.objects["bent"]), co)
    # --object picks one mesh; the input file itself is never modified without -o
    code = cli(ext).execute([str(src), "--object", "good", "--report", str(rep), "--quiet"])
    assert code == 0
    report = json.loads(rep.read_text())
    assert [o["object"] for o in report["objects"]] == ["good"] and report["written"] is False
    bpy.ops.wm.open_mainfile(filepath=str(src))
    assert bpy.data.objects["good"].eegt_last_run.has_run is False


@pytest.mark.parametrize("argv, needle", [
    (["/nonexistent/file.obj"], "no such file"),
    (["{tmp}/mesh.txt"], "unsupported input type"),
    (["{data}/quad_hole.obj", "--a", "-1"], "a must be > 0"),
    (["{data}/quad_hole.obj", "--scaling", "volume"], "invalid choice"),
    (["{data}/quad_hole.obj", "--bogus"], "unrecognized arguments"),
    (["{data}/quad_hole.obj", "--object", "nope"], "no mesh object named 'nope'"),
    ([], "the following arguments are required"),
])
def test_usage_errors_exit_2(bpy, ext, tmp_path, capfd, argv, needle):
    (tmp_path / "mesh.txt").write_text("v 0 0 0\n")
    argv = [a.format(data=DATA, tmp=tmp_path) for a in argv]
    rep = tmp_path / "r.json"
    assert cli(ext).execute([*argv, "--report", str(rep)] if argv else argv) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert needle in err[-1]
    if argv and "--bogus" not in argv and "--scaling" not in argv:
        report = json.loads(rep.read_text())
        assert report["exit_code"] == 2 and needle in report["error"]


def test_help_exit_0_lists_every_parameter(bpy, ext, capfd):
    assert cli(ext).execute(["--help"]) == 0
    out = capfd.readouterr().out
    for f in ext.core.EEGTParams.field_names():
        assert "--" + f.replace("_", "-") in out
    assert "--no-write-on-fail" in out and "--report" in out


def test_command_is_registered(bpy, ext):
    assert cli(ext)._handle is not None


@pytest.mark.parametrize("fmt", ["ply", "stl"])
def test_ply_and_stl_inputs(bpy, ext, tmp_path, fmt):
    import_obj(bpy, "quad_hole")
    src = tmp_path / f"in.{fmt}"
    export = getattr(bpy.ops.wm, f"{fmt}_export")
    export(filepath=str(src), forward_axis="Y", up_axis="Z")
    rep = tmp_path / "r.json"
    code = cli(ext).execute([str(src), "-o", str(tmp_path / f"out.{fmt}"), "--report", str(rep),
                             "--quiet"])
    assert code == 0
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["n_nodes"] == 168 and o["n_faces"] == (140 if fmt == "ply" else 280)
    assert o["before"]["n_inverted"] > 0 and o["after"]["n_inverted"] == 0
    assert (tmp_path / f"out.{fmt}").stat().st_size > 0


def test_garbage_blend_exit_2_one_line(bpy, ext, tmp_path, capfd):
    bad = tmp_path / "garbage.blend"
    bad.write_bytes(b"not a blend file at all")
    assert cli(ext).execute([str(bad), "-o", str(tmp_path / "x.obj")]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    line = [e for e in err if e.startswith("eegt:")]
    assert len(line) == 1 and "cannot read input" in line[0] and "Error: " not in line[0]
    assert not (tmp_path / "x.obj").exists()


def test_unknown_opencl_device_falls_back_to_numpy(bpy, ext, tmp_path):
    rep = tmp_path / "r.json"
    code = cli(ext).execute([str(DATA / "quad_hole.obj"), "--backend", "opencl", "--device",
                             "no-such-device", "--report", str(rep), "--quiet"])
    assert code == 0
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["backend"].startswith("numpy (") and "using NumPy" in o["backend"]
    assert o["after"]["n_inverted"] == 0


# ---- -o naming the input: refused unless --in-place ---------------------------------------


def hidden(folder) -> list[str]:
    return sorted(n for n in os.listdir(folder) if n.startswith("."))


@pytest.mark.parametrize("spelling", ["same path", "symbolic link", "dotted path",
                                      "linked folder"])
def test_output_naming_the_input_is_refused_and_leaves_it(bpy, ext, tmp_path, capfd, spelling):
    real = tmp_path / "d" / "m.obj"
    real.parent.mkdir()
    shutil.copy(DATA / "quad_hole.obj", real)
    (tmp_path / "link.obj").symlink_to(real)
    (tmp_path / "dl").symlink_to(real.parent)
    out = {"same path": real, "symbolic link": tmp_path / "link.obj",
           "dotted path": tmp_path / "d" / ".." / "d" / "m.obj",
           "linked folder": tmp_path / "dl" / "m.obj"}[spelling]
    before = real.read_bytes()
    rep = tmp_path / "r.json"
    assert cli(ext).execute([str(real), "-o", str(out), "--report", str(rep), "--quiet"]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert err == [f"eegt: -o '{out}' is the input file itself: give --in-place to replace "
                   "it, or another output"]
    assert real.read_bytes() == before and hidden(real.parent) == []
    report = json.loads(rep.read_text())
    assert report["exit_code"] == 2 and report["written"] is False and report["objects"] == []
    assert len(bpy.data.objects) == 0  # refused before the input was read


@pytest.mark.parametrize("argv", [["--in-place"], ["-o", "{inp}", "--in-place"],
                                  ["-o", "{link}", "--in-place"]])
def test_in_place_replaces_the_input_whole(bpy, ext, tmp_path, argv):
    inp = tmp_path / "m.obj"
    shutil.copy(DATA / "quad_hole.obj", inp)
    (tmp_path / "link.obj").symlink_to(inp)
    rep = tmp_path / "r.json"
    args = [a.format(inp=inp, link=tmp_path / "link.obj") for a in argv]
    assert cli(ext).execute([str(inp), *args, "--report", str(rep), "--quiet"]) == 0
    report = json.loads(rep.read_text())
    assert report["written"] is True and report["output"] in (str(inp), str(tmp_path / "link.obj"))
    (o,) = report["objects"]
    assert o["before"]["n_inverted"] == 23 and o["after"]["n_inverted"] == 0
    assert not inp.is_symlink() and (tmp_path / "link.obj").is_symlink()
    src, dst = read_obj_vertices(DATA / "quad_hole.obj"), read_obj_vertices(inp)
    assert src.shape == dst.shape == (168, 3) and not np.allclose(src, dst)
    assert hidden(tmp_path) == []
    bpy.ops.wm.read_homefile(use_empty=True)
    from .conftest import mesh_quality
    assert (mesh_quality(ext, import_obj(bpy, "m", inp)) > 0).all()


def test_in_place_blend_keeps_every_object(bpy, ext, tmp_path):
    import_obj(bpy, "quad_hole")
    import_obj(bpy, "tilted_plane")
    src = tmp_path / "in.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(src))
    assert cli(ext).execute([str(src), "--in-place", "--quiet"]) == 0
    bpy.ops.wm.open_mainfile(filepath=str(src))
    assert sorted(o.name for o in bpy.data.objects) == ["quad_hole", "tilted_plane"]
    assert bpy.data.objects["quad_hole"].eegt_last_run.inverted_after == 0
    assert not (tmp_path / "in.blend1").exists() and hidden(tmp_path) == []
