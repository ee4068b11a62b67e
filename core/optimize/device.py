"""Which L-BFGS runs the global stage: the host's NumPy solver or an OpenCL twin (same bits)."""

from __future__ import annotations

import warnings

from .dispatch import Solver, uses_device

__all__ = ["solver_for"]


def solver_for(backend_name: str, sliding: bool = False) -> Solver | None:
    """The device solver when the run's global stage may use one (`dispatch.uses_device`:
    an OpenCL engine, no sliding nodes), made by `solver_parallel.device_solver`; None =
    NumPy. Kernels that do not build warn once and leave NumPy, which gives the same
    result."""
    if not uses_device(backend_name, sliding):
        return None
    from .solver_parallel import device_solver

    try:
        return device_solver()
    except RuntimeError as exc:
        warnings.warn(f"{exc}; global stage on NumPy", RuntimeWarning, stacklevel=3)
        return None
