"""Backend choice: 'numpy' (reference), 'opencl', or 'auto' (OpenCL where it is faster).

'auto' on a mesh under AUTO_ENGINE_MIN_FACES faces keeps the EEGT steps on the NumPy engine
(the OpenCL engine's set-up costs more than the few steps it would speed up) and runs only
the global stage on the device: the result is bit-identical either way.
"""

from __future__ import annotations

import threading

import numpy as np

from ..choices import (
    BACKEND,
    HYBRID,
    NUMPY_ENGINE,
    SMALL_ON_GPU,
    ids,
)
from ..mesh.faces import FaceSet
from ..metrics.targets import Targets
from ..params import EEGTParams
from .boundary import BoundaryMotion
from .engine import Engine, EngineInput
from .engine_numpy import NumpyEngine

__all__ = ["AUTO_ENGINE_MIN_FACES", "BACKENDS", "HYBRID", "SMALL_ON_GPU", "make_engine",
           "start_warm_up", "uses_device_engine", "warm_up"]

BACKENDS = ids(BACKEND)
AUTO_ENGINE_MIN_FACES = 4000  # 'auto': the OpenCL engine from this many faces on
_warned: set[str] = set()


def _opencl_engine_class():
    """The OpenCL engine class, or a one-line reason why it cannot be used."""
    try:
        from . import engine_opencl
    except ImportError as exc:  # the backend module or pyopencl is missing
        return None, f"OpenCL backend unavailable ({exc}); using NumPy"
    return engine_opencl.available()


def _device_is_cpu() -> bool:
    """Whether the OpenCL device runs would use is a CPU (pocl and the like)."""
    from ..opencl.runtime import runtime

    return runtime().is_cpu


def warm_up(backend: str, max_face_size: int = 4) -> str | None:
    """Get the OpenCL device of `backend` ready before a run: its context, the EEGT kernels
    for faces of up to `max_face_size` corners and the global stage's solver, made now
    instead of inside the next run (made once per process either way). A caller may run
    this in a thread while it reads its input; a run that asks for the device meanwhile
    waits for it. Nothing to do for 'numpy'. Never raises: returns why the device is not
    ready (the run then reports it as usual), or None."""
    if backend not in ("opencl", "auto"):
        return None
    cls, why = _opencl_engine_class()
    if cls is None:
        return why
    try:
        from ..opencl.runtime import runtime
        from ..optimize.solver_parallel import device_solver
        from . import engine_opencl

        rt = runtime()
        rt.program(engine_opencl.program_size(max_face_size))
        device_solver()
    except Exception as exc:  # the run meets the same failure and reports it
        return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return None


def uses_device_engine(backend: str, n_faces: int) -> bool:
    """Whether a run of `backend` on `n_faces` faces asks for the OpenCL engine (it gets the
    NumPy engine anyway when there is no device)."""
    return backend == "opencl" or (backend == "auto" and n_faces >= AUTO_ENGINE_MIN_FACES)


def start_warm_up(backend: str, n_faces: int) -> threading.Thread | None:
    """`warm_up` in a thread for a run that will ask for the OpenCL engine, so that the
    device gets ready while the run checks and renumbers its input (a run that reaches the
    device first waits for it); None when the run would not use the engine."""
    if not uses_device_engine(backend, n_faces):
        return None
    thread = threading.Thread(target=warm_up, args=(backend,), name="eegt-warm-up")
    thread.start()
    return thread


def make_engine(
    backend: str,
    points: np.ndarray,
    faces: FaceSet,
    free: np.ndarray,
    params: EEGTParams,
    targets: Targets | None = None,
    motion: BoundaryMotion | None = None,
) -> tuple[Engine, str]:
    """Build the engine for `backend`; returns (engine, name actually used). The arguments
    are an `EngineInput`'s (core/eegt/engine.py)."""
    setup = EngineInput(points, faces, free, params, targets, motion)
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r} (choose from {', '.join(BACKENDS)})")
    if backend in ("opencl", "auto"):
        cls, why = _opencl_engine_class()
        if cls is not None and (not uses_device_engine(backend, faces.n_faces)
                                or not np.any(free)):
            # the global stage's device solver runs on CPU devices only (one work-item);
            # with every node held (a hopeless part) the device has nothing to move
            name = HYBRID if _device_is_cpu() else SMALL_ON_GPU
            return NumpyEngine(*setup), name
        if cls is not None:
            try:
                return cls(*setup), cls.name
            except RuntimeError as exc:  # device refused the kernels: fall back, say why
                why = f"OpenCL backend failed ({exc}); using NumPy"
        name = NUMPY_ENGINE
        if why and why not in _warned:
            _warned.add(why)
            import warnings

            warnings.warn(why, RuntimeWarning, stacklevel=3)
        engine = NumpyEngine(*setup)
        return engine, f"{name} ({why})" if why else name
    return NumpyEngine(*setup), NUMPY_ENGINE
