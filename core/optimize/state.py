"""What every L-BFGS path shares: the packed free coordinates (`State`), the line search's
constants and its step-limit skip, and how a progress answer cancels. The NumPy solver
(`solver`), its device twins (`solver_opencl`, `solver_parallel`) and the energies use these,
so none of them imports another for them."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = [
    "ARMIJO",
    "CURVATURE",
    "LBFGS_MEMORY",
    "LIMIT_MARGIN",
    "TICK_CORNERS",
    "TICK_EVERY",
    "TRIALS",
    "State",
    "Tick",
    "folded_trial",
    "line_search_defines",
    "skipped_trials",
    "stops",
]

LBFGS_MEMORY = 4  # L-BFGS (s, y) pairs kept (8 was 15-20% slower, same iterations: docs)
TICK_EVERY = 20  # progress is reported at most this many L-BFGS iterations apart ...
TICK_CORNERS = 500_000  # ... and every TICK_CORNERS / corners iterations (big meshes: often)
# A solver's progress tick: tick(iterations so far, point) with point() the current iterate
# (packed, a fresh array; a device solver reads it back only when called). False cancels.
Tick = Callable[[int, Callable[[], np.ndarray]], bool]


LIMIT_MARGIN = 1e-6  # trial steps within this (relative) of a det root are evaluated
TRIALS = 40  # line-search halvings
REL_TOL = 1e-7  # a solve's default stop: 5 iterations lower F by less than this (relative)
ARMIJO = 1e-4  # sufficient decrease: accept a trial step when e_t <= e + ARMIJO step slope
CURVATURE = 1e-12  # keep a pair (s, y) only when s.y > CURVATURE |s| |y|


def line_search_defines() -> dict[str, float]:
    """The line search's and the memory update's constants under their kernel names (build
    defines of both device solvers)."""
    return {"TRIALS": TRIALS, "ARMIJO": ARMIJO, "CURVATURE": CURVATURE}


def folded_trial(et: float, dmin: float, guard: bool) -> bool:
    """Whether a rejected trial step failed on what the step limit foresees (an energy that
    is not finite, or, guarded, a det <= 0) rather than on sufficient decrease: the solvers
    compute the limit after an iteration with such a trial."""
    return not math.isfinite(et) or (guard and dmin <= 0.0)


def skipped_trials(step: float, limit: float) -> tuple[float, int]:
    """(first step worth evaluating, halvings skipped): a trial step above the step limit
    (with a margin for round-off) makes some corner det <= 0, which the guarded line search
    rejects, so the search goes on from the first step below it with the same iterate."""
    bound = limit * (1.0 + LIMIT_MARGIN)
    k = 0
    while k < TRIALS and step > bound:
        step *= 0.5
        k += 1
    return step, k


def stops(answer: Any) -> bool:
    """A progress callback's answer cancels when it is falsy but not None (False, np.False_,
    0); None (a callback that returns nothing) and truthy values continue."""
    return answer is not None and not answer


class State:
    """Free coordinates packed as v = [x_free, y_free]; fixed nodes never written."""

    def __init__(self, points: np.ndarray, free: np.ndarray):
        self.x = np.ascontiguousarray(points[:, 0])
        self.y = np.ascontiguousarray(points[:, 1])
        self.fidx = np.flatnonzero(free)
        self.nf = self.fidx.size

    def unpack(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = self.x.copy()
        y = self.y.copy()
        x[self.fidx] = v[: self.nf]
        y[self.fidx] = v[self.nf :]
        return x, y

    def pack(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.concatenate([x[self.fidx], y[self.fidx]])

    @property
    def size(self) -> int:
        """Length of v."""
        return 2 * self.nf

    @property
    def written(self) -> np.ndarray:
        """The nodes v moves (`unpack` gives the others as they were)."""
        return self.fidx

    def preconditioner(self, precond: np.ndarray) -> np.ndarray:
        """The diagonal preconditioner of v from the energy's per-node one."""
        return np.tile(precond[self.fidx], 2)

    def view(self, en):
        """The energy as `lbfgs` sees it for this state (here: itself; core.optimize.slide
        puts the sliding nodes' parameters in between)."""
        return en
