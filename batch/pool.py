# SPDX-License-Identifier: GPL-3.0-or-later
"""N worker processes on this machine: at most N Blenders at once, each running the
single-file command for one file (or, with ``--files-per-worker K``, for up to K files in
turn).

One loop in the calling (main) thread starts, polls and kills the processes, so that a
signal handler that asks to stop is seen within a twentieth of a second and no thread is
left behind. Largest files start first (the last ones to finish are then short).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

from .worker import Run, Served, Server, find_blender, precheck

Result = dict[str, Any]
POLL = 0.05


def default_jobs() -> int:
    """The number of cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def by_size(tasks: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Tasks, largest input first (ties keep their order)."""
    def size(t: dict[str, Any]) -> int:
        try:
            return os.path.getsize(t["input"])
        except OSError:
            return 0
    return sorted(tasks, key=lambda t: -size(t))


def cancelled(task: dict[str, Any], message: str) -> Result:
    """The result of a task that did not run to its end because the batch was stopped."""
    return {"index": task.get("index"), "input": task["input"], "output": task.get("output"),
            "status": "cancelled", "exit_code": None, "seconds": 0.0, "message": message,
            "host": "", "pid": None, "report": None, "log": ""}


class _Slot:
    """One of the N places a file can run: a fresh Blender per file, or a Server kept for
    up to `per_worker` files."""

    def __init__(self, n: int, blender: str, workdir: str, per_worker: int) -> None:
        self.n, self.blender, self.workdir, self.per_worker = n, blender, workdir, per_worker
        self.server: Server | None = None
        self.run: Run | Served | None = None
        self.started = 0

    def start(self, task: dict[str, Any]) -> None:
        if self.per_worker <= 1:
            self.run = Run(task, self.blender, self.workdir)
            return
        if self.server is None or not self.server.usable():
            self.close()
            self.started += 1
            self.server = Server(self.blender, self.workdir, self.per_worker,
                                 f"{self.n}-{self.started}")
        self.run = self.server.submit(task)

    def close(self) -> None:
        if self.server is not None:
            self.server.close()
            self.server = None


def run_local(tasks: Sequence[dict[str, Any]], jobs: int, blender: str,
              on_result: Callable[[Result], None], stop: Callable[[], bool],
              tick: Callable[[], None] | None = None, per_worker: int = 1) -> bool:
    """Run every task in at most `jobs` Blenders; `on_result` gets each result as it comes.
    When `stop()` turns true, running processes are killed (their temporary files removed)
    and the rest are reported cancelled. Returns whether it was stopped."""
    pending = deque(by_size(tasks))
    workdir = tempfile.mkdtemp(prefix="eegt-batch-")
    slots = [_Slot(n, blender, workdir, per_worker) for n in range(jobs)]
    interrupted = False
    try:
        while pending or any(s.run for s in slots):
            if stop():
                interrupted = True
                for s in slots:
                    if s.run is not None:
                        on_result(s.run.kill("cancelled", "interrupted while running (killed)"))
                        s.run = None
                for task in pending:
                    on_result(cancelled(task, "interrupted before it started"))
                pending.clear()
                break
            for s in slots:
                while s.run is None and pending:
                    task = pending.popleft()
                    problem = precheck(task)
                    if problem:
                        on_result(_error(task, problem))
                    else:
                        s.start(task)
                if s.run is not None:
                    res = s.run.poll()
                    if res is not None:
                        s.run = None
                        on_result(res)
            if tick is not None:
                tick()
            if any(s.run for s in slots):
                time.sleep(POLL)
    finally:
        for s in slots:  # an exception above: leave no process behind
            if s.run is not None:
                s.run.kill("cancelled", "batch ended early")
            s.close()
        shutil.rmtree(workdir, ignore_errors=True)
    return interrupted


def _error(task: dict[str, Any], message: str) -> Result:
    res = cancelled(task, message)
    res.update(status="error", exit_code=2)
    return res


def local_blender(binary_path: str | None) -> tuple[str | None, str]:
    """The Blender binary for local workers: $EEGT_BLENDER if set, else this Blender's own,
    else ``blender`` on PATH (the bpy module has no binary)."""
    return find_blender(binary_path or None)
