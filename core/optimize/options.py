"""The one options object the pipeline hands to the global stage."""

from __future__ import annotations

from dataclasses import dataclass

from .dispatch import Solver, solver_to_run

__all__ = ["LIFT_GROW", "GlobalOptions"]

LIFT_GROW = 1.15  # a lift round's floor: at most this x the q_min before it (`lift_grow`)


@dataclass(frozen=True)
class GlobalOptions:
    """Budgets and the solver of one global-stage call.

    max_iter bounds all L-BFGS iterations of `untangle_global`; polish_iter those it spends
    improving quality once no element is inverted (0: stop at the first valid iterate), or
    (long_polish) as many as the untangling took when that is more, up to one eps round, on
    top of max_iter;
    polish_power p > 0 polishes sum (f / 2)^p instead of the paper's sum f (p > 1 raises q_min
    and lowers q_avg, p < 1 the opposite); time_limit (s) stops it early; lift_first_iter
    bounds the first, whole-mesh run of `lift_min_quality` (it maximises the mean quality) and
    lift_rounds its rising-floor rounds; a lift run stops when 5 iterations lower its energy by
    less than lift_rel_tol (relative); lift_chunk > 0 splits the whole-mesh run into runs of
    that many iterations with fresh L-BFGS memory; each later lift round moves only the free
    nodes within lift_rings rings of the elements under its floor, a floor at most lift_grow
    times the q_min before it; solver runs each L-BFGS
    solve (None: NumPy); give_up_early: the run gives up after its second untangling round
    when that round neither halved the inverted count nor the worst corner det's distance
    below 0 of the first (`TIGHT_SHARE`; judged already `TIGHT_CHECK` iterations into the
    round): a repair's region too tight for its fold, which the repair grows
    (core.run.repair), instead of spending its budget there twice; and its
    lift's settle stops after `SETTLE_WATCH` iterations whose q_min never reached the climb's
    (such a settle is not kept); end_round_on_plateau: an untangling round ends once a
    check finds neither its inverted count nor its worst corner det improved
    (`stages.PLATEAU_EVERY`; a repair's attempts), instead of running to its cap;
    stiff_settle: the lift's settle runs with the preconditioner of the targets' stiffness
    (`FoldoverEnergy.stiffness_precond`) for at most `stages.SETTLE_ITER_SHAPED` iterations
    (runs with target shapes: the size-based one is blind to their anisotropy).
    """

    max_iter: int = 3000
    polish_iter: int = 300
    long_polish: bool = True
    polish_power: float = 1.0
    time_limit: float | None = None
    lift_first_iter: int = 150
    lift_rounds: int = 6
    lift_rel_tol: float = 1e-5
    lift_chunk: int = 0
    lift_rings: int = 6
    lift_grow: float = LIFT_GROW
    solver: Solver | None = None
    give_up_early: bool = False
    end_round_on_plateau: bool = False
    stiff_settle: bool = False

    def __post_init__(self) -> None:
        if not self.polish_power > 0.0:
            raise ValueError("polish_power must be > 0")
        if self.lift_rings < 0:
            raise ValueError("lift_rings must be >= 0")
        if not self.lift_grow > 1.0:
            raise ValueError("lift_grow must be > 1")

    def run(self, sliding: bool = False) -> Solver:
        """The L-BFGS to call (`dispatch.solver_to_run`)."""
        return solver_to_run(self.solver, sliding)
