# SPDX-License-Identifier: GPL-3.0-or-later
"""N worker processes on this machine: each file its own ``blender -b``, at most N at once.

One loop in the calling (main) thread starts, polls and kills the processes, so that a
signal handler that asks to stop is seen within a tenth of a second and no thread is left
behind. Largest files start first (the last ones to finish are then short).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

from .worker import Run, find_blender, precheck

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


def run_local(tasks: Sequence[dict[str, Any]], jobs: int, blender: str,
              on_result: Callable[[Result], None], stop: Callable[[], bool],
              tick: Callable[[], None] | None = None) -> bool:
    """Run every task in at most `jobs` processes; `on_result` gets each result as it
    comes. When `stop()` turns true, running processes are killed (their temporary files
    removed) and the rest are reported cancelled. Returns whether it was stopped."""
    pending = deque(by_size(tasks))
    running: list[Run] = []
    workdir = tempfile.mkdtemp(prefix="eegt-batch-")
    interrupted = False
    try:
        while pending or running:
            if stop():
                interrupted = True
                for run in running:
                    on_result(run.kill("cancelled", "interrupted while running (killed)"))
                running = []
                for task in pending:
                    on_result(cancelled(task, "interrupted before it started"))
                pending.clear()
                break
            while pending and len(running) < jobs:
                task = pending.popleft()
                problem = precheck(task)
                if problem:
                    on_result(_error(task, problem))
                    continue
                running.append(Run(task, blender, workdir))
            still = []
            for run in running:
                res = run.poll()
                if res is None:
                    still.append(run)
                else:
                    on_result(res)
            running = still
            if tick is not None:
                tick()
            if running:
                time.sleep(POLL)
    finally:
        for run in running:  # an exception above: leave no process behind
            run.kill("cancelled", "batch ended early")
        shutil.rmtree(workdir, ignore_errors=True)
    return interrupted


def _error(task: dict[str, Any], message: str) -> Result:
    res = cancelled(task, message)
    res.update(status="error", exit_code=2)
    return res


def local_blender(binary_path: str | None) -> tuple[str | None, str]:
    """The Blender binary for local workers: this Blender's own, else $EEGT_BLENDER or
    ``blender`` on PATH (the bpy module has no binary)."""
    return find_blender(binary_path or None)
