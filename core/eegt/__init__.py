"""The EEGT iteration (the paper's local moves) and the engines that run it.

An engine runs the iteration on one mesh: `Engine` (engine.py) is the interface every
engine follows, `backends.make_engine` picks one by name ("numpy", "opencl", "auto").
- NumPy, the reference: `engine_numpy.NumpyEngine`; its per-element terms (`step_size`,
  `distance_weight`, `quality_weight`, `stitch`).
- OpenCL, the same bits on a device: `engine_opencl.OpenCLEngine` (imported on demand, so
  this room needs no OpenCL).
- the element transformation (stretch and shrink): `transform`; the distance to the
  nearest fixed node: `distance.NearestBoundary`; which nodes move and how (fixed, slide,
  free): `boundary.boundary_motion`, `BoundaryMotion`.
"""

from .backends import BACKENDS, make_engine, start_warm_up, uses_device_engine, warm_up
from .boundary import BoundaryMotion, boundary_motion
from .distance import NearestBoundary
from .engine import Engine
from .engine_numpy import NumpyEngine

__all__ = ["BACKENDS", "BoundaryMotion", "Engine", "NearestBoundary", "NumpyEngine",
           "boundary_motion", "make_engine", "start_warm_up", "uses_device_engine", "warm_up"]
