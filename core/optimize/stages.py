"""The global stage's two entry points: `untangle_global` (foldover-free energy with the eps
continuation, then a guarded polish) and `lift_min_quality` (raise the worst element quality
without lowering the mean). Details and measurements: docs/global_untangle.md."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import numpy as np

from ..eegt.boundary import SlideView
from ..fpmath import add_reduce
from .dispatch import Solver
from .energy import FoldoverEnergy, LiftEnergy, chi_scalar
from .mesh_tables import Factors
from .options import GlobalOptions
from .sampled import Sampled
from .slide import make_state
from .state import State, Tick, stops
from .submesh import Neighbourhood

__all__ = ["BUDGET_NODES", "PLATEAU_EVERY", "PLATEAU_LEFT", "PLATEAU_RISE", "STALL_ROUNDS",
           "Resume", "lift_min_quality", "untangle_budget", "untangle_global"]

INNER_ITER = 1000  # L-BFGS iterations between two eps updates (60 stalled on spun holes: docs)
INNER_PER_SQRT_NODE = 40  # ... at least this x sqrt(free nodes): a fold crosses a larger mesh
# in more iterations, and eps shrinking before it has moved stalls it (docs: "Long eps rounds")
BUDGET_NODES = 10_000  # an untangling budget holds up to this many free nodes; a wider mesh
# gets it scaled by sqrt(free nodes / BUDGET_NODES), as its rounds are (`untangle_budget`)
EXTEND_SHRINK = 0.5  # a spent untangling budget gets one more round while the worst corner
# det closes in on 0: |min det| at most this x its value two rounds before (`_extend`)
EXTEND_SHARE = 0.5  # ... up to this share of max_iter in all
STALL_ROUNDS = 12  # untangling rounds in a row that neither lower the inverted count nor
# raise the worst corner det end the run: a fold no move opens (`_stalled`; solvable meshes
# of the corpus take at most 4 untangling rounds in all: docs/global_untangle.md, "Giving up")
STALL_RISE = 1e-6  # a rise of the worst det by less than this x |det| is no progress
TIGHT_SHARE = 0.5  # give_up_early: the second untangling round kept more than this share of
# the first's inverted elements and of its worst det (below 0): a region too tight for the
# fold (its attempts end like this; one that opens later halves the worst det by then)
TIGHT_CHECK = 300  # ... judged already this many iterations into the round: the shares
# level off within 100-300 (failing attempts' rounds run on to 1 000-2 800 iterations)
SLOW_RISE = 0.25  # give_up_early: a later untangling round (the third on) that keeps every
# inverted element and raises the worst det (below 0) by less than this x |det|: the region
# is too tight (failing attempts creep by 4-7 %; the rounds of attempts that opened their
# fold, when they kept every inverted element, rose by 56 % and more)
PLATEAU_EVERY = 100  # options.end_round_on_plateau: an untangling round that has left at
PLATEAU_LEFT = 0.15  # most this share of the run's inverted elements ends at the first check
PLATEAU_RISE = 0.05  # (every PLATEAU_EVERY iterations, the first sets the marks) that finds
# neither fewer inverted elements than its fewest nor its worst corner det above its best by
# this x |det|: at a large eps the round settles near the regularised energy's minimum with
# a few elements still inverted, and the next, smaller eps opens them in a few iterations
# (docs/repair.md). A round with more left runs on: ended early it misleads give_up_early's
# judgement of the region (a fold that opens there was judged too tight: a held-out 20k
# C-grid's margin that opens after a plateau at 28 % went to the whole mesh, 16 -> 236 s)
EPS_MIN = 1e-9  # floor of eps (J is dimensionless: dets are ~1 at the reference size)
SIGMA_MIN = 0.1  # the paper's lower bound on sigma
STOP_REL_DECREASE = 1e-3  # stop polishing when one round lowers F by less than this (relative)
# lift_min_quality (max mean quality subject to a rising quality floor; see the docs)
LIFT_ITER = 200  # L-BFGS iterations per later round (100 stopped short on naca_deform: docs)
LIFT_GAP = 0.15  # next floor: min(q_min * options.lift_grow, q_min + GAP (q_avg - q_min))
LIFT_RATE = 3.0  # a round that lowers q_avg must raise q_min by at least RATE times as much
LIFT_ACTIVE = 1.0  # rounds after the first move only the nodes within options.lift_rings
#                    rings of the elements with q < LIFT_ACTIVE * floor (a small local problem)
LIFT_POOR = 0.5  # while q_min < this x q_avg, q_avg may fall below the input's (still capped)
LIFT_RETRY = 0.5  # share of the floor step after a round that cost too much q_avg (`_retries`;
#                   1.0: no retry)
LIFT_AVG_DROP = 0.03  # q_avg may not fall below (1 - this) x the best q_avg of the lift
SETTLE_FLOOR = 1.01  # the lift's last whole-mesh run: its floor is this x the climb's
# q_min (0: no such run); kept only when q_min and q_avg both rise (`_Lift._settle`)
SETTLE_ITER = 1000  # ... at most this many L-BFGS iterations, until 5 lower its energy by
SETTLE_ITER_SHAPED = 700  # ... or this many with `GlobalOptions.stiff_settle` (target
# shapes: the stiffness preconditioner gets as far in 700 as the size-based one in 1000;
# repair cases, medians: docs/global_untangle.md, "Settle")
SETTLE_TOL = 1e-7  # less than this (relative): the climb's runs stop far from the optimum of
# q_avg (300 iterations at 1e-5), and a converged run raises it by 0.003-0.02 at no q_min
SETTLE_MAX_FREE = 10_000  # meshes with more free nodes skip it (its cost grows with the
# mesh: the 'eegt+local' runs of large meshes keep their time)
SETTLE_WATCH = 300  # give_up_early: the settle stops after this many iterations when its
SETTLE_WATCH_EVERY = 20  # iterate, measured every this many, never passed its keep rule
# (q_min >= the climb's, q_avg above it): on 36 repair cases such runs were never kept, and
# every kept one passed it by 200


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


@dataclass
class Resume:
    """A resumable `untangle_global` (its ``resume`` argument): where the eps continuation
    stood when a call ended, so that the next call on the same sub-mesh (the same nodes and
    elements; fixed nodes may have moved) goes on from there instead of starting afresh.
    Each call updates it in place. A call whose budget ends inside an eps round leaves the
    round open (``used`` iterations at ``eps``, F_eps ``e_start`` at its start): the next
    call finishes it with fresh L-BFGS memory, then lowers eps as one long call would.
    ``eps`` None: the next call starts as a cold one (a fresh state, or a call that ended
    valid)."""

    eps: float | None = None
    used: int = 0  # iterations of the open eps round
    e_start: float = 0.0  # F_eps where the open round began
    top_det: float | None = None  # the best worst det and inverted count (`_stalled`)
    top_inv: int | None = None
    stall: int = 0
    calls: int = 0  # calls that used it
    energy: Any = None  # the first call's FoldoverEnergy (`_energy_for`): its tables and
    # reference sizes, as one long call keeps them; reused while the fixed nodes keep ...
    fixed_at: np.ndarray | None = None  # ... these coordinates (bit for bit) and the ...
    free_at: np.ndarray | None = None  # ... same free nodes


def untangle_budget(iterations: int, n_free: int) -> int:
    """The optimizer's untangling iterations per attempt for a budget of `iterations`: that
    many up to BUDGET_NODES free nodes, beyond in proportion to the mesh's width (the square
    root of its free nodes), as its eps rounds grow (docs/global_untangle.md, "Budget")."""
    if n_free <= BUDGET_NODES:
        return iterations
    need = iterations * iterations * n_free  # the least m with m^2 BUDGET_NODES >= need
    m = math.isqrt(-(-need // BUDGET_NODES))
    return m if m * m * BUDGET_NODES >= need else m + 1


def untangle_global(
    points: np.ndarray,
    groups: Mapping[int, np.ndarray],
    free: np.ndarray,
    options: GlobalOptions | None = None,
    progress: Callable[[int, int, int, Callable[[], np.ndarray]], Any] | None = None,
    factors: Factors | None = None,
    slide: SlideView | None = None,
    resume: Resume | None = None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Untangle a planar polygon mesh by minimising the foldover-free energy (eps continuation).

    points: (N, 2) float64; groups: arity -> (F_n, n) int node arrays, counterclockwise = valid;
    free: (N,) bool mask of the nodes that may move; options: budgets (max_iter, polish_iter,
    polish_power, time_limit) and the solver (`GlobalOptions`; None: the defaults); factors:
    per-face target shapes (`reference.Factors`, aligned with groups; None: regular polygons);
    slide: the free nodes that slide along their boundary curves (core.optimize.slide; the
    host solver then runs). progress(iterations, max_iter, n_inverted, current) is called
    after each round and every `tick_every` L-BFGS iterations inside it (a few tenths of a
    second of work on any mesh size), max_iter the budget so far (more rounds for a fold
    about to give way raise it), n_inverted the best iterate's and current() the current
    iterate's (N, 2) points (made when called: the caller measures them when it wants to);
    a falsy answer other than None cancels (`stops`).

    Returns (new points, info); non-free rows are bit-identical to the input. Once valid, steps
    that would invert a corner are rejected, so a valid iterate stays valid; when no valid one
    was reached, the iterate with the fewest inverted elements is returned.
    info: iterations, rounds, n_inverted_in, n_inverted_out, min_det (smallest normalised corner
    det), eps_history, seconds, seconds_per_iter, status ("untangled" / "failed" / "cancelled" /
    "nothing to do"), gave_up (the run ended early: STALL_ROUNDS rounds without progress, or
    options.give_up_early), too_tight (options.give_up_early ended it).

    resume: a `Resume` to go on from (and updated in place for the next call): the eps
    continuation of the last call on this sub-mesh continues from its eps and open round
    (a budget ends inside a round without lowering eps; no extra rounds are granted), for a
    solve split across calls (Live Untangle's frames). None: a cold run, as always.
    """
    t_start = time.perf_counter()
    P, free = _checked_input(points, free)
    if not np.all(np.isfinite(P)):
        raise ValueError("points contain NaN or inf")
    opt = options if options is not None else GlobalOptions()
    en = _energy_for(P, groups, free, factors, resume if slide is None else None)
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
        "gave_up": False,
        "too_tight": False,
    }
    if en.i0.size == 0 or st.size == 0:
        info["seconds"] = time.perf_counter() - t_start
        return P, info
    run = _Continuation(en, st, later, free, slide, opt, progress, run_lbfgs, n_inv,
                        info["min_det"], resume)
    run.solve(t_start)
    run.keep_resume()
    x, y = run.st.unpack(run.best_v)
    out = P.copy()
    out[run.st.written, 0] = x[run.st.written]
    out[run.st.written, 1] = y[run.st.written]
    n_out = en.n_inverted(x, y)
    secs = time.perf_counter() - t_start
    info.update(
        iterations=run.total,
        rounds=run.rounds,
        n_inverted_out=n_out,
        min_det=float(np.min(en.dets(x, y))),
        eps_history=run.eps_hist,
        seconds=secs,
        seconds_per_iter=secs / max(run.total, 1),
        status=run.status or ("untangled" if n_out == 0 else "failed"),
        gave_up=run.gave_up,
        too_tight=run.too_tight,
    )
    return out, info


def _energy_for(P: np.ndarray, groups: Mapping[int, np.ndarray], free: np.ndarray,
                factors: Factors | None, resume: Resume | None) -> FoldoverEnergy:
    """The call's energy: the resumed solve's own (built by its first call: the same
    tables, frozen corners and reference sizes, as in one long call) while the sub-mesh's
    fixed nodes keep their bits and the free ones are the same; else a new one (kept in
    `resume` for the next call). Building it costs about 60 ms at 50 000 faces, a
    frame's share."""
    fixed = P[~free]
    r = resume
    if r is not None and r.energy is not None and r.free_at is not None and \
            r.free_at.shape == free.shape and np.array_equal(r.free_at, free) and \
            r.fixed_at.tobytes() == fixed.tobytes():
        return r.energy
    en = FoldoverEnergy(P, groups, free, factors)
    if r is not None:
        r.energy, r.fixed_at, r.free_at = en, fixed.copy(), free.copy()
    return en


class _Continuation:
    """`untangle_global`'s rounds: L-BFGS on F_eps with eps lowered between rounds (the
    paper's continuation) while the mesh is tangled, then guarded polish rounds at the eps
    floor; keeps the iterate with the fewest inverted elements (`best_v`)."""

    def __init__(self, en: FoldoverEnergy, st: State, later: bool, free: np.ndarray,
                 slide: SlideView | None, opt: GlobalOptions,
                 progress: Callable[[int, int, int, Callable[[], np.ndarray]], Any] | None,
                 run_lbfgs: Solver,
                 n_inv: int, dmin: float, resume: Resume | None = None):
        self.en, self.st, self.later, self.free, self.slide = en, st, later, free, slide
        self.opt, self.progress, self.run_lbfgs = opt, progress, run_lbfgs
        self.v = st.pack(st.x, st.y)
        self.eps = max(0.1 * abs(dmin), 1e-3) if dmin <= 0.0 else EPS_MIN
        self.inner = max(INNER_ITER, int(np.ceil(INNER_PER_SQRT_NODE * np.sqrt(free.sum()))))
        self.best_v, self.best_inv = self.v, n_inv
        self.n_inv_in = n_inv  # the run's inverted elements at its start
        self.valid = dmin > 0.0  # every corner that can move is positive (others constant)
        self.total = 0
        self.untangle_its = 0  # L-BFGS iterations before the mesh was valid
        self.polish_used = 0
        self.status = ""
        self.eps_hist: list[float] = []
        self.dmins = [dmin]  # the min det at the start and after each untangling round
        self.top_det, self.top_inv = dmin, n_inv  # the best worst det and inverted count
        self.stall = 0  # untangling rounds in a row without progress (`_stalled`)
        self.marks: list[tuple[int, float]] = []  # (inverted, min det) after each
        #                                           untangling round (`_too_tight`)
        self.too_tight = False  # give_up_early ended the run (`_too_tight`)
        self.granted = 0  # iterations `_extend` added to max_iter
        self.rounds = 0
        self.cancel = False
        self.gave_up = False  # `_stalled` ended the run
        self.resume = resume
        if resume is not None:
            self._resumed(resume, dmin)

    def _resumed(self, r: Resume, dmin: float) -> None:
        """Go on from the last call's continuation (`Resume`): its eps and open round while
        the mesh is tangled, its progress marks (`_stalled`)."""
        r.calls += 1
        if dmin > 0.0 or r.eps is None:
            r.eps, r.used = None, 0
            return
        self.eps = r.eps
        if r.top_det is not None and r.top_inv is not None:
            self.top_det, self.top_inv, self.stall = r.top_det, r.top_inv, r.stall

    def keep_resume(self) -> None:
        """Where the continuation stands, into `resume` for the next call."""
        r = self.resume
        if r is None:
            return
        if self.valid:
            r.eps, r.used = None, 0
        else:
            r.eps = self.eps
        r.top_det, r.top_inv, r.stall = self.top_det, self.top_inv, self.stall

    def _open_round(self, guard: bool, e_start: float) -> float:
        """F_eps at the round's start: the open round's (`Resume`) when it goes on."""
        r = self.resume
        if r is None or guard or not r.used:
            return e_start
        return r.e_start

    def _cut(self, guard: bool, its: int, cap: int, e_start: float) -> bool:
        """A resumable call whose budget ended inside an untangling round: the round stays
        open for the next call (eps unchanged); True ends this call."""
        r = self.resume
        if r is None or guard or self.valid:
            if r is not None:
                r.used = 0
            return False
        left = self.inner - r.used
        if its >= cap and cap < left:
            r.used += its
            r.e_start = e_start
            return True
        r.used = 0
        return False

    def solve(self, t_start: float) -> None:
        """Rounds until the budget, a stop rule or a cancel ends them."""
        opt, en = self.opt, self.en
        while self.total < self.budget + self._extra():
            self.rounds += 1
            self.eps_hist.append(self.eps)
            guard = self.valid  # valid: polish the quality, never invert a corner again
            en.power = float(opt.polish_power) if guard else 1.0
            e_start = self._open_round(guard, en.value(*self.st.unpack(self.v), self.eps))
            cap = self._cap(guard)
            if cap <= 0:
                break
            its = self._round(cap, guard)
            e_end, dmin, n_inv = self._take_iterate(its, guard)
            if self.cancel or (self.progress is not None and stops(self.progress(
                    self.total, self.budget, n_inv, partial(self._points, self.v)))):
                self.status = "cancelled"
                break
            if self._cut(guard, its, cap, e_start):
                break
            decrease = (e_start - e_end) / abs(e_start) if e_start != 0.0 else 0.0
            if self._done(guard, decrease, its, t_start):
                break
            if not guard:
                if self._stalled(dmin, n_inv):
                    break
                self._extend(dmin)
            self.eps = self._next_eps(decrease, dmin)

    @property
    def budget(self) -> int:
        """max_iter and the iterations `_extend` granted."""
        return self.opt.max_iter + self.granted

    def _extend(self, dmin: float) -> None:
        """One more round when the budget is spent, the mesh still tangled and its worst
        corner det closing in on 0 (|min det| at most EXTEND_SHRINK x its value two rounds
        before), up to EXTEND_SHARE x max_iter in all: a fold about to give way finishes
        instead of starting over (docs/global_untangle.md, "Budget")."""
        self.dmins.append(dmin)
        spent = self.total >= self.budget
        if (not spent or self.valid or len(self.dmins) < 3 or self.resume is not None
                or -dmin > EXTEND_SHRINK * -self.dmins[-3]):
            return
        more = min(self.inner, int(EXTEND_SHARE * self.opt.max_iter) - self.granted)
        self.granted += max(more, 0)

    def _stalled(self, dmin: float, n_inv: int) -> bool:
        """Whether STALL_ROUNDS untangling rounds in a row have neither lowered the inverted
        count below its best nor raised the worst corner det by STALL_RISE (relative) above
        its best: the iterate sits where the energy has no way down that opens the fold (a
        tangle no position of the free nodes can fix has no certificate in general:
        core/run/hopeless.py finds the common ones). Such a run ends as 'failed' after a few
        dozen iterations instead of the whole budget (tens of thousands of rounds of one
        iteration each at the eps floor)."""
        if self._too_tight(dmin, n_inv):
            self.gave_up = self.too_tight = True
            return True
        progress = False
        if dmin > self.top_det + STALL_RISE * abs(self.top_det):
            self.top_det, progress = dmin, True
        if n_inv < self.top_inv:
            self.top_inv, progress = n_inv, True
        self.stall = 0 if progress else self.stall + 1
        self.gave_up = self.stall >= STALL_ROUNDS
        return self.gave_up

    def _too_tight(self, dmin: float, n_inv: int) -> bool:
        """options.give_up_early: after the second untangling round, whether it kept more
        than TIGHT_SHARE of the first round's inverted elements and of its worst det (still
        below 0); after a later one, whether it was slow (`_slow_after`). The region's fold
        does not open there (a repair then grows the region); cold runs and resumed calls go
        on."""
        if not self.opt.give_up_early or self.resume is not None:
            return False
        self.marks.append((n_inv, dmin))
        if len(self.marks) == 2:
            return self._tight_after_first(n_inv, dmin)
        return len(self.marks) > 2 and self._slow_after(*self.marks[-2], n_inv, dmin)

    @staticmethod
    def _slow_after(inv0: int, det0: float, n_inv: int, dmin: float) -> bool:
        """Whether an untangling round that ended at (n_inv, dmin) from (inv0, det0) kept
        every inverted element and raised the worst det, still below 0, by less than
        SLOW_RISE x |det0|."""
        return 0 < n_inv and inv0 <= n_inv and dmin < 0.0 and \
            dmin - det0 < SLOW_RISE * abs(det0)

    def _tight_after_first(self, n_inv: int, dmin: float) -> bool:
        """Whether (n_inv, dmin) of the second untangling round keep more than TIGHT_SHARE of
        the first round's inverted elements and of its worst det (still below 0)."""
        inv1, det1 = self.marks[0]
        return n_inv > TIGHT_SHARE * inv1 and dmin < 0.0 and dmin < TIGHT_SHARE * det1

    def _tight_watch(self, tick: Tick | None) -> Tick:
        """The second untangling round's tick under give_up_early: `tick`, and a stop at
        the first tick TIGHT_CHECK iterations in when the round is already too tight there
        (`_too_tight` then ends the run on that point); else the round runs on as it would."""
        en, st = self.en, self.st
        checked = False

        def watch(it: int, point: Callable[[], np.ndarray]) -> bool:
            nonlocal checked
            if checked or it < TIGHT_CHECK:
                return True
            checked = True
            return not self._tight_after_first(*_inverted_and_worst(en, *st.unpack(point())))

        return _chained(tick, watch)

    def _plateau_watch(self, tick: Tick | None) -> Tick:
        """An untangling round's tick under options.end_round_on_plateau: `tick`, and every
        PLATEAU_EVERY iterations the inverted count and worst corner det of the round's point
        (the first check sets the marks); a check that betters neither (`PLATEAU_RISE`) with
        at most PLATEAU_LEFT of the run's inverted elements left ends the round, whose point
        then goes on to the next eps as at the round's cap."""
        en, st, few = self.en, self.st, PLATEAU_LEFT * self.n_inv_in
        marks: tuple[int, float] | None = None  # (fewest inverted, best worst det) so far
        measured_at = 0

        def watch(it: int, point: Callable[[], np.ndarray]) -> bool:
            nonlocal marks, measured_at
            if it - measured_at < PLATEAU_EVERY:
                return True
            measured_at = it
            n, d = _inverted_and_worst(en, *st.unpack(point()))
            if marks is None:
                marks = (n, d)
                return True
            fewest, top = marks
            marks = (min(fewest, n), max(top, d))
            return n > few or n < fewest or d > top + PLATEAU_RISE * abs(top)

        return _chained(tick, watch)

    def _cap(self, guard: bool) -> int:
        """The round's L-BFGS iterations: while tangled `inner` per eps; once valid, one
        long run, no memory restarts (the rest of the polish budget)."""
        left = self.budget - self.total
        if guard:
            return min(left + self._extra(), self._polish_budget() - self.polish_used)
        if self.resume is not None:
            return min(left, self.inner - self.resume.used)
        return min(left, self.inner)

    def _extra(self) -> int:
        """What the polish budget adds to max_iter (only once the mesh is valid)."""
        return max(self._polish_budget() - self.opt.polish_iter, 0) if self.valid else 0

    def _polish_budget(self) -> int:
        """The polish's iterations: polish_iter, or as many as the untangling took (at most
        one round, `inner`) when that is more and options.long_polish (a fold that took long
        to untangle leaves the mesh far from the energy's optimum: docs/global_untangle.md,
        "Polish after a long untangle"); none when polish_iter is 0. What it adds to
        polish_iter comes on top of max_iter."""
        polish = self.opt.polish_iter
        if polish <= 0 or not self.opt.long_polish:
            return max(polish, 0)
        return max(polish, min(self.untangle_its, self.inner))

    def _tick(self) -> Tick | None:
        """The progress tick of a round (long runs report, and cancel, from inside)."""
        if self.progress is None:
            return None
        progress, max_iter = self.progress, self.budget
        done, n_now = self.total, self.best_inv

        def tick(it: int, point: Callable[[], np.ndarray]) -> bool:
            def current() -> np.ndarray:
                return self._points(point())

            self.cancel = self.cancel or stops(progress(done + it, max_iter, n_now, current))
            return not self.cancel

        return tick

    def _points(self, v: np.ndarray) -> np.ndarray:
        """(N, 2) points of the packed iterate v."""
        return np.column_stack(self.st.unpack(v))

    def _round(self, cap: int, guard: bool) -> int:
        """One L-BFGS run from v; the iterations it took."""
        st = self.st
        tick = self._tick()
        if (not guard and self.opt.give_up_early and self.resume is None
                and len(self.marks) == 1):  # the second untangling round
            tick = self._tight_watch(tick)
        if not guard and self.opt.end_round_on_plateau and self.resume is None:
            tick = self._plateau_watch(tick)
        self.v, its = self.run_lbfgs(st.view(self.en), st, self.v, self.eps, max_it=cap,
                                     guard=guard, tick=tick)
        self.total += its
        if guard:
            self.polish_used += its
        else:
            self.untangle_its += its
        return its

    def _take_iterate(self, its: int, guard: bool) -> tuple[float, float, int]:
        """The round's end point: (F_eps there, min det, inverted elements); the best so
        far, and the sliding nodes join once the mesh is valid."""
        en, st = self.en, self.st
        x, y = st.unpack(self.v)
        e_end = en.value(x, y, self.eps)
        n_inv, dmin = _inverted_and_worst(en, x, y)
        self.valid = dmin > 0.0
        if n_inv <= self.best_inv:
            self.best_v, self.best_inv = self.v, n_inv
        if self.later and self.valid:  # valid now: the sliding nodes join (best_v is this)
            self.st, self.later = make_state(np.column_stack([x, y]), self.free, self.slide), False
            self.v = self.best_v = self.st.pack(x, y)
        return e_end, dmin, n_inv

    def _done(self, guard: bool, decrease: float, its: int, t_start: float) -> bool:
        """Stop: a polish round that barely lowered F, a valid mesh without a polish
        budget, or the time limit."""
        opt = self.opt
        if guard and (decrease < STOP_REL_DECREASE or its == 0):
            return True
        if self.valid and opt.polish_iter <= 0:
            return True
        return opt.time_limit is not None and time.perf_counter() - t_start > opt.time_limit

    def _next_eps(self, decrease: float, dmin: float) -> float:
        """The paper's eps update from the round's relative decrease and min det; the eps
        floor once valid (the guard keeps dets > 0: the exact barrier, see the docs)."""
        if self.valid:
            return EPS_MIN
        sigma = max(decrease, SIGMA_MIN)
        mu = (1.0 - sigma) * chi_scalar(dmin, self.eps)
        return max(2.0 * float(np.sqrt(mu * (mu - dmin))) if dmin < mu else EPS_MIN, EPS_MIN)


def _inverted_and_worst(en: FoldoverEnergy, x: np.ndarray, y: np.ndarray) -> tuple[int, float]:
    """(inverted elements, smallest corner det) at the node positions x, y: the marks the
    continuation's rules (`_stalled`, `_too_tight`, the plateau) judge a point by."""
    return en.n_inverted(x, y), float(np.min(en.dets(x, y)))


def _chained(tick: Tick | None, watch: Tick) -> Tick:
    """A tick that asks `tick` (a progress report, None: none) and then `watch`: the run
    stops when either says so (`state.stops`)."""
    def chained(it: int, point: Callable[[], np.ndarray]) -> bool:
        if tick is not None and stops(tick(it, point)):
            return False
        return watch(it, point)

    return chained


def _runs(run_lbfgs: Solver, en: LiftEnergy, st: State, v: np.ndarray, opt: GlobalOptions,
          tick: Tick | None,
          show: Callable[[np.ndarray], None] | None = None
          ) -> tuple[np.ndarray, int, np.ndarray]:
    """The lift's whole-mesh run: (point, iterations, element qualities there). One L-BFGS
    run, or (opt.lift_chunk > 0) runs of that many iterations with fresh memory each, until
    one lowers the energy by less than opt.lift_rel_tol (relative). Fresh memory matters on
    a large mesh with a few stiff corners (a just-untangled spot): the memory's scale then
    shrinks every step of the whole mesh (docs/global_untangle.md, "Restarts").
    show(qualities), with a tick, sees each run's end point (the live progress numbers)."""
    chunk, max_it, tol = opt.lift_chunk, opt.lift_first_iter, opt.lift_rel_tol
    if chunk <= 0:
        v, its = run_lbfgs(st.view(en), st, v, EPS_MIN, max_it=max_it, guard=True,
                           rel_tol=tol, tick=tick)
        return v, its, en.element_quality(*st.unpack(v))
    total = 0
    e0, q = en.value_and_quality(*st.unpack(v))  # the energy and qualities at v
    while total < max_it:
        sub = None if tick is None else (lambda it, point, base=total: tick(base + it, point))
        v, its = run_lbfgs(
            st.view(en), st, v, EPS_MIN, max_it=min(chunk, max_it - total), guard=True,
            rel_tol=tol,
            tick=sub,
        )
        total += its
        e1, q = en.value_and_quality(*st.unpack(v))
        if tick is not None:
            if show is not None:
                show(q)
            if stops(tick(total, v.copy)):
                break
        if its < chunk or not e0 - e1 > tol * abs(e0):
            break
        e0 = e1
    return v, total, q


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
    nodes within `options.lift_rings` rings of the elements under the new floor. A round is
    kept only when q_min rises, q_avg stays within LIFT_AVG_DROP (relative) of the best q_avg
    seen and, once q_min >= LIFT_POOR q_avg, at least the input's, and any q_avg it costs buys
    at least LIFT_RATE times as much q_min; a round that is not kept ends the climb, or once,
    on a poor mesh, makes the later rounds take LIFT_RETRY of the floor step (`_retries`).
    Returns (points, info) with the kept iterate: the input itself (bit-identical) when
    nothing qualifies or the input has an inverted element. info: iterations, rounds (kept),
    q_min_in, q_avg_in, q_min_out, q_avg_out, trail ((q_min, q_avg) after each run), seconds,
    status ("lifted", "unchanged", "cancelled").
    progress(iterations, round, q_min, q_avg) after each run (the kept iterate's qualities)
    and every few tenths of a second inside one (the whole mesh's, with the run's current
    point, measured now and then: `Sampled`); a falsy answer other than None
    cancels (`stops`) and the input is returned. options.solver runs the L-BFGS solves;
    factors: per-face target shapes (the qualities are then against them); slide: the free
    nodes that slide along their boundary curves (the host solver then runs); neighbourhood:
    the `Neighbourhood` of (groups, free, factors) if the caller has one (else built here).
    """
    t_start = time.perf_counter()
    P, free = _checked_input(points, free)
    opt = options if options is not None else GlobalOptions()
    en = LiftEnergy(P, groups, free, factors)
    st = make_state(P, free, slide)
    run_lbfgs = opt.run(sliding=type(st) is not State)
    info: dict[str, Any] = {"iterations": 0, "rounds": 0, "status": "unchanged"}
    q = en.element_quality(st.x, st.y) if en.n_elem else np.zeros(0)
    m0 = float(q.min()) if q.size else 0.0
    a0 = add_reduce(q) / q.size if q.size else 0.0
    info.update(q_min_in=m0, q_avg_in=a0, q_min_out=m0, q_avg_out=a0)
    if q.size == 0 or st.size == 0 or not m0 > 0.0 or not np.all(np.isfinite(P)):
        info["seconds"] = time.perf_counter() - t_start
        return P, info

    lift = _Lift(en, st, _LiftMesh(groups, free, factors, slide), neighbourhood, opt,
                 progress, run_lbfgs, q, info)
    if not lift.climb():
        info.update(iterations=lift.total, status="cancelled",
                    seconds=time.perf_counter() - t_start)
        return P, info
    info.update(iterations=lift.total, seconds=time.perf_counter() - t_start)
    if lift.best_v is None:
        return P, info
    x, y = st.unpack(lift.best_v)
    P[st.written, 0] = x[st.written]
    P[st.written, 1] = y[st.written]
    info.update(q_min_out=lift.best_m, q_avg_out=lift.best_a, status="lifted")
    return P, info


def _numbers(q: np.ndarray) -> tuple[float, float]:
    """(q_min, q_avg) of element qualities q."""
    return float(q.min()), add_reduce(q) / q.size


@dataclass(frozen=True)
class _LiftMesh:
    """The mesh a lift works on, as `lift_min_quality` was handed it (its rounds cut
    sub-meshes from it)."""

    groups: Mapping[int, np.ndarray]
    free: np.ndarray
    factors: Factors | None
    slide: SlideView | None


class _Lift:
    """`lift_min_quality`'s climb: the whole-mesh run at the input's floor, then rounds
    with a rising floor over sub-meshes, each kept or ending the climb (`_keeps`)."""

    def __init__(self, en: LiftEnergy, st: State, mesh: _LiftMesh,
                 neighbourhood: Neighbourhood | None, opt: GlobalOptions,
                 progress: Callable[[int, int, float, float], Any] | None,
                 run_lbfgs: Solver, q: np.ndarray, info: dict[str, Any]):
        self.en, self.st, self.mesh, self.opt = en, st, mesh, opt
        self.progress, self.run_lbfgs, self.info = progress, run_lbfgs, info
        self.near = neighbourhood  # node -> element incidence (built on first use)
        self.m0, self.a0 = info["q_min_in"], info["q_avg_in"]
        self.best_v, self.best_m, self.best_a = None, self.m0, self.a0
        self.v = st.pack(st.x, st.y)
        self.q, self.cur_m, self.cur_a = q, self.m0, self.a0
        self.peak = self.a0  # the best q_avg seen: q_avg may fall at most LIFT_AVG_DROP below
        self.total = 0
        self.trail: list[tuple[float, float]] = []  # (q_min, q_avg) after each run
        info["trail"] = self.trail
        self.live: Sampled[tuple[float, float]] = Sampled()  # (q_min, q_avg): progress
        self.live.set((self.m0, self.a0))
        self.cancel = False
        self.step = 1.0  # share of the full floor step a round takes (LIFT_RETRY once retried)

    def climb(self) -> bool:
        """Every round the options allow, until one is not kept (and not retried); False:
        cancelled."""
        en, st, progress = self.en, self.st, self.progress
        for r in range(self.opt.lift_rounds + 1):
            en.qc = self._floor(r)
            if r == 0:  # the whole mesh: maximise q_avg at the input's floor
                tick = self._tick(r, lambda v: _numbers(en.element_quality(*st.unpack(v))))
                vt, its, qt = _runs(self.run_lbfgs, en, st, self.v, self.opt, tick, self._show)
            else:  # only near the elements under the new floor: the rest is at its optimum
                found = self._local_round(r)
                if found is None:
                    break
                vt, its, qt = found
            self.total += its
            qm, qa = _numbers(qt)
            self.trail.append((qm, qa))
            kept = r == 0 or self._keeps(qm, qa)
            shown = (qm, qa) if kept else (self.cur_m, self.cur_a)  # the iterate going on
            if self.cancel or (progress is not None and
                               stops(progress(self.total, r, *shown))):
                return False
            if not kept:
                if not self._retries(qm):
                    break
                self.step = LIFT_RETRY
                continue
            # the first run maximises q_avg at the input's floor: the start of the climb
            self.v, self.q, self.cur_m, self.cur_a = vt, qt, qm, qa
            self.peak = max(self.peak, qa)
            if r > 0:
                self.info["rounds"] = r
            if (self.cur_a >= self.a0 or self.info["rounds"]) and self.cur_m > self.best_m:
                self.best_v, self.best_m, self.best_a = self.v, self.cur_m, self.cur_a
        return self._settle()

    def _settle(self) -> bool:
        """After local rounds, on meshes up to SETTLE_MAX_FREE free nodes: one whole-mesh run
        that maximises q_avg at a floor just above the climb's q_min (SETTLE_FLOOR x q_min),
        converged further than the climb's runs (SETTLE_ITER, SETTLE_TOL), kept only when
        neither measure falls (docs/global_untangle.md, "Settle"). With options.stiff_settle
        it runs with the stiffness preconditioner, at most SETTLE_ITER_SHAPED iterations."""
        if (SETTLE_FLOOR <= 0.0 or not self.info["rounds"] or self.best_v is None
                or int(np.count_nonzero(self.mesh.free)) > SETTLE_MAX_FREE):
            return True
        en, st, cap = self.en, self.st, SETTLE_ITER
        en.qc = SETTLE_FLOOR * self.best_m
        if self.opt.stiff_settle:  # a copy: the climb's energy keeps its preconditioner
            en, cap = en.with_precond(en.stiffness_precond()), SETTLE_ITER_SHAPED
        r = self.opt.lift_rounds + 1
        tick = self._tick(r, lambda v: _numbers(en.element_quality(*st.unpack(v))))
        if self.opt.give_up_early:
            tick = self._watched(tick)
        opt = replace(self.opt, lift_first_iter=cap, lift_rel_tol=SETTLE_TOL, lift_chunk=0)
        vt, its, qt = _runs(self.run_lbfgs, en, st, self.best_v, opt, tick, self._show)
        self.total += its
        qm, qa = _numbers(qt)
        self.trail.append((qm, qa))
        if self.cancel:
            return False
        if self._settle_keeps(qm, qa):
            self.best_v, self.best_m, self.best_a = vt, qm, qa
            self.v, self.q, self.cur_m, self.cur_a = vt, qt, qm, qa
            self.info["settled"] = True
        return True

    def _settle_keeps(self, qm: float, qa: float) -> bool:
        """Whether the settle's (q_min, q_avg) is kept: neither falls below the climb's best,
        and q_avg rises."""
        return qm >= self.best_m and qa > self.best_a

    def _watched(self, tick: Tick | None) -> Tick:
        """The settle's tick for options.give_up_early (a repair's attempt): `tick`, and a
        stop once SETTLE_WATCH iterations have passed without the run's iterate passing
        `_settle_keeps` at a measurement (every SETTLE_WATCH_EVERY iterations): such a
        settle is not kept (its q_min stays below the climb's, or its q_avg falls from the
        start), and it costs a repair's attempt as much as its climb."""
        en, st = self.en, self.st
        reached, measured_at = False, 0

        def watch(it: int, point: Callable[[], np.ndarray]) -> bool:
            nonlocal reached, measured_at
            if reached or it - measured_at < SETTLE_WATCH_EVERY:
                return True
            measured_at = it
            reached = self._settle_keeps(*_numbers(en.element_quality(*st.unpack(point()))))
            return reached or it < SETTLE_WATCH

        return _chained(tick, watch)

    def _retries(self, qm: float) -> bool:
        """Whether a round that was not kept is tried again at LIFT_RETRY of its floor step
        (it and every later round): once, and only when it raised q_min on a poor mesh (q_min
        < LIFT_POOR q_avg), where it missed on the q_avg it cost, not on q_min."""
        return (LIFT_RETRY < 1.0 and self.step == 1.0 and qm > self.cur_m
                and self.cur_m < LIFT_POOR * self.cur_a)

    def _floor(self, r: int) -> float:
        """Round r's floor qc: the input's q_min, then rising with the kept iterate's."""
        if r == 0:
            return self.m0
        m, a = self.cur_m, self.cur_a
        full = min(m * self.opt.lift_grow, m + LIFT_GAP * (a - m))
        return full if self.step == 1.0 else m + self.step * (full - m)

    def _tick(self, r: int, numbers: Callable[[np.ndarray], tuple[float, float]]
              ) -> Tick | None:
        """Round r's progress tick: the current iterate's (q_min, q_avg) of the whole mesh,
        `numbers` of the solve's point, measured now and then (`Sampled`)."""
        if self.progress is None:
            return None
        progress, done = self.progress, self.total
        self.live.set((self.cur_m, self.cur_a))

        def tick(it: int, point: Callable[[], np.ndarray]) -> bool:
            self.live.update(lambda: numbers(point()))
            self.cancel = self.cancel or stops(progress(done + it, r, *self.live.value))
            return not self.cancel

        return tick

    def _show(self, q: np.ndarray) -> None:
        """The whole-mesh run's latest end point: its numbers go to the progress ticks."""
        self.live.set(_numbers(q))

    def _local_round(self, r: int) -> tuple[np.ndarray, int, np.ndarray] | None:
        """Round r's L-BFGS run over the free nodes near the elements under the floor: (point,
        iterations, element qualities), or None when no such node is free."""
        en, st, mesh = self.en, self.st, self.mesh
        if self.near is None:
            self.near = Neighbourhood(mesh.groups, mesh.free, mesh.factors)
        (sub, nodes, sfree, sub_f), elems = self.near.submesh(self.q < LIFT_ACTIVE * en.qc,
                                                                self.opt.lift_rings)
        if not sfree.any():
            return None
        x, y = st.unpack(self.v)
        sp = np.stack([x[nodes], y[nodes]], axis=1)
        sen = LiftEnergy(sp, sub, sfree, sub_f)
        sen.qc = en.qc
        sst = make_state(sp, sfree, None if mesh.slide is None else
                         mesh.slide.sub(nodes, np.column_stack([x, y])))

        def merged(sv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """The whole mesh's point and element qualities with the sub-mesh at sv."""
            sx, sy = sst.unpack(sv)
            xt, yt = x.copy(), y.copy()
            xt[nodes], yt[nodes] = sx, sy
            qt = self.q.copy()  # only the sub-mesh's elements change
            qt[elems] = en.element_quality_of(elems, xt, yt)
            return st.pack(xt, yt), qt

        sv, its = self.run_lbfgs(
            sst.view(sen), sst, sst.pack(sst.x, sst.y), EPS_MIN, max_it=LIFT_ITER,
            guard=True, rel_tol=self.opt.lift_rel_tol,
            tick=self._tick(r, lambda v: _numbers(merged(v)[1])),
        )
        vt, qt = merged(sv)
        return vt, its, qt

    def _keeps(self, qm: float, qa: float) -> bool:
        """Whether a round's (q_min, q_avg) is kept: q_min rises, q_avg stays above its
        floor, and q_avg it costs buys LIFT_RATE times as much q_min."""
        cur_m, cur_a = self.cur_m, self.cur_a
        floor = (1.0 - LIFT_AVG_DROP) * self.peak
        if cur_m >= LIFT_POOR * cur_a:
            floor = max(floor, self.a0)
        return not (qa < floor or qm <= cur_m
                    or (qa < cur_a and qm - cur_m < LIFT_RATE * (cur_a - qa)))
