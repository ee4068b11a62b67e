"""The command line never loses or corrupts output: checks before computing, faceless input,
atomic checked saves, and a full disk (a 16 KB tmpfs, root only)."""

from __future__ import annotations

import json
import os
import subprocess

import pytest

from .conftest import DATA

pytestmark = pytest.mark.blender


def run(ext, *argv) -> tuple[int, dict]:
    return ext.operators.cli.run([str(a) for a in argv])


def leftovers(folder) -> list[str]:
    return sorted(n for n in os.listdir(folder) if ".eegt-tmp-" in n)


def test_unsupported_output_type_fails_before_loading_the_input(bpy, ext, tmp_path, capfd):
    code, rep = run(ext, DATA / "naca_deform.obj", "-o", tmp_path / "x.fbx")
    assert code == 2 and rep["written"] is False
    assert "unsupported output type '.fbx'" in capfd.readouterr().err
    assert len(bpy.data.objects) == 0  # the input was never imported
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("where", ["no folder", "a directory"])
def test_unwritable_report_fails_before_computing_and_writes_no_output(bpy, ext, tmp_path,
                                                                       where):
    report = tmp_path / ("missing/r.json" if where == "no folder" else "")
    out = tmp_path / "out.obj"
    code, rep = run(ext, DATA / "quad_hole.obj", "-o", out, "--report", report)
    assert code == 2 and not out.exists() and rep["written"] is False
    assert len(bpy.data.objects) == 0 and rep["objects"] == []


def test_output_folder_missing_fails_before_computing(bpy, ext, tmp_path, capfd):
    code, _ = run(ext, DATA / "quad_hole.obj", "-o", tmp_path / "nope" / "out.obj")
    assert code == 2 and len(bpy.data.objects) == 0
    assert "no folder" in capfd.readouterr().err


def test_directory_input_says_is_a_directory(bpy, ext, tmp_path, capfd):
    code, rep = run(ext, tmp_path, "-o", tmp_path / "out.obj")
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].endswith("is a directory") and "no such file" not in err[-1]
    assert rep["error"].endswith("is a directory")


@pytest.mark.parametrize("text", [
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nl 1 2\nl 2 3\n",  # edges only
    "v 0 0 0\nv 1 0 0\n",  # points only
    "",  # empty file
    "this is not an obj file\nat all\n",  # garbage the importer skips
])
def test_input_with_nothing_to_work_on_exits_2_and_writes_nothing(bpy, ext, tmp_path, capfd,
                                                                  text):
    src, out = tmp_path / "in.obj", tmp_path / "out.obj"
    src.write_text(text)
    for extra in ([], ["--no-write-on-fail"]):
        code, rep = run(ext, src, "-o", out, *extra)
        err = capfd.readouterr().err.strip().splitlines()
        assert code == 2 and not out.exists() and rep["written"] is False
        assert "nothing to work on" in err[-1] or "no faces to work on" in err[-1]


def test_faceless_object_in_a_blend_is_skipped_the_others_processed(bpy, ext, tmp_path,
                                                                     capfd):
    from .conftest import import_obj

    import_obj(bpy, "quad_hole")
    me = bpy.data.meshes.new("edges")
    me.from_pydata([(0, 0, 0), (1, 0, 0)], [(0, 1)], [])
    bpy.context.collection.objects.link(bpy.data.objects.new("edges", me))
    src, out, report = tmp_path / "in.blend", tmp_path / "out.blend", tmp_path / "r.json"
    bpy.ops.wm.save_as_mainfile(filepath=str(src))
    code, rep = run(ext, src, "-o", out, "--report", report, "--quiet")
    assert code == 0 and rep["written"] is True and out.exists()
    assert [o["object"] for o in rep["objects"]] == ["quad_hole"]
    assert "EEGT edges: skipped: no faces" in capfd.readouterr().out


@pytest.mark.parametrize("fmt", ["blend", "obj", "ply", "stl"])
def test_save_goes_through_a_checked_temporary_file(bpy, ext, tmp_path, fmt):
    out = tmp_path / f"out.{fmt}"
    out.write_bytes(b"old")
    code, rep = run(ext, DATA / "quad_hole.obj", "-o", out, "--quiet")
    assert code == 0 and rep["written"] is True
    assert out.stat().st_size > 1000 and leftovers(tmp_path) == []
    assert not (tmp_path / f"out.{fmt}1").exists()  # no .blend1 backup of the old file


@pytest.fixture
def full_disk(tmp_path):
    """A 16 KB tmpfs: a full file system for any real output (root only)."""
    mnt = tmp_path / "tiny"
    mnt.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=16k", "tmpfs", str(mnt)],
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


@pytest.mark.parametrize("fmt", ["blend", "obj", "ply", "stl"])
def test_disk_full_exits_2_leaves_no_file_and_keeps_an_existing_one(bpy, ext, tmp_path, capfd,
                                                                    full_disk, fmt):
    """Regression: a full file system gave exit 0, a truncated file and "written": true."""
    out, report = full_disk / f"out.{fmt}", tmp_path / "r.json"
    code, _ = run(ext, DATA / "tri_two_holes.obj", "-o", out, "--report", report, "--quiet")
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and not out.exists() and leftovers(full_disk) == []
    assert f"cannot write output '{out}'" in err[-1]
    saved = json.loads(report.read_text())
    assert saved["written"] is False and saved["exit_code"] == 2
    assert saved["objects"][0]["status"] == "untangled"  # the work was done, not saved
    out.write_bytes(b"previous result")  # an existing output stays intact
    code, _ = run(ext, DATA / "tri_two_holes.obj", "-o", out, "--quiet")
    assert code == 2 and out.read_bytes() == b"previous result"
    assert leftovers(full_disk) == []


@pytest.mark.parametrize("fmt", ["blend", "obj", "ply", "stl"])
def test_truncated_output_is_detected_by_its_format(bpy, ext, tmp_path, fmt):
    """The format checks behind the disk-full check: a file cut short anywhere (here at 60 %,
    and for OBJ also at a line end) is refused; the whole file passes."""
    out = tmp_path / f"whole.{fmt}"
    code, _ = run(ext, DATA / "tri_two_holes.obj", "-o", out, "--quiet")
    assert code == 0
    check = ext.operators.cli._incomplete
    data = out.read_bytes()
    assert check(str(out), f".{fmt}") is None
    cut = tmp_path / f"cut.{fmt}"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    assert "truncated" in check(str(cut), f".{fmt}")
    if fmt == "obj":
        at_line_end = data[: data.rindex(b"\n", 0, int(len(data) * 0.9)) + 1]
        cut.write_bytes(at_line_end)
        assert "faces)" in check(str(cut), ".obj")


def test_background_progress_prints_at_least_every_second(ext, capfd):
    """A line when a phase starts, every 100 iterations, and once a second in between (a
    1M-face run printed nothing for 39 s)."""
    now = [0.0]
    progress = ext.operators.ops_untangle._printer("m", clock=lambda: now[0])
    stats = ext.core.Stats(5, 0.0, 0.5)
    for it, t in [(0, 0.0), (1, 0.3), (2, 0.9), (3, 1.05), (4, 1.5), (5, 2.2), (100, 2.3)]:
        now[0] = t
        assert progress(it, "global", stats) is True
    lines = capfd.readouterr().out.strip().splitlines()
    assert [ln.split(":")[1].strip() for ln in lines] == [
        "global iteration 0", "global iteration 3", "global iteration 5",
        "global iteration 100"]
