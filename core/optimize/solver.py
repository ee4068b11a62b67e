"""L-BFGS with a diagonal preconditioner and Armijo backtracking (NumPy), shared by both
energies; `solver_opencl` is its device twin (same arguments, same bits)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from .state import ARMIJO, CURVATURE, LBFGS_MEMORY, TRIALS, State, skipped_trials, stops

if TYPE_CHECKING:
    from .energy import FoldoverEnergy

__all__ = ["lbfgs"]


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
    a dot product dot(a, b) is `np.add.reduce(a * b)`, NumPy's pairwise sum, never BLAS's
    `a @ b`, whose result depends on its thread count (one scratch buffer; the four of a new pair as
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
            al = rho * red(mul(s, q, tmp))  # rho dot(s, q)
            alphas.append(al)
            c0.fill(al)
            q -= mul(yv, c0, tmp)  # q -= al yv
        if mem:
            c0.fill(mem[-1][3] / mem[-1][4])
            q *= mul(dpre, c0, tmp)  # q *= dpre (dot(s, y) / dot(y, dpre y)) of the last pair
            for (s, yv, rho, _, _), al in zip(mem, reversed(alphas), strict=True):
                c0.fill(al - rho * red(mul(yv, q, tmp)))
                q += mul(s, c0, tmp)  # q += (al - rho dot(yv, q)) s
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
                and et <= e + ARMIJO * step * slope
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
        sy, ss, yy, ydy = red(prods, 1).tolist()  # dot(s, y), dot(s, s), ...
        if sy > CURVATURE * math.sqrt(ss * yy):
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
