"""The ``eegt`` command with many inputs, in the bpy module: everything a batch decides
before starting a worker (bad input is exit 2 with one line), the flags it hands on, and a
real Dask LocalCluster whose tasks report that their machine has no Blender. Worker
processes running real Blender are tested in tests/e2e (the bpy module has no binary)."""

from __future__ import annotations

import argparse
import csv
import importlib
import json
import os
import shutil
import sys
import time

import pytest

from .conftest import DATA

pytestmark = pytest.mark.blender


def cli(ext):
    return ext.operators.command.entry


def batch(ext):
    # the command imports its batch module on first use: import it here too, so a test
    # run alone does not depend on one that ran before it
    return importlib.import_module(f"{ext.__name__}.operators.command.batch")


@pytest.fixture
def meshes(tmp_path):
    """in/quad_hole.obj, in/sub/tilted_plane.obj."""
    (tmp_path / "in" / "sub").mkdir(parents=True)
    shutil.copy(DATA / "quad_hole.obj", tmp_path / "in")
    shutil.copy(DATA / "tilted_plane.obj", tmp_path / "in" / "sub")
    return tmp_path / "in"


def one_error_line(capfd) -> str:
    err = [ln for ln in capfd.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1, err
    return err[0]


@pytest.mark.parametrize(("argv", "message"), [
    (["{t}/nothing/*.obj", "{t}/empty", "-o", "{t}/out"],
     "eegt: no input files: '{t}/nothing/*.obj' matched no "
     ".blend/.obj/.ply/.stl/.msh/.vtk/.vtu/.inp/.mesh/.su2 files; folder '{t}/empty' has no "
     ".blend/.obj/.ply/.stl/.msh/.vtk/.vtu/.inp/.mesh/.su2 files"),
    (["{m}", "-o", "{t}/afile"], "eegt: output folder '{t}/afile' is a file"),
    (["{m}", "--recursive", "-o", "{t}/one.obj"],
     "eegt: -o {t}/one.obj names one file but 2 inputs matched: give an output folder"),
    (["{m}", "-o", "{t}/out", "--jobs", "0"], "eegt: --jobs must be at least 1 (got 0)"),
    (["{m}", "-o", "{t}/out", "--files-per-worker", "0"],
     "eegt: --files-per-worker must be at least 1 (got 0)"),
    (["{m}", "-o", "{t}/out", "--format", "fbx"],
     "blender -b -c eegt: error: argument --format: invalid choice: 'fbx' (choose from ..."),
    (["{m}", "-o", "{t}/out", "--timeout", "0"],
     "eegt: --timeout must be a positive number of seconds (got 0)"),
    (["{m}", "-o", "{t}/out", "--suffix", "a/b"],
     "eegt: --suffix 'a/b' must not contain a path separator"),
    (["{m}", "--skip-existing"],
     "eegt: --skip-existing needs -o OUTDIR (outputs to compare or name)"),
    (["{m}/quad_hole.obj", "{m}/sub/tilted_plane.obj", "{t}/x/quad_hole.obj", "-o", "{t}/out"],
     "eegt: '{m}/quad_hole.obj' and '{t}/x/quad_hole.obj' would both write "
     "'{t}/out/quad_hole.obj' (use --suffix, or inputs from one folder)"),
    (["{m}", "-o", "{m}"], "eegt: the output of '{m}/quad_hole.obj' would replace it: give "
                           "--in-place to replace it, or another -o folder, a --suffix or a "
                           "--format"),
    (["{m}", "-o", "{t}/out", "--dask", "local:2", "--jobs", "2"],
     "eegt: --jobs is for local workers; with --dask the cluster's workers run the files "
     "(local:N sets their number)"),
    (["{m}", "-o", "{t}/out", "--dask", "local:zero"],
     "eegt: --dask local:zero: local:N needs a whole number N >= 1"),
])
def test_bad_batches_exit_2_with_one_line_and_start_nothing(bpy, ext, tmp_path, meshes, capfd,
                                                            argv, message):
    (tmp_path / "afile").write_text("")
    (tmp_path / "x").mkdir()
    (tmp_path / "empty").mkdir()
    shutil.copy(DATA / "quad_hole.obj", tmp_path / "x")
    fmt = {"t": tmp_path, "m": meshes}
    assert cli(ext).execute([a.format(**fmt) for a in argv]) == 2
    line, expected = one_error_line(capfd), message.format(**fmt)
    if expected.endswith("..."):  # argparse words its choices differently across Pythons
        assert line.startswith(expected[:-3]) and "stl" in line
    else:
        assert line == expected
    assert not (tmp_path / "out" / "eegt_report.json").exists()


def test_dask_missing_exits_2_saying_how_to_install(bpy, ext, tmp_path, meshes, capfd,
                                                    monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    assert cli(ext).execute([str(meshes), "-o", str(tmp_path / "out"), "--dask", "local:2"]) == 2
    line = one_error_line(capfd)
    assert line.startswith("eegt: --dask needs the dask and distributed packages")
    assert "blender -b --python-expr" in line and "--target" in line


@pytest.mark.parametrize("value", ["local:zero", "local:0", " "])
def test_bad_dask_value_is_said_before_a_missing_dask(bpy, ext, tmp_path, meshes, capfd,
                                                      monkeypatch, value):
    monkeypatch.setitem(sys.modules, "distributed", None)
    assert cli(ext).execute([str(meshes), "-o", str(tmp_path / "out"), "--dask", value]) == 2
    line = one_error_line(capfd)
    assert line.startswith(f"eegt: --dask {value.strip()}".rstrip()) and "packages" not in line


def test_dask_scheduler_not_listening_is_exit_2_in_seconds(bpy, ext, tmp_path, meshes, capfd):
    pytest.importorskip("distributed", reason="--dask needs the distributed package, which "
                                              "this Python lacks")
    t0 = time.monotonic()
    code = cli(ext).execute([str(meshes), "-o", str(tmp_path / "out"), "--dask",
                             "tcp://127.0.0.1:1"])
    seconds = time.monotonic() - t0
    assert code == 2 and seconds < 8
    assert one_error_line(capfd) == ("eegt: cannot connect to the Dask scheduler at "
                                     "tcp://127.0.0.1:1: connection refused (is `dask "
                                     "scheduler` running there?)")
    assert not (tmp_path / "out").exists()  # checked before the output folder is made


@pytest.mark.parametrize("argv", [["{m}", "--in-place"], ["{m}", "-o", "{m}", "--in-place"]])
def test_in_place_batch_writes_each_input_over_itself(bpy, ext, tmp_path, meshes, monkeypatch,
                                                     argv):
    monkeypatch.setenv("EEGT_BLENDER", sys.executable)  # planned, never started
    b = batch(ext)
    argv = [a.format(m=meshes) for a in argv] + ["--recursive", "--quiet"]
    parser = b.build_parser()
    ns = parser.parse_intermixed_args(argv)
    p = b.plan(ns, parser, argv)
    files = [str(meshes / "quad_hole.obj"), str(meshes / "sub" / "tilted_plane.obj")]
    assert [(t["input"], t["output"]) for t in p.tasks] == list(zip(files, files))
    assert all("--in-place" in t["args"] for t in p.tasks)
    argv = ext.batch.worker.file_args(p.tasks[0], "r.json")
    back = ext.operators.command.parser.build_parser().parse_args(argv)
    assert back.output == back.input == files[0] and back.in_place is True


def test_in_place_batch_skip_existing_still_runs_every_file(bpy, ext, meshes, monkeypatch):
    monkeypatch.setenv("EEGT_BLENDER", sys.executable)  # planned, never started
    b = batch(ext)
    argv = [str(meshes), "-o", str(meshes), "--in-place", "--skip-existing", "--recursive"]
    parser = b.build_parser()
    p = b.plan(parser.parse_intermixed_args(argv), parser, argv)
    assert len(p.tasks) == 2 and p.entries == [None, None]


def test_no_blender_binary_for_workers_is_exit_2(bpy, ext, tmp_path, meshes, capfd, monkeypatch):
    monkeypatch.setenv("EEGT_BLENDER", str(tmp_path / "no-blender"))
    assert cli(ext).execute([str(meshes), "-o", str(tmp_path / "out")]) == 2
    assert one_error_line(capfd) == (
        f"eegt: cannot start workers: EEGT_BLENDER={tmp_path / 'no-blender'} is not an "
        "executable file (set EEGT_BLENDER to a Blender binary with this extension)")


def test_skip_existing_with_every_output_up_to_date_runs_nothing(bpy, ext, tmp_path, meshes,
                                                                 capfd, monkeypatch):
    monkeypatch.setenv("EEGT_BLENDER", str(tmp_path / "no-blender"))  # must not be needed
    out = tmp_path / "out"
    (out / "sub").mkdir(parents=True)
    (out / "quad_hole.obj").write_text("done")
    (out / "sub" / "tilted_plane.obj").write_text("done")
    (meshes / "gone.obj").symlink_to(tmp_path / "nowhere.obj")  # an unreadable explicit input
    code = cli(ext).execute([str(meshes), str(meshes / "gone.obj"), "--recursive", "-o", str(out),
                             "--skip-existing", "--quiet"])
    assert code == 2  # the unreadable one
    rep = json.loads((out / "eegt_report.json").read_text())
    assert rep["kind"] == "batch" and rep["exit_code"] == 2 and rep["interrupted"] is False
    assert [(os.path.relpath(f["input"], meshes), f["status"]) for f in rep["files"]] == [
        ("quad_hole.obj", "skipped"), (os.path.join("sub", "tilted_plane.obj"), "skipped"),
        ("gone.obj", "error")]
    assert rep["files"][2]["message"] == f"eegt: cannot read input '{meshes / 'gone.obj'}': " \
                                         "no such file"
    assert rep["counts"]["skipped"] == 2 and rep["counts"]["error"] == 1
    rows = list(csv.DictReader(open(out / "eegt_report.csv", newline="")))
    assert [r["status"] for r in rows] == ["skipped", "skipped", "error"]
    assert (out / "quad_hole.obj").read_text() == "done"  # untouched
    assert "3 files in" in capfd.readouterr().out


def test_batch_help_lists_batch_and_single_file_flags(bpy, ext, capfd):
    assert cli(ext).execute(["--help"]) == 0
    out = capfd.readouterr().out
    for flag in ("--jobs", "--timeout", "--skip-existing", "--recursive", "--suffix", "--format",
                 "--dask", "--no-write-on-fail", "--max-untangle-iterations", "--object"):
        assert flag in out, flag


def _a_value(a) -> str:
    """A command-line text that flag `a` accepts and that differs from its default."""
    if a.choices:
        return str(list(a.choices)[-1])
    if a.type in (int, float):
        return "7" if a.type is int else "0.1234567890123"
    for text in ("all", "x y", "1", "0.5"):  # a flag with its own parser (e.g. a name list)
        try:
            if a.type is None or a.type(text) != a.default:
                return text
        except (ValueError, TypeError, argparse.ArgumentTypeError):
            pass
    raise AssertionError(f"no value found for {a.option_strings}")


def test_every_single_file_flag_reaches_the_workers_unchanged(bpy, ext):
    """Each single-file flag given a non-default value, through the batch parser and the
    hand-on, reads back to the same value in the single-file parser."""
    single = ext.operators.command.parser.build_parser()
    argv = ["a.obj", "b.obj", "-o", "out", "--report", "r.json", "--jobs", "2"]
    for a in single._actions:
        if not a.option_strings or a.dest in ("help", "output", "report"):
            continue
        flag = next(s for s in a.option_strings if s.startswith("--"))
        if isinstance(a, argparse.BooleanOptionalAction):
            argv.append("--no-" + flag[2:])
        elif a.nargs == 0:
            argv.append(flag)
        elif isinstance(a, argparse._AppendAction):
            argv += [flag, "Plate", f"{flag}=-odd name"]
        else:
            argv.append(f"{flag}={_a_value(a)}")
    bp = batch(ext).build_parser()
    ns = bp.parse_intermixed_args(argv)
    tokens = ext.batch.arguments.passthrough(bp, argv)
    back = single.parse_args(["in.obj", *tokens])
    compared = 0
    for a in single._actions:
        if a.option_strings and a.dest not in ("help", "output", "report"):
            assert getattr(back, a.dest) == getattr(ns, a.dest), a.dest
            assert getattr(back, a.dest) != a.default, a.dest
            compared += 1
    assert compared >= 20


def test_single_file_command_lines_keep_the_single_file_path(bpy, ext, tmp_path):
    out, rep = tmp_path / "o.obj", tmp_path / "r.json"
    argv = [str(DATA / "quad_hole.obj"), "-o", str(out), "--report", str(rep), "--quiet"]
    assert not batch(ext).is_batch(argv)
    assert cli(ext).execute(argv) == 0
    report = json.loads(rep.read_text())
    assert report["input"] == str(DATA / "quad_hole.obj") and "kind" not in report


def test_dask_local_cluster_tasks_report_a_machine_without_blender(bpy, ext, tmp_path, meshes,
                                                                   capfd, monkeypatch):
    """A real LocalCluster of 2 worker processes: the worker module is uploaded, every task
    runs on a worker and reports, as a per-file error, that this machine has no Blender."""
    pytest.importorskip("distributed", reason="--dask needs the distributed package, which "
                                              "this Python lacks")
    monkeypatch.setenv("EEGT_BLENDER", str(tmp_path / "no-blender"))  # workers inherit it
    out = tmp_path / "out"
    code = cli(ext).execute([str(meshes), "--recursive", "-o", str(out), "--dask", "local:2",
                             "--quiet"])
    assert code == 2
    rep = json.loads((out / "eegt_report.json").read_text())
    assert rep["mode"] == "dask" and rep["dask"] == "local:2" and rep["counts"]["error"] == 2
    for f in rep["files"]:
        assert f["status"] == "error" and f["exit_code"] == 2 and f["host"]
        assert f["message"] == (f"eegt: EEGT_BLENDER={tmp_path / 'no-blender'} is not an "
                                f"executable file on {f['host']}")
    assert (out / "sub").is_dir()  # the task made the output folder on its worker
    assert "Dask cluster tcp://127.0.0.1:" in capfd.readouterr().out


def test_served_files_match_fresh_runs_and_each_leaves_its_report(bpy, ext, tmp_path):
    """A worker Blender serving several files in turn (--files-per-worker) writes what a
    fresh single-file run writes, byte for byte, and a report for each, also for a file it
    cannot read."""
    worker = ext.batch.worker
    tasks = [{"index": i, "input": str(DATA / f"{m}.obj"), "output": str(tmp_path / f"{m}.obj"),
              "args": ["--max-smooth-iterations=40"]}
             for i, m in enumerate(["polygon_voronoi", "quad_hole", "no_such_mesh"])]
    lines = [json.dumps(worker.file_args(t, str(tmp_path / f"{t['index']}.json"))) + "\n"
             for t in tasks]
    assert batch(ext).serve(["not json\n", *lines]) == 0
    reports = [json.loads((tmp_path / f"{i}.json").read_text()) for i in range(3)]
    assert [r["exit_code"] for r in reports] == [0, 0, 2]
    assert "no such file" in reports[2]["error"]
    for t in tasks[:2]:
        fresh = tmp_path / "fresh.obj"
        assert cli(ext).execute([t["input"], "-o", str(fresh), "--quiet", *t["args"]]) == 0
        assert fresh.read_bytes() == open(t["output"], "rb").read()


def test_uv_batch_files_are_summed_up_with_uv_stats(bpy, ext, tmp_path):
    """``eegt DIR -o OUT --uv``: each worker's UV report (served in turn, as a batch's
    worker Blender does) goes into the batch's JSON + CSV summary with its UV stats (it
    once raised KeyError 'q_avg')."""
    from .uvtools import tangled
    worker, summary = (importlib.import_module(f"{ext.__name__}.batch.{m}")
                       for m in ("worker", "summary"))
    tasks = []
    for i, kind in enumerate(("sphere", "organic")):
        bpy.ops.wm.read_homefile(use_empty=True)
        tangled(bpy, kind, "jitter").name = f"{kind.title()}UV"
        path = tmp_path / f"{kind}.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(path))
        tasks.append({"index": i, "input": str(path), "output": str(tmp_path / "out" /
                                                                      f"{kind}.blend"),
                      "args": ["--uv"]})
    (tmp_path / "out").mkdir()
    lines = [json.dumps(worker.file_args(t, str(tmp_path / f"{t['index']}.json"))) + "\n"
             for t in tasks]
    assert batch(ext).serve(lines) == 0
    entries = []
    for t in tasks:
        rep = json.loads((tmp_path / f"{t['index']}.json").read_text())
        assert rep["exit_code"] == 0 and all(o["kind"] == "uv" for o in rep["objects"])
        entries.append(summary.file_entry(worker._from_report(t, rep, 1.0, 0, "")))
    for e, name in zip(entries, ("SphereUV", "OrganicUV")):
        assert e["status"] == "ok" and e["kind"] == "uv"
        assert [o["object"] for o in e["objects"]] == [name]
        assert e["before"]["inverted"] > 0 and e["after"]["inverted"] == 0
        assert e["after"]["flipped"] == 0 and "q_avg" not in e["after"]
    csv_path = summary.write_reports(str(tmp_path / "r.json"), {"files": entries})
    rows = list(csv.reader(open(csv_path, newline="")))
    got = [dict(zip(rows[0], r)) for r in rows[1:]]
    assert [r["kind"] for r in got] == ["uv", "uv"]
    assert all(int(r["uv_inverted_before"]) > 0 and r["uv_inverted_after"] == "0" for r in got)
