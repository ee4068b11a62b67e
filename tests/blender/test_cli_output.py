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
    return ext.operators.command.cli.run([str(a) for a in argv])


def leftovers(folder) -> list[str]:
    return sorted(n for n in os.listdir(folder) if ".eegt-tmp-" in n)


def test_unsupported_output_type_fails_before_loading_the_input(bpy, ext, tmp_path, capfd):
    code, rep = run(ext, DATA / "naca_deform.obj", "-o", tmp_path / "x.fbx")
    assert code == 2 and rep["written"] is False
    assert capfd.readouterr().err.strip() == (
        "eegt: unsupported output type '.fbx' (use .blend, .obj, .ply, .stl, .msh, .vtk, .vtu, "
        ".inp, .mesh or .su2)")
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


@pytest.mark.parametrize("report", ["/proc/nope/r.json", "{tmp}/missing/r.json"])
def test_unwritable_report_is_said_once(bpy, ext, tmp_path, capfd, report):
    report = report.format(tmp=tmp_path)
    code, rep = run(ext, DATA / "quad_hole.obj", "--report", report, "--quiet")
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and err == [f"eegt: cannot write report '{report}': no folder "
                                 f"{os.path.dirname(report)}"]
    assert rep["error"] == err[0] and rep["exit_code"] == 2


def test_output_folder_missing_fails_before_computing(bpy, ext, tmp_path, capfd):
    code, _ = run(ext, DATA / "quad_hole.obj", "-o", tmp_path / "nope" / "out.obj")
    assert code == 2 and len(bpy.data.objects) == 0
    assert "no folder" in capfd.readouterr().err


def test_directory_input_says_is_a_directory(bpy, ext, tmp_path, capfd):
    code, rep = run(ext, tmp_path, "-o", tmp_path / "out.obj")
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].endswith("is a directory") and "no such file" not in err[-1]
    assert rep["error"].endswith("is a directory")


def exits_2_writing_nothing(ext, tmp_path, capfd, text: str) -> list[str]:
    """Runs the command on an OBJ of ``text``, with and without --no-write-on-fail: exit 2,
    no output file, written false each time; the last stderr line of each run."""
    src, out = tmp_path / "in.obj", tmp_path / "out.obj"
    src.write_text(text)
    lines = []
    for extra in ([], ["--no-write-on-fail"]):
        code, rep = run(ext, src, "-o", out, *extra)
        err = capfd.readouterr().err.strip().splitlines()
        assert code == 2 and not out.exists() and rep["written"] is False
        lines.append(err[-1])
    return lines


@pytest.mark.parametrize("text", [
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nl 1 2\nl 2 3\n",  # edges only
    "v 0 0 0\nv 1 0 0\n",  # points only
], ids=["edges only", "points only"])
def test_input_of_a_faceless_mesh_says_no_faces_exits_2_and_writes_nothing(bpy, ext, tmp_path,
                                                                           capfd, text):
    want = (f"eegt: input '{tmp_path / 'in.obj'}' has no faces to work on (1 mesh object, "
            "edges or points only)")
    assert exits_2_writing_nothing(ext, tmp_path, capfd, text) == [want, want]


@pytest.mark.parametrize("text", [
    "",  # empty file
    "this is not an obj file\nat all\n",  # garbage the importer skips
], ids=["empty file", "garbage"])
def test_input_with_no_mesh_object_says_nothing_to_work_on_exits_2_and_writes_nothing(
        bpy, ext, tmp_path, capfd, text):
    want = f"eegt: input '{tmp_path / 'in.obj'}' has no mesh objects (nothing to work on)"
    assert exits_2_writing_nothing(ext, tmp_path, capfd, text) == [want, want]


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
    assert rep["skipped"] == [{"object": "edges", "reason": "no faces"}]
    assert json.loads(report.read_text())["skipped"] == rep["skipped"]
    assert "EEGT edges: skipped: no faces" in capfd.readouterr().out


@pytest.mark.parametrize("fmt", ["blend", "obj", "ply", "stl"])
def test_save_goes_through_a_checked_temporary_file(bpy, ext, tmp_path, fmt):
    out = tmp_path / f"out.{fmt}"
    out.write_bytes(b"old")
    code, rep = run(ext, DATA / "quad_hole.obj", "-o", out, "--quiet")
    assert code == 0 and rep["written"] is True
    assert out.stat().st_size > 1000 and leftovers(tmp_path) == []
    assert not (tmp_path / f"out.{fmt}1").exists()  # no .blend1 backup of the old file


def mount_tmpfs(folder, *options: str) -> None:
    """Mount a 16 KB tmpfs on `folder`, or skip the test saying why it cannot be done."""
    folder.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", ",".join(["size=16k", *options]),
                           "tmpfs", str(folder)], capture_output=True, text=True, check=False)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")


@pytest.fixture
def full_disk(tmp_path):
    """A 16 KB tmpfs: a full file system for any real output (root only)."""
    mnt = tmp_path / "tiny"
    mount_tmpfs(mnt)
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


@pytest.fixture
def read_only_folder(tmp_path):
    """A folder that exists but cannot be written, even by root (a read-only tmpfs)."""
    mnt = tmp_path / "ro"
    mount_tmpfs(mnt, "ro")
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
    check = ext.operators.command.output_files.incomplete
    data = out.read_bytes()
    assert check(str(out), f".{fmt}") is None
    cut = tmp_path / f"cut.{fmt}"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    assert "truncated" in check(str(cut), f".{fmt}")
    if fmt == "obj":
        at_line_end = data[: data.rindex(b"\n", 0, int(len(data) * 0.9)) + 1]
        cut.write_bytes(at_line_end)
        assert "faces)" in check(str(cut), ".obj")


def test_compressed_blend_truncation_is_detected_by_its_seek_table(bpy, ext, tmp_path):
    """A compressed .blend (zstd frames and a seek table) passes whole and fails cut short
    anywhere, even by one byte; so does an uncompressed one, and a file of neither kind."""
    from .conftest import import_obj

    import_obj(bpy, "tri_two_holes")
    check = ext.operators.command.output_files.incomplete
    for compress in (True, False):
        whole = tmp_path / f"whole{int(compress)}.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(whole), copy=True, compress=compress)
        data = whole.read_bytes()
        assert data.startswith(b"\x28\xb5\x2f\xfd" if compress else b"BLENDER")
        assert check(str(whole), ".blend") is None
        cut = tmp_path / "cut.blend"
        for n in (10, len(data) // 2, len(data) - 33, len(data) - 1):
            cut.write_bytes(data[:n])
            assert "truncated" in check(str(cut), ".blend"), (compress, n)
    cut.write_bytes(b"no blend at all")
    assert check(str(cut), ".blend") == "not a .blend file"


@pytest.mark.parametrize("fmt", ["stl", "ply"])
def test_stl_and_ply_cut_anywhere_are_refused(bpy, ext, tmp_path, fmt):
    """Binary STL and PLY: a cut inside the header or one byte short is refused too."""
    out = tmp_path / f"whole.{fmt}"
    assert run(ext, DATA / "quad_hole.obj", "-o", out, "--quiet")[0] == 0
    data, cut = out.read_bytes(), tmp_path / f"cut.{fmt}"
    for n in (1, 50, len(data) - 1):
        cut.write_bytes(data[:n])
        assert "truncated" in ext.operators.command.output_files.incomplete(str(cut), f".{fmt}"), n


def test_report_that_fails_at_the_end_leaves_no_output(bpy, ext, tmp_path, capfd, full_disk):
    """The report is written before the output is renamed into place: when the report
    cannot be written (its disk is full, though it was creatable up front), exit 2 leaves
    nothing at the output, no temporary file and no half report."""
    filler = full_disk / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT)
    try:  # fill the tmpfs to the last byte
        while os.write(fd, b"x" * 1024):
            pass
    except OSError:
        pass
    finally:
        os.close(fd)
    out, report = tmp_path / "out.obj", full_disk / "r.json"
    code, rep = run(ext, DATA / "quad_hole.obj", "-o", out, "--report", report, "--quiet")
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and f"cannot write report '{report}'" in err[-1]
    assert not out.exists() and not report.exists()
    assert leftovers(tmp_path) == [] and leftovers(full_disk) == []
    assert rep["written"] is False and rep["objects"][0]["status"] == "untangled"


@pytest.mark.parametrize("what", ["output", "report"])
def test_read_only_target_fails_before_loading_the_input(bpy, ext, tmp_path, capfd,
                                                         read_only_folder, what):
    """A folder that exists but is read-only is found up front, not after the work."""
    out, report = tmp_path / "out.obj", tmp_path / "r.json"
    target = read_only_folder / ("out.obj" if what == "output" else "r.json")
    argv = ["-o", target, "--report", report] if what == "output" else \
        ["-o", out, "--report", target]
    code, rep = run(ext, DATA / "quad_hole.obj", *argv)
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1] == f"eegt: cannot write {what} '{target}': read-only file system"
    assert len(bpy.data.objects) == 0 and rep["objects"] == [] and rep["written"] is False
    assert not out.exists() and os.listdir(read_only_folder) == []


def test_failed_rename_keeps_the_old_output_and_reports_not_written(bpy, ext, tmp_path,
                                                                    capfd, monkeypatch):
    """The last step can fail too (the rename onto the target): exit 2, the old file kept,
    no temporary file, and the report (still written) says "written": false."""
    out, report = tmp_path / "out.ply", tmp_path / "r.json"
    out.write_bytes(b"old result")
    real = os.replace

    def replace(src, dst):
        if str(dst) == str(out):
            raise OSError(5, "Input/output error")
        real(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    code, _ = run(ext, DATA / "quad_hole.obj", "-o", out, "--report", report, "--quiet")
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1] == f"eegt: cannot write output '{out}': input/output error"
    assert out.read_bytes() == b"old result" and leftovers(tmp_path) == []
    saved = json.loads(report.read_text())
    assert saved["written"] is False and saved["exit_code"] == 2
    assert saved["error"] == err[-1]


def test_symlinked_output_and_report_are_written_through_and_kept_as_links(bpy, ext,
                                                                            tmp_path):
    """The temporary file goes beside a link's target and replaces the target: the link
    stays a link, pointing at the new file."""
    real = tmp_path / "real"
    real.mkdir()
    (real / "out.stl").write_bytes(b"old")
    (real / "r.json").write_text("{}")
    out, report = tmp_path / "out.stl", tmp_path / "r.json"
    out.symlink_to(real / "out.stl")
    report.symlink_to(real / "r.json")
    code, _ = run(ext, DATA / "quad_hole.obj", "-o", out, "--report", report, "--quiet")
    assert code == 0 and out.is_symlink() and report.is_symlink()
    assert (real / "out.stl").stat().st_size == 84 + 50 * 280
    assert json.loads((real / "r.json").read_text())["written"] is True
    assert leftovers(tmp_path) == [] and leftovers(real) == []


def test_report_to_a_device_is_written_not_replaced(bpy, ext, tmp_path):
    """`--report /dev/null` must not replace the device by a file (as root it could): a
    private null device node stands in for it."""
    import stat

    node = tmp_path / "null"
    try:
        os.mknod(node, stat.S_IFCHR | 0o666, os.makedev(1, 3))
        node.open("w").close()
    except OSError as exc:
        pytest.skip(f"cannot make a device node here: {exc}")
    code, rep = run(ext, DATA / "quad_hole.obj", "--report", node, "--quiet")
    assert code == 0 and rep["exit_code"] == 0
    assert stat.S_ISCHR(node.stat().st_mode) and leftovers(tmp_path) == []


def test_background_progress_prints_at_least_every_second(ext, capfd):
    """A line when a phase starts, every 100 iterations, and once a second in between (a
    1M-face run printed nothing for 39 s)."""
    now = [0.0]
    progress = ext.operators.shared.progress.printer("m", clock=lambda: now[0])
    stats = ext.core.Stats(5, 0.0, 0.5)
    for it, t in [(0, 0.0), (1, 0.3), (2, 0.9), (3, 1.05), (4, 1.5), (5, 2.2), (100, 2.3)]:
        now[0] = t
        assert progress(it, "global", stats) is True
    lines = capfd.readouterr().out.strip().splitlines()
    assert [ln.split(":")[1].strip() for ln in lines] == [
        "global iteration 0", "global iteration 3", "global iteration 5",
        "global iteration 100"]
