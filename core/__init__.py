"""EEGT core: untangle and smooth planar polygon meshes (NumPy; never imports bpy).

from core import untangle_and_smooth, quality, EEGTParams
res = untangle_and_smooth(points, faces, fixed=None, params=None, backend="numpy")
quality(points, faces, measure="min_angle"); summaries(points, faces)  # docs/measures.md

Where each piece lives: NumPy (the reference) first, then its OpenCL twin (the same bits on
a CPU device; a kernel or function of `opencl/eegt_kernels.cl` unless another file is named).
The method is docs/method.md, the backends' contract docs/opencl.md.

- the run (Algorithm 1: untangle, smooth, keep the best iterate): `pipeline.untangle_and_smooth`;
  engine choice `backends.make_engine`; a plane in 3D `pipeline_3d.untangle_and_smooth_3d`
  (the plane itself: `plane.PlaneFrame`).
- one EEGT iteration: `engine_numpy.NumpyEngine.step`; `engine_opencl.OpenCLEngine.step`.
  - stretch n_k: `transform._stretch`; `stretch_vector`, `TRI_PAPER_STRETCH`.
  - stretch and shrink (p^s - p per corner): `transform.group_transform_delta`;
    `transform_moves`, `MOVE_TRI_KERNEL_X`.
  - step size lambda = a (1 - q) (eq. 17): `engine_numpy.step_size`; `step_size`.
  - distance weight f(d) = (lbar / d)^c (eq. 20): `engine_numpy.distance_weight`;
    `distance_weight`. d: `distance.NearestBoundary`; `nearest_d`.
  - quality weight g(q) = (1 - q)^eta, 5 for an inverted element (eq. 21):
    `engine_numpy.quality_weight`; `quality_weight`.
  - element weight w = f g: `NumpyEngine._node_moves`; `FACE_WEIGHT` (the `move_*` kernels).
  - stitching (eq. 18): `engine_numpy.stitch`; the `stitch` kernel.
  - smoothing's step back from new inverted elements: `NumpyEngine._revert_inverted`;
    `mark_*`, `revert`.
- quality (the mean ratio, docs/method.md 3): `mean_ratio.group_quality` (per arity group),
  `quality.quality`, `quality.stats_of`; `mean_ratio`, the `quality_*` kernels (q_avg in
  NumPy's order: `engine_opencl._SumPlan`). Input points: `points.check_points`.
- boundary (which nodes move; modes fixed, slide, free): `topology.free_nodes`,
  `boundary.boundary_motion`, sliding `boundary.Slide.project`; `slide_project`.
- targets (per-face target shapes, docs/targets.md): `targets.prepare_targets`,
  `reference_shapes.reference_targets`, `transform._target_stretch`, `mean_ratio`'s
  per-corner factors; the `*_tgt*` kernels, `target_ratio`, `TRI_TARGET_STRETCH`.
- global stage (L-BFGS untangling, polish, lift; beyond the paper): `optimize/`, mapped in
  `core/optimize/__init__.py`.
- UV maps: `uv_layout` (welding, islands), `uv_overlap`, `uv_untangle.untangle_uv` (NumPy;
  the pipeline per island).
- measures (min angle, skewness, ...; docs/measures.md): `measures` (NumPy only).
- the OpenCL runtime (`opencl/`, mapped in `core/opencl/__init__.py`): device choice,
  context and program cache `opencl.runtime`; sources and build options `opencl.build`.
- NumPy's bits on a device: `fpmath` (log, exp, power from basic operations; NumPy's
  summation cut points); the kernels get its constants and every other shared constant as
  `-D` build defines (`opencl.build.cl_defines`, `opencl.build.fpmath_options`).
- mesh model: `faces.FaceSet` (faces by arity), `topology.EdgeInfo`, `csr`, `reorder`;
  OBJ files `obj_io`.
"""

from .faces import FaceSet, as_faceset, faces_from_csr
from .measures import MEASURE_NAMES, MEASURES, Measure, MeasureSummary, summaries, summarize
from .page_advice import prefer_ordinary_pages
from .params import EEGTParams
from .pipeline import Cancelled, EEGTResult, free_nodes, untangle_and_smooth
from .pipeline_3d import untangle_and_smooth_3d
from .plane import PlaneFrame
from .quality import Stats, mesh_stats, quality
from .topology import boundary_nodes

__version__ = "0.1.0"

prefer_ordinary_pages()  # before any mesh array exists (core/page_advice.py)

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
