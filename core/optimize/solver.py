"""L-BFGS with a diagonal preconditioner and Armijo backtracking (NumPy), shared by both
energies; `solver_opencl` is its device twin (same arguments, same bits)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .energy import FoldoverEnergy

__all__ = ["LBFGS_MEMORY", "LIMIT_MARGIN", "TRIALS", "State", "lbfgs", "skipped_trials", "stops"]

LBFGS_MEMORY = 4  # L-BFGS (s, y) pairs kept (8 was 15-20% slower, same iterations: docs)
TICK_EVERY = 20  # progress is reported at most this many L-BFGS iterations apart ...
TICK_CORNERS = 500_000  # ... and every TICK_CORNERS / corners iterations (big meshes: often)


LIMIT_MARGIN = 1e-6  # trial steps within this (relative) of a det root are evaluated
TRIALS = 40  # line-search halvings


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


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """Dot product by NumPy's pairwise sum: unlike `a @ b` (BLAS, whose result depends on its
    thread count), bit-identical on every run and thread setting (`np.add.reduce` is
    `np.sum` without its Python wrapper: half the cost on small meshes)."""
    return float(np.add.reduce(a * b))


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


def lbfgs(
    en: FoldoverEnergy,
    st: State,
    v0: np.ndarray,
    eps: float,
    *,
    max_it: int,
    guard: bool,
    rel_tol: float = 1e-7,
    tick: Callable[[int], bool] | None = None,
) -> tuple[np.ndarray, int]:
    """L-BFGS with a diagonal preconditioner and Armijo backtracking from v0.

    guard: reject trial points with a corner det <= 0 (used once the mesh is valid); without
    it, stop as soon as every corner is positive.
    Stops after max_it iterations, when 5 iterations lower F by less than rel_tol (relative),
    or when tick(iterations so far), called every `en.tick_every` iterations, cancels.
    Returns the last accepted point and the number of iterations done.

    Written for few NumPy calls per iteration, same arithmetic as the plain formulas in the
    comments: the energy sees z = [v, fixed coordinates] (`FoldoverEnergy._packed`), whose first
    2 nf gradient entries are the packed gradient, and only accepted points get a gradient;
    dot products are `_dot`'s pairwise sums (one scratch buffer; the four of a new pair as
    the rows of one reduce, each row summed exactly as alone); a scalar factor is filled into
    an array first (a cheaper NumPy operand than a float or a 0-d array).
    """
    layout, fixed = en._packed(st)
    evaluate, gradient = en._eval, en._grad
    mul, red, amax = np.multiply, np.add.reduce, np.maximum.reduce
    n2 = st.size
    z = np.concatenate([v0, fixed])  # the energy's input: trial points go into z[:n2]
    zv = z[:n2]
    tmp = np.empty(n2)  # scratch: a product before its sum, a scaled vector
    c0 = np.empty(n2)  # scratch: a scalar factor, filled in (faster operand than a float)
    prods = np.empty((4, n2))  # s y, s s, y y, y (dpre y) of a new pair
    # the step limit (guarded runs; not with sliding nodes, whose positions are not linear
    # in the variables) and the direction in z's layout (fixed part 0)
    limit = getattr(en, "_step_limit", None) if guard else None
    dz = np.zeros(z.size) if limit is not None else None
    sy_, ss_, yy_, ydy_ = prods
    v = v0
    e, _, ok = evaluate(z, layout, eps)
    g = gradient(layout)[:n2] if ok else np.zeros(n2)
    dpre = st.preconditioner(en.precond)
    # memory: (s, y, rho = 1 / s.y, s.y, y.(dpre y)) per pair, oldest first
    mem: list[tuple[np.ndarray, np.ndarray, float, float, float]] = []
    e_hist = [e]
    h0 = 0.1 * en.h_mean  # first step: the fastest node moves a tenth of a typical edge
    it = 0
    rejected = 0  # trial steps the last iteration rejected (or skipped)
    while it < max_it:
        it += 1
        q = -g
        alphas = []
        for s, yv, rho, _, _ in reversed(mem):
            al = rho * red(mul(s, q, tmp))  # rho _dot(s, q)
            alphas.append(al)
            c0.fill(al)
            q -= mul(yv, c0, tmp)  # q -= al yv
        if mem:
            c0.fill(mem[-1][3] / mem[-1][4])
            q *= mul(dpre, c0, tmp)  # q *= dpre (_dot(s, y) / _dot(y, dpre y)) of the last pair
            for (s, yv, rho, _, _), al in zip(mem, reversed(alphas), strict=True):
                c0.fill(al - rho * red(mul(yv, q, tmp)))
                q += mul(s, c0, tmp)  # q += (al - rho _dot(yv, q)) s
            step = 1.0
        else:
            q *= dpre
            qmax = float(amax(np.abs(q, out=tmp)))
            step = h0 / qmax if qmax > 0.0 else 0.0
        slope = float(red(mul(g, q, tmp)))
        if not slope < 0.0:  # not a descent direction: restart from preconditioned descent
            mem = []
            q = -dpre * g
            slope = float(red(mul(g, q, tmp)))
            qmax = float(amax(np.abs(q, out=tmp)))
            step = h0 / qmax if qmax > 0.0 else 0.0
            if not slope < 0.0:
                break
        accepted = False
        skip = 0
        if limit is not None and rejected:  # steps that make a det <= 0 are rejected: skip
            # them (the limit costs about two trials: worth it after an iteration with some)
            zv[:] = v
            dz[:n2] = q
            step, skip = skipped_trials(step, limit(z, dz, layout[0], step))
        rejected = skip
        for _ in range(TRIALS - skip):
            c0.fill(step)
            np.add(v, mul(q, c0, tmp), zv)  # vt = v + step q
            et, dmin_t, ok = evaluate(z, layout, eps)
            if (
                math.isfinite(et)
                and et <= e + 1e-4 * step * slope
                and not (guard and dmin_t <= 0.0)
            ):
                accepted = True
                break
            step *= 0.5
            rejected += 1
        if not accepted:
            if mem:  # drop the memory and retry once from plain descent
                mem = []
                continue
            break
        gt = gradient(layout)[:n2]
        vt = zv.copy()
        s = vt - v
        yv = gt - g
        mul(s, yv, sy_)
        mul(s, s, ss_)
        mul(yv, yv, yy_)
        mul(yv, mul(dpre, yv, tmp), ydy_)
        sy, ss, yy, ydy = red(prods, 1).tolist()  # _dot(s, y), _dot(s, s), ...
        if sy > 1e-12 * math.sqrt(ss * yy):
            mem.append((s, yv, 1.0 / sy, sy, ydy))
            if len(mem) > LBFGS_MEMORY:
                del mem[0]
        v, e, g = vt, et, gt
        if not guard and dmin_t > 0.0:  # just became valid: hand over to the guarded polish
            break
        e_hist.append(e)
        if len(e_hist) > 5 and e_hist[-6] - e <= rel_tol * abs(e_hist[-6]):
            break
        if tick is not None and it % en.tick_every == 0 and stops(tick(it)):
            break
    return v, it
