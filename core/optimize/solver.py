"""L-BFGS with a diagonal preconditioner and Armijo backtracking (NumPy), shared by both
energies; `solver_opencl` is its device twin (same arguments, same bits)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..fpmath import add_reduce_rows, add_reducer
from .state import (
    ARMIJO,
    CURVATURE,
    LBFGS_MEMORY,
    REL_TOL,
    TRIALS,
    State,
    Tick,
    folded_trial,
    skipped_trials,
    stops,
)

if TYPE_CHECKING:
    from .energy import FoldoverEnergy

__all__ = ["ResumableLBFGS", "lbfgs"]


def lbfgs(
    en: FoldoverEnergy,
    st: State,
    v0: np.ndarray,
    eps: float,
    *,
    max_it: int,
    guard: bool,
    rel_tol: float = REL_TOL,
    tick: Tick | None = None,
) -> tuple[np.ndarray, int]:
    """L-BFGS with a diagonal preconditioner and Armijo backtracking from v0.

    guard: reject trial points with a corner det <= 0 (used once the mesh is valid); without
    it, stop as soon as every corner is positive.
    Stops after max_it iterations, when 5 iterations lower F by less than rel_tol (relative),
    or when tick(iterations so far, point), called every `en.tick_every` iterations,
    cancels (`state.Tick`).
    Returns the last accepted point and the number of iterations done.

    Written for few NumPy calls per iteration, same arithmetic as the plain formulas in the
    comments: the energy sees z = [v, fixed coordinates] (`FoldoverEnergy.packed`), whose first
    2 nf gradient entries are the packed gradient, and only accepted points get a gradient;
    a dot product dot(a, b) is `fpmath.add_reduce(a * b)` (through `fpmath.add_reducer`),
    NumPy's pairwise sum in one order under every NumPy, never BLAS's `a @ b`, whose result
    depends on its thread count (one scratch buffer; the four of a new pair as the rows of
    one array, each row summed exactly as alone); a scalar factor is filled into an array
    first (a cheaper NumPy operand than a float or a 0-d array).
    """
    run = _Run(en, st, v0, eps, guard)
    it, _ = _iterate(run, max_it, guard, rel_tol, tick, en.tick_every)
    return run.v, it


def _iterate(run: _Run, max_it: int, guard: bool, rel_tol: float, tick: Tick | None,
             tick_every: int) -> tuple[int, bool]:
    """At most max_it iterations of `run` (lbfgs's loop); (iterations, whether a stop rule
    ended them before max_it)."""
    it = 0
    while it < max_it:
        it += 1
        found = run.direction()
        if found is None:  # no descent direction, not even the preconditioned gradient
            return it, True
        if not run.line_search(*found):
            if run.mem:  # drop the memory and retry once from plain descent
                run.mem = []
                continue
            return it, True
        valid = run.accept()
        if not guard and valid:  # just became valid: hand over to the guarded polish
            return it, True
        if run.stalled(rel_tol):
            return it, True
        if tick is not None and it % tick_every == 0 and stops(tick(it, run.v.copy)):
            return it, True
    return it, False


class ResumableLBFGS:
    """`lbfgs` (guarded) split across calls: the point and the memory of pairs carry from
    one `run` to the next, as in one long solve (Live Untangle's rest pull runs a frame's
    share at a time). `energy_changed` measures the point again after the energy's own
    parameters changed (the pull's weight); the memory stays."""

    def __init__(self, en: FoldoverEnergy, st: State, v0: np.ndarray, eps: float):
        self._run = _Run(en, st, v0, eps, True)

    @property
    def v(self) -> np.ndarray:
        """The last accepted point."""
        return self._run.v

    def run(self, max_it: int, rel_tol: float = REL_TOL) -> tuple[int, bool]:
        """At most max_it more iterations; (iterations, whether a stop rule ended them)."""
        return _iterate(self._run, max_it, True, rel_tol, None, 1)

    def energy_changed(self) -> None:
        """The energy at the point and its gradient again (the stall rule starts afresh)."""
        r = self._run
        r.zv[:] = r.v
        r.e, _, ok = r.evaluate(r.z, r.layout, r.eps)
        r.g = r.gradient(r.layout)[: r.n2] if ok else np.zeros(r.n2)
        r.at_v = True
        r.e_hist = [r.e]


class _Run:
    """One L-BFGS solve's state: the point v (energy e, gradient g), the memory of pairs and
    the scratch buffers; `lbfgs` drives it step by step."""

    def __init__(self, en: FoldoverEnergy, st: State, v0: np.ndarray, eps: float, guard: bool):
        layout, fixed = en.packed(st)
        self.layout, self.eps, self.guard = layout, eps, guard
        self.evaluate, self.gradient = en.evaluate, en.gradient
        self.n2 = n2 = st.size
        self.z = np.concatenate([v0, fixed])  # the energy's input: trial points go in z[:n2]
        self.zv = self.z[:n2]
        self.tmp = np.empty(n2)  # scratch: a product before its sum, a scaled vector
        self.sum = add_reducer(n2)
        self.c0 = np.empty(n2)  # scratch: a scalar factor, filled in (faster than a float)
        self.prods = np.empty((4, n2))  # s y, s s, y y, y (dpre y) of a new pair
        # the step limit (guarded runs; not with sliding nodes, whose positions are not
        # linear in the variables) and the direction in z's layout (fixed part 0)
        self.limit = getattr(en, "step_limit", None) if guard else None
        self.dz = np.zeros(self.z.size) if self.limit is not None else None
        self.v = v0
        self.e, _, ok = self.evaluate(self.z, layout, eps)
        self.g = self.gradient(layout)[:n2] if ok else np.zeros(n2)
        self.at_v = True  # the energy's last evaluation was at v (its J is v's)
        self.dpre = st.preconditioner(en.precond)
        # memory: (s, y, rho = 1 / s.y, s.y, y.(dpre y)) per pair, oldest first
        self.mem: list[tuple[np.ndarray, np.ndarray, float, float, float]] = []
        self.e_hist = [self.e]
        self.h0 = 0.1 * en.h_mean  # first step: the fastest node moves a tenth of an edge
        self.folded = 0  # trial steps the last iteration rejected for a det <= 0 (or skipped)
        self.et = self.dmin_t = 0.0  # the accepted trial's energy and smallest det

    def _dot(self, a: np.ndarray, b: np.ndarray) -> float:
        """dot(a, b) as fpmath.add_reduce's pairwise sum (never BLAS)."""
        return self.sum(np.multiply(a, b, self.tmp))

    def _two_loop(self) -> tuple[np.ndarray, float]:
        """-H g by the two-loop recursion (H: the memory's inverse Hessian, dpre scaled by
        the last pair), and the first trial step (1, or h0 / max |q| without memory)."""
        mul, tmp, c0 = np.multiply, self.tmp, self.c0
        q = -self.g
        alphas = []
        for s, yv, rho, _, _ in reversed(self.mem):
            al = rho * self._dot(s, q)  # rho dot(s, q)
            alphas.append(al)
            c0.fill(al)
            q -= mul(yv, c0, tmp)  # q -= al yv
        if not self.mem:
            q *= self.dpre
            return q, self._first_step(q)
        c0.fill(self.mem[-1][3] / self.mem[-1][4])
        q *= mul(self.dpre, c0, tmp)  # q *= dpre (dot(s, y) / dot(y, dpre y)) of the last pair
        for (s, yv, rho, _, _), al in zip(self.mem, reversed(alphas), strict=True):
            c0.fill(al - rho * self._dot(yv, q))
            q += mul(s, c0, tmp)  # q += (al - rho dot(yv, q)) s
        return q, 1.0

    def _first_step(self, q: np.ndarray) -> float:
        """h0 / max |q|: the fastest node moves h0 (0 for q = 0)."""
        qmax = float(np.maximum.reduce(np.abs(q, out=self.tmp)))
        return self.h0 / qmax if qmax > 0.0 else 0.0

    def direction(self) -> tuple[np.ndarray, float, float] | None:
        """(q, first step, slope g.q) of a descent direction; when the memory's is none,
        the memory goes and the preconditioned gradient is tried; None: neither descends."""
        q, step = self._two_loop()
        slope = float(self._dot(self.g, q))
        if not slope < 0.0:  # not a descent direction: restart from preconditioned descent
            self.mem = []
            q = -self.dpre * self.g
            slope = float(self._dot(self.g, q))
            step = self._first_step(q)
            if not slope < 0.0:
                return None
        return q, step, slope

    def line_search(self, q: np.ndarray, step: float, slope: float) -> bool:
        """Armijo backtracking from `step` along q (trial points rejected when an energy is
        not finite or, guarded, when a det is <= 0; the step limit skips trials it knows
        to fail); the accepted trial stays in z[:n2]."""
        skip = 0
        zv, tmp, c0 = self.zv, self.tmp, self.c0
        if self.limit is not None and self.folded:  # steps that make a det <= 0 are
            # rejected: skip them (the limit costs about two trials: worth it after an
            # iteration that had such trials, not after one whose trials only missed
            # sufficient decrease: in a repair's lift 487 such limits skipped 37 trials)
            zv[:] = self.v
            self.dz[: self.n2] = q
            step, skip = skipped_trials(step, self.limit(self.z, self.dz, self.layout[0], step,
                                                         self.at_v))
        self.folded = skip
        for _ in range(TRIALS - skip):
            c0.fill(step)
            np.add(self.v, np.multiply(q, c0, tmp), zv)  # vt = v + step q
            et, dmin_t, _ = self.evaluate(self.z, self.layout, self.eps)
            if (
                math.isfinite(et)
                and et <= self.e + ARMIJO * step * slope
                and not (self.guard and dmin_t <= 0.0)
            ):
                self.et, self.dmin_t = et, dmin_t
                return True
            step *= 0.5
            self.folded += folded_trial(et, dmin_t, self.guard)
        self.at_v = False  # the last evaluation was a rejected trial
        return False

    def accept(self) -> bool:
        """Move to the accepted trial: its gradient, the new pair (kept when its curvature
        s.y is positive enough), the memory; whether every det is now positive."""
        mul = np.multiply
        gt = self.gradient(self.layout)[: self.n2]
        vt = self.zv.copy()
        s = vt - self.v
        yv = gt - self.g
        sy_, ss_, yy_, ydy_ = self.prods
        mul(s, yv, sy_)
        mul(s, s, ss_)
        mul(yv, yv, yy_)
        mul(yv, mul(self.dpre, yv, self.tmp), ydy_)
        sy, ss, yy, ydy = add_reduce_rows(self.prods)  # dot(s, y), dot(s, s), ...
        if sy > CURVATURE * math.sqrt(ss * yy):
            self.mem.append((s, yv, 1.0 / sy, sy, ydy))
            if len(self.mem) > LBFGS_MEMORY:
                del self.mem[0]
        self.v, self.e, self.g = vt, self.et, gt
        self.at_v = True
        return self.dmin_t > 0.0

    def stalled(self, rel_tol: float) -> bool:
        """Whether the last 5 iterations lowered the energy by less than rel_tol (relative)."""
        e, hist = self.e, self.e_hist
        hist.append(e)
        return len(hist) > 5 and hist[-6] - e <= rel_tol * abs(hist[-6])
