"""Algorithm 1's EEGT loops, shared by the whole run (`pipeline`) and live frames (`live`):
untangle while a face that a move can change is inverted, then smooth until the quality
stops improving, optionally stopping early at a deadline.

The callers keep the best iterate and report progress in the ``step`` they pass (one EEGT
iteration of a phase, returning the new iterate's stats); the loops decide only when to
stop.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from ..metrics.face_quality import Stats
from ..params import EEGTParams

__all__ = ["Deadline", "smooth_loop", "smoothing_done", "untangle_loop"]

Step = Callable[[], Stats]
Stop = Callable[[Stats], bool]


def _never(_s: Stats) -> bool:
    return False


class Deadline:
    """A time limit for the loops: ``late`` once the next iteration, taking as long as the
    last one timed (``timed``), would end after ``at`` (a ``time.perf_counter`` value;
    None: never late)."""

    def __init__(self, at: float | None = None):
        self.at = at
        self.step = 0.0  # seconds of the last timed iteration

    def timed(self, step: Callable[[str], Stats]) -> Callable[[str], Stats]:
        """``step`` measuring its own duration (the next ``late`` reads it)."""
        def run(phase: str) -> Stats:
            t = time.perf_counter()
            s = step(phase)
            self.step = time.perf_counter() - t
            return s
        return run

    def late(self, _s: Stats | None = None) -> bool:
        """Whether one more iteration would pass the deadline."""
        return self.at is not None and time.perf_counter() + self.step > self.at


def untangle_loop(step: Step, tangled: Callable[[Stats], bool], iterations: int,
                  stop: Stop = _never) -> tuple[Stats | None, int]:
    """At most ``iterations`` untangling steps, ending after the first whose iterate is not
    ``tangled`` or where ``stop(iterate)`` says so (a deadline, a stall). Returns (the last
    iterate's stats, None if no step ran; the steps run)."""
    current, n = None, 0
    for _ in range(iterations):
        current = step()
        n += 1
        if not tangled(current) or stop(current):
            break
    return current, n


def smoothing_done(previous: Stats, current: Stats, params: EEGTParams) -> bool:
    """The smoothing stop rule: go on while the mean quality improves by ``tol``, or holds
    while the worst face improves by ``tol_min`` (when ``tol_min`` > 0)."""
    d_avg, d_min = current.q_avg - previous.q_avg, current.q_min - previous.q_min
    worst = params.tol_min > 0.0 and d_avg >= 0.0 and d_min >= params.tol_min
    return d_avg < params.tol and not worst


def smooth_loop(step: Step, current: Stats, params: EEGTParams,
                stop: Stop = _never) -> tuple[Stats, int]:
    """At most ``params.max_smooth_iterations`` smoothing steps from the iterate ``current``,
    ending when ``smoothing_done`` or ``stop(iterate)`` says so. Returns (the last iterate's
    stats, the steps run)."""
    n = 0
    for _ in range(params.max_smooth_iterations):
        previous = current
        current = step()
        n += 1
        if smoothing_done(previous, current, params) or stop(current):
            break
    return current, n
