"""Which L-BFGS solves a global-stage problem, and the contract every one of them keeps.

Three implementations of `Solver` give the same iterates to the last bit: the host's
`solver.lbfgs` (NumPy), the parallel kernels `solver_parallel.ParallelLbfgs` (many
work-items; any device) and the single-work-item kernel `solver_opencl.OpenCLLbfgs` (one
work-item runs the whole solve; CPU devices). The rule, all of it here:

1. a run's global stage uses a device solver only when its engine is OpenCL and no node
   slides (a sliding node's curve parameter is a variable the kernels do not have):
   `uses_device`, `solver_to_run`;
2. the kernels solve the plain energies only: a powered polish (power != 1) or an empty
   problem runs on the host (`on_host`), as does a problem whose tables need indices
   beyond 32 bits (found when they are built: `TooLarge`);
3. on a CPU device, problems under `SMALL_CORNERS` energy corners go to the single-work-item
   kernel, faster there (docs/opencl.md has the measurements); elsewhere every problem runs
   on the parallel kernels (`single_kernel_corners`, `route`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal, Protocol

import numpy as np

from ..choices import global_stage_on_device
from .state import REL_TOL, Tick

if TYPE_CHECKING:
    from .energy import FoldoverEnergy
    from .state import State

__all__ = ["SMALL_CORNERS", "Solver", "TooLarge", "on_host", "route", "single_kernel_corners",
           "solver_to_run", "uses_device"]

# Below this many energy corners the single-work-item kernel beats the parallel kernels on
# a CPU device (~35 launches and a read per iteration cost the parallel kernels ~0.15 ms;
# bench/lbfgs_parallel_bench.py, docs/opencl.md)
SMALL_CORNERS = 20_000


class Solver(Protocol):
    """An L-BFGS run from v0 on `en` (packed free coordinates `st`): returns the last
    accepted point and the iterations done. guard: reject trial points with a corner det
    <= 0 (else stop once every det is positive); stops after max_it iterations, when 5
    iterations lower the energy by less than rel_tol (relative), or when tick(iterations,
    point), called every `en.tick_every` iterations, cancels (`state.Tick`)."""

    def __call__(
        self,
        en: FoldoverEnergy,
        st: State,
        v0: np.ndarray,
        eps: float,
        *,
        max_it: int,
        guard: bool,
        rel_tol: float = REL_TOL,
        tick: Tick | None = None,
    ) -> tuple[np.ndarray, int]: ...


class TooLarge(ValueError):
    """A problem's device tables need indices beyond 32 bits: the host solves it."""


def uses_device(backend_name: str, sliding: bool) -> bool:
    """Whether a run's global stage may use a device solver (rule 1)."""
    return global_stage_on_device(backend_name) and not sliding


def solver_to_run(solver: Solver | None, sliding: bool) -> Solver:
    """The solver a stage calls: the host's with sliding nodes or without a device solver."""
    if solver is None or sliding:
        from .solver import lbfgs

        return lbfgs
    return solver


def on_host(en: FoldoverEnergy, st: State) -> bool:
    """Whether the kernels cannot solve this problem (rule 2, without the index check)."""
    return en.power != 1.0 or en.i0.size == 0 or st.nf == 0


def single_kernel_corners(is_cpu: bool) -> int:
    """The single-work-item kernel's share (rule 3): problems under this many corners."""
    return SMALL_CORNERS if is_cpu else 0


def route(en: FoldoverEnergy, st: State, small: int) -> Literal["host", "single", "parallel"]:
    """Where a device solver sends one problem, `small` its single-kernel share (rules 2, 3)."""
    if on_host(en, st):
        return "host"
    return "single" if en.i0.size < small else "parallel"
