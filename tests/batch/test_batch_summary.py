"""The batch's account: exit codes, per-file entries, the progress line, JSON + CSV."""

from __future__ import annotations

import csv
import json
import os

import pytest

from batch import summary


def result(status, code, objects=(), **kw):
    rep = {"objects": list(objects), "written": status in ("ok", "failed"), "skipped": [],
           "error": kw.pop("error", None)}
    return {"index": 0, "input": "in/m.obj", "output": "out/m.obj", "status": status,
            "exit_code": code, "seconds": 2.5, "message": kw.pop("message", ""),
            "host": "h1", "report": rep if objects or code is not None else None, **kw}


def obj(name, n_faces, before, after, backend="numpy", status="untangled"):
    return {"object": name, "status": status, "n_faces": n_faces, "backend": backend,
            "before": dict(zip(("n_inverted", "q_min", "q_avg"), before)),
            "after": dict(zip(("n_inverted", "q_min", "q_avg"), after))}


@pytest.mark.parametrize(("codes", "worst"), [
    ([], 0), ([0, 0], 0), ([0, 3], 3), ([3, 2, 0], 2), ([2, 1, 3], 1), ([0, 7], 1),
])
def test_worst_exit_ranks_internal_over_usage_over_failed(codes, worst):
    assert summary.worst_exit(codes) == worst


def test_file_codes_of_timeouts_crashes_and_skips():
    assert summary.file_code("timeout", None) == 1
    assert summary.file_code("crashed", -11) == 1
    assert summary.file_code("skipped", 0) == 0
    assert summary.file_code("failed", 3) == 3
    assert summary.file_code("error", 2) == 2


def test_batch_exit_is_130_when_interrupted_else_the_worst():
    entries = [summary.file_entry(result("ok", 0)), summary.file_entry(result("failed", 3))]
    assert summary.batch_exit(entries, interrupted=False) == 3
    assert summary.batch_exit(entries, interrupted=True) == 130
    entries.append(summary.file_entry(result("timeout", None)))
    assert summary.batch_exit(entries, interrupted=False) == 1


def test_file_entry_combines_objects_weighted_by_faces():
    e = summary.file_entry(result("failed", 3, [
        obj("A", 100, (10, 0.0, 0.5), (0, 0.6, 0.9)),
        obj("B", 300, (5, 0.0, 0.7), (2, 0.0, 0.8), backend="opencl", status="failed")]))
    assert e["before"] == {"n_inverted": 15, "q_min": 0.0, "q_avg": pytest.approx(0.65)}
    assert e["after"] == {"n_inverted": 2, "q_min": 0.0, "q_avg": pytest.approx(0.825)}
    assert e["backend"] == "numpy,opencl" and e["written"] is True
    assert [o["object"] for o in e["objects"]] == ["A", "B"]


def test_file_entry_without_report_has_no_stats():
    e = summary.file_entry(result("timeout", None, message="timed out after 1 s"))
    assert e["before"] is None and e["after"] is None and e["objects"] == []
    assert e["message"] == "timed out after 1 s" and e["written"] is False


def test_progress_line_counts_rate_and_eta():
    p = summary.Progress(10, width=10)
    assert p.line(now=p.started) == "[----------] 0/10 done, 0 failed, 10 left, 0s"
    for status in ("ok", "ok", "timeout", "skipped"):
        p.add({"status": status})
    assert p.line(now=p.started + 8.0) == \
        "[####------] 4/10 done, 1 failed, 6 left, 8s, 0.50 files/s, ETA 12s"


@pytest.mark.parametrize(("s", "text"), [(0.4, "0s"), (59.6, "1m00s"), (187, "3m07s"),
                                         (7500, "2h05m")])
def test_duration(s, text):
    assert summary.duration(s) == text


def test_reports_json_and_csv_written_side_by_side(tmp_path):
    entries = [summary.file_entry(result("ok", 0, [obj("A", 4, (1, 0.0, 0.5), (0, 0.7, 0.9))])),
               summary.file_entry(result("error", 2, error="eegt: cannot read input 'x':\nbad",
                                         message="eegt: cannot read input 'x':\nbad"))]
    data = {"files": entries, "exit_code": 2}
    path = tmp_path / "r.json"
    csv_path = summary.write_reports(str(path), data)
    assert csv_path == str(tmp_path / "r.csv")
    assert json.loads(path.read_text())["files"][1]["status"] == "error"
    rows = list(csv.reader(open(csv_path, newline="")))
    assert rows[0] == list(summary.CSV_COLUMNS)
    assert rows[1][:8] == ["in/m.obj", "out/m.obj", "ok", "0", "2.500", "1", "1", "0"]
    assert rows[1][8:12] == ["0.000000", "0.700000", "0.500000", "0.900000"]
    assert rows[2][2:4] == ["error", "2"] and rows[2][-1] == "eegt: cannot read input 'x': bad"
    assert sorted(os.listdir(tmp_path)) == ["r.csv", "r.json"]  # no temporary left


def test_csv_path_for_names_without_json_extension():
    assert summary.csv_path_for("a/report.JSON") == "a/report.csv"
    assert summary.csv_path_for("a/report") == "a/report.csv"
