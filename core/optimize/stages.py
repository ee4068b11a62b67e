"""The global stage's two entry points: `untangle_global` (foldover-free energy with the eps
continuation, then a guarded polish) and `lift_min_quality` (raise the worst element quality
without lowering the mean). Details and measurements: docs/global_untangle.md."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from ..boundary import SlideView
from .dispatch import Solver
from .energy import FoldoverEnergy, LiftEnergy, chi_scalar
from .mesh_tables import Factors
from .options import GlobalOptions
from .slide import make_state
from .state import State, stops
from .submesh import Neighbourhood

__all__ = ["lift_min_quality", "untangle_global"]

INNER_ITER = 1000  # L-BFGS iterations between two eps updates (60 stalled on spun holes: docs)
EPS_MIN = 1e-9  # floor of eps (J is dimensionless: dets are ~1 at the reference size)
SIGMA_MIN = 0.1  # the paper's lower bound on sigma
STOP_REL_DECREASE = 1e-3  # stop polishing when one round lowers F by less than this (relative)
# lift_min_quality (max mean quality subject to a rising quality floor; see the docs)
LIFT_ITER = 200  # L-BFGS iterations per later round (100 stopped short on naca_deform: docs)
LIFT_GROW = 1.15  # floor of the next round: min(q_min * GROW, q_min + GAP * (q_avg - q_min))
LIFT_GAP = 0.15
LIFT_RATE = 3.0  # a round that lowers q_avg must raise q_min by at least RATE times as much
LIFT_RINGS = 6  # rounds after the first move only the nodes within this many rings of ...
LIFT_ACTIVE = 1.0  # ... the elements with q < LIFT_ACTIVE * floor (a small local problem)
LIFT_POOR = 0.5  # while q_min < this x q_avg, q_avg may fall below the input's (still capped)
LIFT_AVG_DROP = 0.03  # q_avg may not fall below (1 - this) x the best q_avg of the lift


def _checked_input(points, free) -> tuple[np.ndarray, np.ndarray]:
    """A float64 copy of the (N, 2) points and the (N,) bool free mask; ValueError else."""
    P = np.array(points, dtype=np.float64, copy=True)
    free = np.asarray(free, dtype=bool).reshape(-1)
    if P.ndim != 2 or P.shape[1] != 2 or free.shape[0] != P.shape[0]:
        raise ValueError("points must be (N, 2) and free (N,)")
    return P, free


def _untangle_state(
    P: np.ndarray, free: np.ndarray, slide: SlideView | None, en: FoldoverEnergy
) -> tuple[State, bool]:
    """The state `untangle_global` starts with, and whether the sliding nodes join later.
    While some corner is inverted the sliding nodes stay (the foldover energy would pull
    them to their neighbours: every trial step past one is refused, and the line search
    stalls); they slide once the mesh is valid, or from the start when nothing else moves.
    The sliding nodes of a corner that the others cannot change (`_held_stuck`) slide from
    the start: without them the mesh can never become valid."""
    if slide is None or en.i0.size == 0:
        return make_state(P, free, slide), False
    if float(np.min(en.dets(P[:, 0], P[:, 1]))) > 0.0:
        return make_state(P, free, slide), False
    _, local = slide.here(P.shape[0])
    rest = free.copy()
    rest[local] = False
    if not rest.any():
        return make_state(P, free, slide), False
    need = _held_stuck(P, free, rest, en)
    if need.any():
        return make_state(P, rest | need, slide), True
    return State(P, rest), True


def _held_stuck(P: np.ndarray, free: np.ndarray, rest: np.ndarray, en: FoldoverEnergy
                ) -> np.ndarray:
    """(N,) bool: the sliding nodes (free, not in `rest`) of validity corners that no node of
    `rest` can make positive: two of the corner's nodes outside `rest` at one point (its det
    is 0 wherever the third goes), or all three outside `rest` and a det <= 0. A node dragged
    onto its neighbour on the boundary makes such a corner."""
    out = np.zeros(P.shape[0], dtype=bool)
    v0, v1, v2 = en.v0, en.v1, en.v2
    held = ~rest
    h0, h1, h2 = held[v0], held[v1], held[v2]
    maybe = (h0 & (h1 | h2)) | (h1 & h2)
    if not maybe.any():
        return out
    v0, v1, v2 = v0[maybe], v1[maybe], v2[maybe]
    h0, h1, h2 = h0[maybe], h1[maybe], h2[maybe]
    x, y = P[:, 0], P[:, 1]
    same01 = (x[v0] == x[v1]) & (y[v0] == y[v1])
    same02 = (x[v0] == x[v2]) & (y[v0] == y[v2])
    same12 = (x[v1] == x[v2]) & (y[v1] == y[v2])
    det = (x[v1] - x[v0]) * (y[v2] - y[v0]) - (y[v1] - y[v0]) * (x[v2] - x[v0])
    stuck = (h0 & h1 & same01) | (h0 & h2 & same02) | (h1 & h2 & same12) | \
        (h0 & h1 & h2 & (det <= 0.0))
    if not stuck.any():
        return out
    for v in (v0, v1, v2):
        out[v[stuck]] = True
    return out & free & ~rest


def untangle_global(
    points: np.ndarray,
    groups: Mapping[int, np.ndarray],
    free: np.ndarray,
    options: GlobalOptions | None = None,
    progress: Callable[[int, int, int], Any] | None = None,
    factors: Factors | None = None,
    slide: SlideView | None = None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Untangle a planar polygon mesh by minimising the foldover-free energy (eps continuation).

    points: (N, 2) float64; groups: arity -> (F_n, n) int node arrays, counterclockwise = valid;
    free: (N,) bool mask of the nodes that may move; options: budgets (max_iter, polish_iter,
    polish_power, time_limit) and the solver (`GlobalOptions`; None: the defaults); factors:
    per-face target shapes (`reference.Factors`, aligned with groups; None: regular polygons);
    slide: the free nodes that slide along their boundary curves (core.optimize.slide; the
    host solver then runs). progress(iterations, max_iter, n_inverted) is called after each
    round and every `tick_every` L-BFGS iterations inside it (a few tenths of a second of
    work on any mesh size); a falsy answer other than None cancels (`stops`).

    Returns (new points, info); non-free rows are bit-identical to the input. Once valid, steps
    that would invert a corner are rejected, so a valid iterate stays valid; when no valid one
    was reached, the iterate with the fewest inverted elements is returned.
    info: iterations, rounds, n_inverted_in, n_inverted_out, min_det (smallest normalised corner
    det), eps_history, seconds, seconds_per_iter, status ("untangled" / "failed" / "cancelled" /
    "nothing to do").
    """
    t_start = time.perf_counter()
    P, free = _checked_input(points, free)
    if not np.all(np.isfinite(P)):
        raise ValueError("points contain NaN or inf")
    opt = options if options is not None else GlobalOptions()
    max_iter, polish_iter = opt.max_iter, opt.polish_iter
    en = FoldoverEnergy(P, groups, free, factors)
    run_lbfgs = opt.run(sliding=slide is not None)
    st, later = _untangle_state(P, free, slide, en)
    n_inv = en.n_inverted(st.x, st.y)
    info: dict[str, Any] = {
        "iterations": 0,
        "rounds": 0,
        "n_inverted_in": n_inv,
        "n_inverted_out": n_inv,
        "min_det": float(np.min(en.dets(st.x, st.y))) if en.i0.size else 0.0,
        "eps_history": [],
        "seconds": 0.0,
        "seconds_per_iter": 0.0,
        "status": "nothing to do",
    }
    if en.i0.size == 0 or st.size == 0:
        info["seconds"] = time.perf_counter() - t_start
        return P, info

    v = st.pack(st.x, st.y)
    dmin = info["min_det"]
    eps = max(0.1 * abs(dmin), 1e-3) if dmin <= 0.0 else EPS_MIN
    best_v, best_inv = v, n_inv
    valid = dmin > 0.0  # every corner that can move is positive (others are constant)
    total = 0
    polish_used = 0
    status = ""
    eps_hist: list[float] = []
    rounds = 0
    cancel = False
    while total < max_iter:
        rounds += 1
        eps_hist.append(eps)
        guard = valid  # valid: polish the quality, never invert a corner again
        en.power = float(opt.polish_power) if guard else 1.0
        e_start = en.value(*st.unpack(v), eps)
        if guard:  # eps is at its floor: one long L-BFGS run, no memory restarts
            cap = min(max_iter - total, polish_iter - polish_used)
            if cap <= 0:
                break
        else:
            cap = min(max_iter - total, INNER_ITER)
        tick = None
        if progress is not None:  # long runs report (and cancel) from inside

            def tick(it: int, done: int = total, n_now: int = best_inv) -> bool:
                nonlocal cancel
                cancel = cancel or stops(progress(done + it, max_iter, n_now))
                return not cancel

        v, its = run_lbfgs(st.view(en), st, v, eps, max_it=cap, guard=guard, tick=tick)
        total += its
        if guard:
            polish_used += its
        x, y = st.unpack(v)
        e_end = en.value(x, y, eps)
        dmin = float(np.min(en.dets(x, y)))
        valid = dmin > 0.0
        n_inv = en.n_inverted(x, y)
        if n_inv <= best_inv:
            best_v, best_inv = v, n_inv
        if later and valid:  # valid now: the sliding nodes join (best_v is this iterate)
            st, later = make_state(np.column_stack([x, y]), free, slide), False
            v = best_v = st.pack(x, y)
        if cancel or (progress is not None and stops(progress(total, max_iter, n_inv))):
            status = "cancelled"
            break
        decrease = (e_start - e_end) / abs(e_start) if e_start != 0.0 else 0.0
        if guard and (decrease < STOP_REL_DECREASE or its == 0):
            break
        if valid and polish_iter <= 0:
            break
        if opt.time_limit is not None and time.perf_counter() - t_start > opt.time_limit:
            break
        sigma = max(decrease, SIGMA_MIN)
        mu = (1.0 - sigma) * chi_scalar(dmin, eps)
        eps = max(2.0 * float(np.sqrt(mu * (mu - dmin))) if dmin < mu else EPS_MIN, EPS_MIN)
        if valid:  # the guard now keeps dets > 0: use the exact barrier (see the docs)
            eps = EPS_MIN

    x, y = st.unpack(best_v)
    out = P.copy()
    out[st.written, 0] = x[st.written]
    out[st.written, 1] = y[st.written]
    n_out = en.n_inverted(x, y)
    if not status:
        status = "untangled" if n_out == 0 else "failed"
    secs = time.perf_counter() - t_start
    info.update(
        iterations=total,
        rounds=rounds,
        n_inverted_out=n_out,
        min_det=float(np.min(en.dets(x, y))),
        eps_history=eps_hist,
        seconds=secs,
        seconds_per_iter=secs / max(total, 1),
        status=status,
    )
    return out, info


def _runs(run_lbfgs: Solver, en: LiftEnergy, st: State, v: np.ndarray, opt: GlobalOptions,
          tick: Callable[[int], bool] | None) -> tuple[np.ndarray, int]:
    """The lift's whole-mesh run: one L-BFGS run, or (opt.lift_chunk > 0) runs of that many
    iterations with fresh memory each, until one lowers the energy by less than
    opt.lift_rel_tol (relative). Fresh memory matters on a large mesh with a few stiff
    corners (a just-untangled spot): the memory's scale then shrinks every step of the whole
    mesh (docs/global_untangle.md, "Restarts")."""
    chunk, max_it, tol = opt.lift_chunk, opt.lift_first_iter, opt.lift_rel_tol
    if chunk <= 0:
        return run_lbfgs(st.view(en), st, v, EPS_MIN, max_it=max_it, guard=True, rel_tol=tol,
                         tick=tick)
    total = 0
    e0 = en.value(*st.unpack(v), EPS_MIN)
    while total < max_it:
        sub = None if tick is None else (lambda it, base=total: tick(base + it))
        v, its = run_lbfgs(
            st.view(en), st, v, EPS_MIN, max_it=min(chunk, max_it - total), guard=True,
            rel_tol=tol,
            tick=sub,
        )
        total += its
        if tick is not None and stops(tick(total)):
            break
        e1 = en.value(*st.unpack(v), EPS_MIN)
        if its < chunk or not e0 - e1 > tol * abs(e0):
            break
        e0 = e1
    return v, total


def lift_min_quality(
    points: np.ndarray,
    groups: Mapping[int, np.ndarray],
    free: np.ndarray,
    options: GlobalOptions | None = None,
    progress: Callable[[int, int, float, float], Any] | None = None,
    factors: Factors | None = None,
    slide: SlideView | None = None,
    neighbourhood: Neighbourhood | None = None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Raise the worst element quality of a valid mesh without lowering its mean quality.

    Maximises the mean quality q_avg subject to a soft floor q_e >= qc on every element
    (`LiftEnergy`, guarded L-BFGS: the mesh stays valid), first with qc = the input's q_min,
    then for up to `options.lift_rounds` rounds with a rising floor, each over only the free
    nodes within LIFT_RINGS rings of the elements under the new floor. A round is kept only
    when q_min rises, q_avg stays within LIFT_AVG_DROP (relative) of the best q_avg seen and,
    once q_min >= LIFT_POOR q_avg, at least the input's, and any q_avg it costs buys at least
    LIFT_RATE times as much q_min.
    Returns (points, info) with the kept iterate: the input itself (bit-identical) when
    nothing qualifies or the input has an inverted element. info: iterations, rounds (kept),
    q_min_in, q_avg_in, q_min_out, q_avg_out, trail ((q_min, q_avg) after each run), seconds,
    status ("lifted", "unchanged", "cancelled").
    progress(iterations, rounds_done, q_min, q_avg) after each run and every few tenths of a
    second inside one, with the kept iterate's qualities; a falsy answer other than None
    cancels (`stops`) and the input is returned. options.solver runs the L-BFGS solves;
    factors: per-face target shapes (the qualities are then against them); slide: the free
    nodes that slide along their boundary curves (the host solver then runs); neighbourhood:
    the `Neighbourhood` of (groups, free, factors) if the caller has one (else built here).
    """
    t_start = time.perf_counter()
    P, free = _checked_input(points, free)
    opt = options if options is not None else GlobalOptions()
    rounds = opt.lift_rounds
    en = LiftEnergy(P, groups, free, factors)
    st = make_state(P, free, slide)
    run_lbfgs = opt.run(sliding=type(st) is not State)
    info: dict[str, Any] = {"iterations": 0, "rounds": 0, "status": "unchanged"}
    q = en.element_quality(st.x, st.y) if en.n_elem else np.zeros(0)
    m0 = float(q.min()) if q.size else 0.0
    a0 = float(q.mean()) if q.size else 0.0
    info.update(q_min_in=m0, q_avg_in=a0, q_min_out=m0, q_avg_out=a0)
    if q.size == 0 or st.size == 0 or not m0 > 0.0 or not np.all(np.isfinite(P)):
        info["seconds"] = time.perf_counter() - t_start
        return P, info

    best_v, best_m, best_a = None, m0, a0
    v = st.pack(st.x, st.y)
    cur_m, cur_a = m0, a0
    peak = a0  # the best q_avg seen: q_avg may fall at most LIFT_AVG_DROP below it
    total = 0
    trail: list[tuple[float, float]] = []  # (q_min, q_avg) after each run, kept or not
    info["trail"] = trail
    cancel = False
    near = neighbourhood  # node -> element incidence, for the rounds (built on first use)
    for r in range(rounds + 1):
        en.qc = m0 if r == 0 else min(cur_m * LIFT_GROW, cur_m + LIFT_GAP * (cur_a - cur_m))
        tick = None
        if progress is not None:

            def tick(
                it: int, done: int = total, r: int = r, m: float = cur_m, a: float = cur_a
            ) -> bool:
                nonlocal cancel
                cancel = cancel or stops(progress(done + it, r, m, a))
                return not cancel

        if r == 0:  # the whole mesh: maximise q_avg at the input's floor
            vt, its = _runs(run_lbfgs, en, st, v, opt, tick)
            xt, yt = st.unpack(vt)
        else:  # only near the elements under the new floor: the rest is at its optimum
            x, y = st.unpack(v)
            if near is None:
                near = Neighbourhood(groups, free, factors)
            (sub, nodes, sfree, sub_f), elems = near.submesh(q < LIFT_ACTIVE * en.qc,
                                                               LIFT_RINGS)
            if not sfree.any():
                break
            sp = np.stack([x[nodes], y[nodes]], axis=1)
            sen = LiftEnergy(sp, sub, sfree, sub_f)
            sen.qc = en.qc
            sst = make_state(sp, sfree, None if slide is None else
                             slide.sub(nodes, np.column_stack([x, y])))
            sv, its = run_lbfgs(
                sst.view(sen), sst, sst.pack(sst.x, sst.y), EPS_MIN, max_it=LIFT_ITER,
                guard=True, rel_tol=opt.lift_rel_tol, tick=tick,
            )
            sx, sy = sst.unpack(sv)
            xt, yt = x.copy(), y.copy()
            xt[nodes], yt[nodes] = sx, sy
            vt = st.pack(xt, yt)
        total += its
        if r == 0:
            qt = en.element_quality(xt, yt)
        else:  # only the sub-mesh's elements changed
            qt = q.copy()
            qt[elems] = en.element_quality_of(elems, xt, yt)
        qm, qa = float(qt.min()), float(qt.mean())
        trail.append((qm, qa))
        if cancel or (progress is not None and stops(progress(total, r, cur_m, cur_a))):
            info.update(iterations=total, status="cancelled", seconds=time.perf_counter() - t_start)
            return P, info
        if r == 0:  # the first run maximises q_avg at the input's floor: the start of the climb
            v, q, cur_m, cur_a = vt, qt, qm, qa
            peak = max(peak, qa)
        else:
            floor = (1.0 - LIFT_AVG_DROP) * peak
            if cur_m >= LIFT_POOR * cur_a:
                floor = max(floor, a0)
            if qa < floor or qm <= cur_m or (qa < cur_a and qm - cur_m < LIFT_RATE * (cur_a - qa)):
                break
            v, q, cur_m, cur_a = vt, qt, qm, qa
            peak = max(peak, qa)
            info["rounds"] = r
        if (cur_a >= a0 or info["rounds"]) and cur_m > best_m:
            best_v, best_m, best_a = v, cur_m, cur_a

    info.update(iterations=total, seconds=time.perf_counter() - t_start)
    if best_v is None:
        return P, info
    x, y = st.unpack(best_v)
    P[st.written, 0] = x[st.written]
    P[st.written, 1] = y[st.written]
    info.update(q_min_out=best_m, q_avg_out=best_a, status="lifted")
    return P, info
