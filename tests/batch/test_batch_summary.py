"""The batch's account: exit codes, per-file entries, the progress line, JSON + CSV."""

from __future__ import annotations

import csv
import json
import os

import pytest
from eegt_blender.batch import summary


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


def uv_obj(name, n_faces, before, after, status="untangled"):
    keys = ("flipped", "inverted", "overlapping", "distortion_mean", "distortion_worst")
    return {"kind": "uv", "object": name, "uv_map": "UVMap", "status": status,
            "n_faces": n_faces, "backend": "numpy",
            "before": {"n_faces": n_faces, "zero_area": 0, **dict(zip(keys, before))},
            "after": {"n_faces": n_faces, "zero_area": 0, **dict(zip(keys, after))}}


def test_file_entry_of_a_uv_run_combines_uv_stats():
    e = summary.file_entry(result("ok", 0, [
        uv_obj("A", 100, (10, 12, 20, 0.5, 0.0), (0, 0, 0, 0.9, 0.6)),
        uv_obj("B", 300, (5, 6, 8, 0.7, 0.1), (0, 0, 2, 0.8, 0.3))]))
    assert e["kind"] == "uv"
    assert e["before"] == {"flipped": 15, "inverted": 18, "overlapping": 28,
                           "distortion_mean": pytest.approx(0.65), "distortion_worst": 0.0}
    assert e["after"] == {"flipped": 0, "inverted": 0, "overlapping": 2,
                          "distortion_mean": pytest.approx(0.825), "distortion_worst": 0.3}


def test_file_entry_kind_of_mesh_runs_and_of_a_uv_entry_without_kind():
    e = summary.file_entry(result("ok", 0, [obj("A", 4, (1, 0.0, 0.5), (0, 0.7, 0.9))]))
    assert e["kind"] == "mesh"
    old = uv_obj("A", 4, (1, 1, 0, 0.5, 0.1), (0, 0, 0, 0.9, 0.7))
    del old["kind"]  # a report of an older worker: its stats tell the kind
    assert summary.file_entry(result("ok", 0, [old]))["kind"] == "uv"
    assert summary.file_entry(result("timeout", None))["kind"] is None
    entries = [summary.file_entry(result("ok", 0, [obj("A", 4, (1, 0.0, 0.5), (0, 0.7, 0.9))])),
               summary.file_entry(result("ok", 0, [old])),
               summary.file_entry(result("ok", 0, [old])),
               summary.file_entry(result("timeout", None))]
    assert summary.kinds(entries) == {"mesh": 1, "uv": 2}


def test_reports_csv_has_the_uv_columns_beside_the_mesh_ones(tmp_path):
    entries = [summary.file_entry(result("ok", 0, [obj("A", 4, (1, 0.0, 0.5), (0, 0.7, 0.9))])),
               summary.file_entry(result("ok", 0, [
                   uv_obj("U", 4, (2, 3, 4, 0.25, 0.0), (0, 0, 1, 0.75, 0.5))]))]
    csv_path = summary.write_reports(str(tmp_path / "r.json"), {"files": entries})
    rows = list(csv.reader(open(csv_path, newline="")))
    head = rows[0]
    for col in ("kind", "inverted_before", "q_avg_after", "uv_flipped_before",
                "uv_flipped_after", "uv_inverted_before", "uv_inverted_after",
                "uv_overlapping_before", "uv_overlapping_after",
                "uv_distortion_mean_before", "uv_distortion_mean_after",
                "uv_distortion_worst_before", "uv_distortion_worst_after"):
        assert col in head
    mesh, uv = (dict(zip(head, r)) for r in rows[1:])
    assert mesh["kind"] == "mesh" and mesh["inverted_before"] == "1"
    assert mesh["uv_flipped_before"] == "" and mesh["q_min_after"] == "0.700000"
    assert uv["kind"] == "uv" and uv["inverted_before"] == "" and uv["q_avg_before"] == ""
    assert (uv["uv_flipped_before"], uv["uv_flipped_after"]) == ("2", "0")
    assert (uv["uv_inverted_before"], uv["uv_overlapping_after"]) == ("3", "1")
    assert uv["uv_distortion_mean_after"] == "0.750000"
    assert uv["uv_distortion_worst_after"] == "0.500000"
