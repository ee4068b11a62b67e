# SPDX-License-Identifier: GPL-3.0-or-later
"""A batch's account: per-file entries, the exit code, the console progress line, and the
JSON report with a CSV beside it.

Exit code of a batch: the worst of its files', worst first 1 (internal error, a timeout or
a crash: the file's run did not finish), 2 (bad or unreadable input, output not saved),
3 (a mesh could not be untangled; its best result was written), 0; an interrupted batch
exits 130.
"""

from __future__ import annotations

import csv
import io
import json
import os
import time
from collections.abc import Iterable
from typing import Any

from ..fileio.run_stats import KINDS, MESH, kind_of_objects

EXIT_INTERRUPTED = 130
# Worst first: an unfinished run, then nothing written, then a mesh left tangled.
_SEVERITY = {1: 3, 2: 2, 3: 1, 0: 0}
STATUSES = ("ok", "failed", "error", "timeout", "crashed", "skipped", "cancelled")
# Each kind's stats columns (fileio/run_stats.py), the mesh ones first as they always were,
# then the kind of the file's run; a file fills the columns of its kind only.
CSV_COLUMNS = ("input", "output", "status", "exit_code", "seconds", "objects",
               *(c for k in KINDS.values() for c in k.columns()), "kind",
               "backend", "host", "message")


def file_code(status: str, exit_code: int | None) -> int:
    """The exit code a file contributes to the batch's: its own run's, with a timeout or a
    crash counting as 1 and a skipped file as 0."""
    if status in ("timeout", "crashed"):
        return 1
    if status in ("skipped", "cancelled"):
        return 0
    return exit_code if exit_code in _SEVERITY else 1


def worst_exit(codes: Iterable[int]) -> int:
    """The worst of per-file exit codes (1 > 2 > 3 > 0; an unknown code counts as 1)."""
    worst = 0
    for c in codes:
        c = c if c in _SEVERITY else 1
        if _SEVERITY[c] > _SEVERITY[worst]:
            worst = c
    return worst


def combine(stats: list[dict[str, Any] | None], faces: list[int],
            kind: str = "mesh") -> dict[str, Any] | None:
    """One file's stats from its objects' stats blocks of a ``kind`` of run (see
    ``run_stats``: mesh: inverted faces added up, the lowest q_min, q_avg weighted by face
    count; uv: flipped / inverted / overlapping faces added up, distortion mean weighted by
    face count, the worst distortion kept)."""
    return KINDS[kind].combine(stats, faces)


def file_entry(result: dict[str, Any]) -> dict[str, Any]:
    """The report entry of one file from its worker result (see batch.worker)."""
    rep = result.get("report") or {}
    objects = rep.get("objects") or []
    faces = [int(o.get("n_faces") or 0) for o in objects]
    backends = sorted({o.get("backend") for o in objects if o.get("backend")})
    status = result["status"]
    kind = kind_of_objects(objects)
    stats = kind in KINDS
    return {
        "input": result["input"], "output": result.get("output"), "status": status,
        "exit_code": result.get("exit_code"),
        "written": bool(rep.get("written")) if rep else False,
        "started": result.get("started"), "seconds": result.get("seconds", 0.0),
        "kind": kind,  # of the run: the keys of before / after (run_stats.KINDS)
        "before": combine([o.get("before") for o in objects], faces, kind) if stats else None,
        "after": combine([o.get("after") for o in objects], faces, kind) if stats else None,
        "backend": ",".join(backends), "host": result.get("host", ""),
        "pid": result.get("pid"),
        "message": result.get("message", ""), "objects": objects,
        "skipped_objects": rep.get("skipped", []), "log": result.get("log", ""),
    }


def counts(entries: Iterable[dict[str, Any]]) -> dict[str, int]:
    """How many files ended in each status."""
    c = dict.fromkeys(STATUSES, 0)
    for e in entries:
        c[e["status"]] = c.get(e["status"], 0) + 1
    return c


def kinds(entries: Iterable[dict[str, Any]]) -> dict[str, int]:
    """How many files ran each kind of run ("mesh", "uv": which stats their totals hold;
    files with no object result are left out)."""
    c: dict[str, int] = {}
    for e in entries:
        if e.get("kind"):
            c[e["kind"]] = c.get(e["kind"], 0) + 1
    return c


def batch_exit(entries: Iterable[dict[str, Any]], interrupted: bool) -> int:
    """The batch's exit code (130 when interrupted)."""
    if interrupted:
        return EXIT_INTERRUPTED
    return worst_exit(file_code(e["status"], e.get("exit_code")) for e in entries)


def duration(seconds: float) -> str:
    """``42s``, ``3m07s``, ``2h05m``."""
    s = max(0, round(seconds))
    if s < 60:
        return f"{s}s"
    if s < 3600:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s // 3600}h{s % 3600 // 60:02d}m"


class Progress:
    """Files done / failed / left, rate and ETA, as one console line."""

    def __init__(self, total: int, width: int = 24) -> None:
        self.total, self.width = total, width
        self.done = self.bad = 0
        self.started = time.monotonic()

    def add(self, entry: dict[str, Any]) -> None:
        """Count one finished (or skipped) file."""
        self.done += 1
        self.bad += entry["status"] not in ("ok", "skipped")

    def line(self, now: float | None = None) -> str:
        """``[#####-----] 12/40 done, 1 failed, 28 left, 0.8 files/s, ETA 35s``."""
        elapsed = (time.monotonic() if now is None else now) - self.started
        filled = self.width * self.done // self.total if self.total else self.width
        bar = "#" * filled + "-" * (self.width - filled)
        left = self.total - self.done
        text = (f"[{bar}] {self.done}/{self.total} done, {self.bad} failed, {left} left, "
                f"{duration(elapsed)}")
        if self.done and elapsed > 0:
            rate = self.done / elapsed
            text += f", {rate:.2f} files/s"
            if left:
                text += f", ETA {duration(left / rate)}"
        return text


def csv_rows(entries: Iterable[dict[str, Any]]) -> list[list[Any]]:
    """One CSV row per file (CSV_COLUMNS): the stats columns of the file's kind filled."""
    rows = []
    for e in entries:
        kind = e.get("kind", MESH.name if e.get("before") or e.get("after") else None)
        b, a = e.get("before") or {}, e.get("after") or {}
        cells: list[Any] = []
        for k in KINDS.values():
            for s in k.stats:
                for block in (b, a):
                    cells.append(_cell(block.get(s.key), s.integer) if k.name == kind else "")
        rows.append([e["input"], e.get("output") or "", e["status"],
                     "" if e.get("exit_code") is None else e["exit_code"],
                     f"{e.get('seconds', 0.0):.3f}", len(e.get("objects") or []),
                     *cells, kind or "", e.get("backend", ""), e.get("host", ""),
                     " ".join(str(e.get("message") or "").split())])
    return rows


def _cell(x: Any, integer: bool) -> Any:
    if x is None:
        return ""
    return int(x) if integer else f"{float(x):.6f}"


def csv_path_for(json_path: str) -> str:
    """The CSV beside a JSON report: same name, .csv."""
    stem, ext = os.path.splitext(json_path)
    return (stem if ext.lower() == ".json" else json_path) + ".csv"


def write_reports(json_path: str, data: dict[str, Any]) -> str:
    """Write the JSON report and the CSV beside it, each to a temporary name first and then
    renamed (a reader never sees half a report); the CSV's path."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    w.writerows(csv_rows(data["files"]))
    csv_path = csv_path_for(json_path)
    _atomic_write(json_path, json.dumps(data, indent=2) + "\n")
    _atomic_write(csv_path, buf.getvalue())
    return csv_path


def _atomic_write(path: str, text: str) -> None:
    real = os.path.realpath(path)
    tmp = os.path.join(os.path.dirname(real), f".{os.path.basename(real)}.eegt-tmp-"
                                              f"{os.getpid()}{os.path.splitext(real)[1]}")
    try:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
        os.replace(tmp, real)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
