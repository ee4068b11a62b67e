# SPDX-License-Identifier: GPL-3.0-or-later
"""Progress callbacks of a run: the signature the core calls back, and the background
printer of the operator and the command."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from ...fileio.run_stats import MESH
from .report_lines import stat_values

Progress = Callable[[int, str, Any], bool]

PRINT_EVERY = 1.0  # seconds: the longest a background run stays silent between progress lines


def printer(name: str, clock: Callable[[], float] = time.monotonic) -> Progress:
    """Background progress: one line when a phase starts, every 100 iterations and at least
    every PRINT_EVERY seconds (the core calls back every few tenths of a second of work)."""
    state: dict[str, Any] = {"phase": None, "at": clock()}

    def progress(iteration: int, phase: str, stats: Any) -> bool:
        now = clock()
        if phase != state["phase"] or iteration % 100 == 0 or now - state["at"] >= PRINT_EVERY:
            state["phase"], state["at"] = phase, now
            print(f"EEGT {name}: {phase} iteration {iteration}: {stat_values(MESH, stats)}",
                  flush=True)
        return True

    return progress
