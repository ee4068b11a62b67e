"""EEGT core: untangle and smooth planar polygon meshes (NumPy; never imports bpy).

from core import untangle_and_smooth, quality, EEGTParams
res = untangle_and_smooth(points, faces, fixed=None, params=None, backend="numpy")
quality(points, faces, measure="min_angle"); summaries(points, faces)  # docs/measures.md

This file is the public face; callers outside core import from it or from one room's face
(`core.mesh`, `core.metrics`, `core.eegt`, `core.run`, `core.uv`), never from a module
inside a room. Importing core changes nothing in the process: the run's process settings
(page advice, freed memory) are made when a run starts (`host`).

The rooms, each mapped in its own `__init__.py`; a room imports only the rooms above it:
- `params`, `choices`, `fpmath` (top): the parameters and their bounds, every choice list,
  NumPy's bits from basic operations (log, exp, power, summation order) for the kernels.
- `mesh/`: faces by arity, edges, boundary and free nodes, renumbering, the plane of a 3D
  mesh, input checks, OBJ files.
- `metrics/`: the mean ratio quality, the other measures, target shapes (docs/targets.md).
- `eegt/`: one EEGT iteration and its engines (the `Engine` interface, NumPy and OpenCL),
  the element transform, distances, boundary modes.
- `optimize/`: the global stage (L-BFGS untangling, polish, lift; beyond the paper).
- `run/`: Algorithm 1 in 2D and 3D, the acceptance rule ("no worse than the input"),
  the harmonic start, live frames.
- `uv/`: UV layouts, overlaps, the run per island.
- `host/`: process settings while a run works; `opencl/`: the OpenCL runtime and kernels.

Where each step of the method lives: NumPy (the reference) first, then its OpenCL twin (the
same bits on a CPU device; a kernel or function of `opencl/eegt_kernels.cl` unless another
file is named). The method is docs/method.md, the backends' contract docs/opencl.md.

- the run (Algorithm 1: untangle, smooth, keep the best iterate):
  `run.pipeline.untangle_and_smooth`; engine choice `eegt.backends.make_engine`; a plane in
  3D `run.pipeline_3d.untangle_and_smooth_3d` (the plane itself: `mesh.plane.PlaneFrame`);
  the EEGT loops and their stop rule, shared with live frames: `run.algorithm1`; "no worse
  than the input", the one rule of every path: `run.acceptance.accept`.
- one EEGT iteration: `eegt.engine_numpy.NumpyEngine.step`;
  `eegt.engine_opencl.OpenCLEngine.step`.
  - stretch n_k: `eegt.transform._stretch`; `stretch_vector`, `TRI_PAPER_STRETCH`.
  - stretch and shrink (p^s - p per corner): `eegt.transform.group_transform_delta`;
    `transform_moves`, `MOVE_TRI_KERNEL_X`.
  - step size lambda = a (1 - q) (eq. 17): `eegt.engine_numpy.step_size`; `step_size`.
  - distance weight f(d) = (lbar / d)^c (eq. 20): `eegt.engine_numpy.distance_weight`;
    `distance_weight`. d: `eegt.distance.NearestBoundary`; `nearest_d`.
  - quality weight g(q) = (1 - q)^eta, 5 for an inverted element (eq. 21):
    `eegt.engine_numpy.quality_weight`; `quality_weight`.
  - element weight w = f g: `NumpyEngine._node_moves`; `FACE_WEIGHT` (the `move_*` kernels).
  - stitching (eq. 18): `eegt.engine_numpy.stitch`; the `stitch` kernel.
  - smoothing's step back from new inverted elements: `NumpyEngine._revert_inverted`;
    `mark_*`, `revert`.
- quality (the mean ratio, docs/method.md 3): `metrics.mean_ratio.group_quality` (per arity
  group), `metrics.face_quality.quality`, `stats_of`; `mean_ratio`, the `quality_*` kernels
  (q_avg in NumPy's order: `eegt.engine_opencl._SumPlan`). Input points:
  `mesh.points.check_points`.
- boundary (which nodes move; modes fixed, slide, free): `mesh.topology.free_nodes`,
  `eegt.boundary.boundary_motion`, sliding `eegt.boundary.Slide.project`; `slide_project`.
- targets (per-face target shapes): `metrics.targets.prepare_targets`,
  `metrics.reference_shapes.reference_targets`, `eegt.transform._target_stretch`,
  `mean_ratio`'s per-corner factors; the `*_tgt*` kernels, `target_ratio`,
  `TRI_TARGET_STRETCH`.
- global stage: `optimize/`, mapped in `core/optimize/__init__.py`.
- UV maps: `uv.uv_layout` (welding, islands), `uv.uv_overlap`, `uv.uv_untangle.untangle_uv`
  (NumPy; the pipeline per island).
- measures (min angle, skewness, ...; docs/measures.md): `metrics.measures` (NumPy only).
- the OpenCL runtime (`opencl/`, mapped in `core/opencl/__init__.py`): device choice,
  context and program cache `opencl.runtime`; sources and build options `opencl.build`;
  NumPy's constants as `-D` build defines (`opencl.build.cl_defines`, `fpmath_options`).
"""

from .mesh import FaceSet, PlaneFrame, as_faceset, boundary_nodes, faces_from_csr, free_nodes
from .metrics import (
    MEASURE_NAMES,
    MEASURES,
    Measure,
    MeasureSummary,
    Stats,
    mesh_stats,
    quality,
    summaries,
    summarize,
)
from .params import EEGTParams
from .run import Cancelled, EEGTResult, untangle_and_smooth, untangle_and_smooth_3d

__version__ = "0.1.0"

__all__ = [
    "MEASURES",
    "MEASURE_NAMES",
    "Cancelled",
    "EEGTParams",
    "EEGTResult",
    "FaceSet",
    "Measure",
    "MeasureSummary",
    "PlaneFrame",
    "Stats",
    "as_faceset",
    "boundary_nodes",
    "faces_from_csr",
    "free_nodes",
    "mesh_stats",
    "quality",
    "summaries",
    "summarize",
    "untangle_and_smooth",
    "untangle_and_smooth_3d",
]
