"""When a command line is a batch, and the single-file flags handed on to each worker."""

from __future__ import annotations

import argparse
import os
import socket
import time

import pytest
from eegt_blender.batch import arguments, dask_pool, worker


def single_parser():
    """A parser with the kinds of flags the single-file command has."""
    p = argparse.ArgumentParser(prog="eegt")
    p.add_argument("input")
    p.add_argument("-o", "--output")
    p.add_argument("--report")
    p.add_argument("--object", action="append", default=[])
    p.add_argument("--backend", choices=("numpy", "opencl"), default=None)
    p.add_argument("--a", dest="a", type=float, default=None)
    p.add_argument("--max-iterations", dest="max_iterations", type=int, default=None)
    p.add_argument("--global-stage", dest="global_stage", default=None,
                   action=argparse.BooleanOptionalAction)
    p.add_argument("--quiet", action="store_true")
    p.add_argument("--names", type=lambda t: tuple(t.split(",")), default=())
    p.add_argument("-v", "--verbose", action="count")
    return p


def batch_parser():
    p = single_parser()
    arguments.add_batch_arguments(p)
    return p


def test_batch_parser_takes_many_inputs_between_flags():
    ns = batch_parser().parse_intermixed_args(["a.obj", "--jobs", "2", "b.obj", "-o", "out"])
    assert ns.input == ["a.obj", "b.obj"] and ns.jobs == 2 and ns.output == "out"


def test_passthrough_hands_on_every_single_file_flag_as_given():
    argv = ["x.obj", "--object", "A", "--object=-B", "--backend", "opencl", "--a", "1e-1",
            "--max-iterations", "7", "--no-global-stage", "--quiet", "-o", "out",
            "--report", "r.json", "--jobs", "3", "--timeout", "9.5", "--suffix", "_f",
            "--names", "p,q", "-vv", "y.obj"]
    bp = batch_parser()
    ns = bp.parse_intermixed_args(argv)
    tokens = arguments.passthrough(bp, argv)
    assert tokens == ["--object=A", "--object=-B", "--backend=opencl", "--a=1e-1",
                      "--max-iterations=7", "--no-global-stage", "--quiet", "--names=p,q",
                      "--verbose", "--verbose"]
    back = single_parser().parse_args(["in.obj", *tokens])
    for dest in ("object", "backend", "a", "max_iterations", "global_stage", "quiet", "names",
                 "verbose"):
        assert getattr(back, dest) == getattr(ns, dest), dest
    assert back.output is None and back.report is None  # set per file by the batch
    # the parser's types are back: a second parse converts again
    assert bp.parse_intermixed_args(argv).a == 0.1 and ns.names == ("p", "q")


def test_passthrough_leaves_flags_not_given_out():
    bp = batch_parser()
    assert arguments.passthrough(bp, ["a.obj", "b.obj", "--jobs", "2"]) == []


@pytest.mark.parametrize("argv", [["a.obj", "--jobs", "0"], ["a.obj", "-j2"], ["a.obj", "--ti=3"],
                                  ["a.obj", "--format", "fbx"], ["a.obj", "--skip-existing"]])
def test_batch_flags_are_seen_even_when_their_value_is_bad(argv):
    assert arguments.batch_flag_in(argv)


def test_single_file_command_lines_are_not_batches(tmp_path):
    f = tmp_path / "m.obj"
    f.write_text("v 0 0 0\n")
    bp = batch_parser()
    for argv in ([str(f)], [str(f), "-o", str(tmp_path / "o.obj")], [str(tmp_path / "no.obj")],
                 [str(f), "--object", "A", "--quiet"]):
        assert not arguments.batch_flag_in(argv)
        assert not arguments.is_batch(bp.parse_intermixed_args(argv)), argv


def test_many_inputs_folders_globs_output_folders_and_flags_are_batches(tmp_path):
    f = tmp_path / "m.obj"
    f.write_text("v 0 0 0\n")
    bp = batch_parser()
    for argv in ([str(f), str(f)], [str(tmp_path)], [str(tmp_path / "*.obj")],
                 [str(f), "-o", str(tmp_path)], [str(f), "-o", "newdir" + os.sep],
                 [str(f), "--jobs", "0"], [str(f), "--recursive"]):
        assert arguments.is_batch(bp.parse_intermixed_args(argv)), argv


def test_worker_command_line_is_the_single_file_command():
    task = {"input": "in/m.obj", "output": "out/m.ply", "args": ["--a=0.1"]}
    assert worker.command("/bin/blender", task, "/tmp/r.json") == [
        "/bin/blender", "-b", "-c", "eegt", "in/m.obj", "-o", "out/m.ply",
        "--report", "/tmp/r.json", "--quiet", "--a=0.1"]
    task["output"] = None
    assert "-o" not in worker.command("/bin/blender", task, "/tmp/r.json")


def test_find_blender_prefers_eegt_blender_and_says_why_not(monkeypatch, tmp_path):
    exe = tmp_path / "blender"
    exe.write_text("#!/bin/sh\n")
    exe.chmod(0o755)
    monkeypatch.setenv("EEGT_BLENDER", str(exe))
    assert worker.find_blender("/nowhere/blender") == (str(exe), "")
    monkeypatch.setenv("EEGT_BLENDER", str(tmp_path / "missing"))
    assert worker.find_blender(str(exe)) == \
        (None, f"EEGT_BLENDER={tmp_path / 'missing'} is not an executable file")
    monkeypatch.delenv("EEGT_BLENDER")
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    assert worker.find_blender(str(exe)) == (str(exe), "")
    found, why = worker.find_blender(str(tmp_path / "nope"))
    assert found is None and "no Blender binary" in why


def test_precheck_names_a_missing_input_and_the_shared_storage_rule(tmp_path):
    msg = worker.precheck({"input": str(tmp_path / "gone.obj"), "output": None})
    assert msg.startswith(f"eegt: input '{tmp_path / 'gone.obj'}' not found on ")
    assert "storage every worker sees" in msg
    f = tmp_path / "m.obj"
    f.write_text("")
    assert worker.precheck({"input": str(f), "output": str(tmp_path / "a" / "b" / "m.obj")}) \
        is None
    assert (tmp_path / "a" / "b").is_dir()  # output folders made on the worker


def test_run_task_without_blender_is_a_per_file_error(monkeypatch, tmp_path):
    f = tmp_path / "m.obj"
    f.write_text("")
    monkeypatch.setenv("EEGT_BLENDER", str(tmp_path / "missing"))
    res = worker.run_task({"index": 4, "input": str(f), "output": None, "blender": None})
    assert res["status"] == "error" and res["exit_code"] == 2 and res["index"] == 4
    assert res["message"].startswith(f"eegt: EEGT_BLENDER={tmp_path / 'missing'} is not an "
                                     "executable file on ")


@pytest.mark.parametrize(("address", "parsed"), [("local", ("local", None)),
                                                 ("local:3", ("local", 3)),
                                                 ("tcp://h:8786", ("remote", None))])
def test_dask_addresses(address, parsed):
    assert dask_pool.parse_address(address) == parsed


@pytest.mark.parametrize("address", ["local:0", "local:x", " "])
def test_bad_dask_addresses_are_one_line_errors(address):
    with pytest.raises(dask_pool.DaskError, match=r"^eegt: --dask"):
        dask_pool.parse_address(address)


def test_unreachable_scheduler_is_refused_within_the_connect_timeout():
    """Nothing listens on port 1: refused at once; no Dask needed to tell."""
    t0 = time.monotonic()
    with pytest.raises(dask_pool.DaskError) as err:
        dask_pool.probe("tcp://127.0.0.1:1")
    assert time.monotonic() - t0 < dask_pool.CONNECT_TIMEOUT
    assert str(err.value) == ("eegt: cannot connect to the Dask scheduler at tcp://127.0.0.1:1: "
                              "connection refused (is `dask scheduler` running there?)")
    assert dask_pool.CONNECT_TIMEOUT <= 5


def test_probe_connects_to_a_listening_scheduler_port():
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        port = server.getsockname()[1]
        for address in (f"tcp://127.0.0.1:{port}", f"127.0.0.1:{port}"):
            dask_pool.probe(address)  # no error


@pytest.mark.parametrize("address", ["tcp://127.0.0.1", "tcp://127.0.0.1:port"])
def test_scheduler_address_without_a_port_number_is_a_bad_value(address):
    with pytest.raises(dask_pool.DaskError) as err:
        dask_pool.probe(address)
    assert str(err.value) == (f"eegt: --dask {address}: a scheduler address is "
                              "tcp://HOST:PORT (its port is 8786 unless it was started with "
                              "another)")


def test_missing_dask_says_how_to_install_it(monkeypatch):
    import sys
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(dask_pool.DaskError) as err:
        dask_pool.require()
    msg = str(err.value)
    assert "\n" not in msg and "--dask needs the dask and distributed packages" in msg
    assert "'pip', 'install', '--target', bpy.utils.user_resource('SCRIPTS', path='modules'" in msg
    assert "'dask[distributed]'" in msg and "python3-distributed" in msg


def test_dask_chunks_deal_files_round_robin_one_chunk_per_worker_at_least():
    tasks = [{"index": i} for i in range(10)]
    assert dask_pool.chunked(tasks, 1, 2) == [[t] for t in tasks]
    chunks = dask_pool.chunked(tasks, 20, 2)  # 10 files, 2 workers: 2 chunks of 5
    assert [[t["index"] for t in c] for c in chunks] == [[0, 2, 4, 6, 8], [1, 3, 5, 7, 9]]
    chunks = dask_pool.chunked(tasks, 3, 2)  # at most 3 per chunk: 4 chunks
    assert [[t["index"] for t in c] for c in chunks] == [[0, 4, 8], [1, 5, 9], [2, 6], [3, 7]]
    assert [len(c) for c in dask_pool.chunked(tasks[:1], 5, 4)] == [1]
