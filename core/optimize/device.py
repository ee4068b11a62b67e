"""Which L-BFGS runs the global stage: the host's NumPy solver or an OpenCL twin (same bits)."""

from __future__ import annotations

import warnings

from ..backends import global_stage_on_device
from .options import Solver

__all__ = ["solver_for"]


def solver_for(backend_name: str) -> Solver | None:
    """The device solver when the run's engine is OpenCL (`solver_parallel.device_solver`:
    many work-items, and on a CPU device the single-work-item kernel for small problems);
    None = NumPy. Kernels that do not build warn once and leave NumPy, which gives the same
    result."""
    if not global_stage_on_device(backend_name):
        return None
    from .solver_parallel import device_solver

    try:
        return device_solver()
    except RuntimeError as exc:
        warnings.warn(f"{exc}; global stage on NumPy", RuntimeWarning, stacklevel=3)
        return None
