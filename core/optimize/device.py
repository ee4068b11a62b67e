"""Which L-BFGS runs the global stage: the host's NumPy solver or an OpenCL twin (same bits)."""

from __future__ import annotations

import warnings

from .options import Solver

__all__ = ["solver_for"]


def solver_for(backend_name: str) -> Solver | None:
    """The device solver when the run's engine is OpenCL and its device is a CPU (a single
    work-item kernel: `solver_opencl.device_solver` gives none elsewhere); None = NumPy.
    A kernel that does not build warns once and leaves NumPy, which gives the same result."""
    if not backend_name.startswith("opencl"):
        return None
    from .solver_opencl import device_solver

    try:
        return device_solver()
    except RuntimeError as exc:
        warnings.warn(f"{exc}; global stage on NumPy", RuntimeWarning, stacklevel=3)
        return None
