"""A whole run: Algorithm 1 (untangle, smooth, keep the best iterate) with the global
stage, on a plane in 2D or 3D, in one go or frame by frame under a cursor.

- 2D: `pipeline.untangle_and_smooth` -> `EEGTResult`; 3D (a planar mesh in space):
  `pipeline_3d.untangle_and_smooth_3d` (``stored=np.float32``: judged as Blender stores it).
- Algorithm 1's EEGT loops (untangle, then smooth, optionally under a deadline), shared by
  the whole run and live frames: `algorithm1.untangle_loop`, `smooth_loop`, `Deadline`.
- the acceptance rule ("no worse than the input", every path's one decision, with the
  storage type's ties): `acceptance.accept`, `tie_tolerance`.
- the harmonic start for large folds: `harmonic.harmonic_positions`.
- a repair (region "folds", target "keep"): the folded faces and a growing margin only,
  each face pulled towards its own shape: `repair.repair_folds`, `folded_faces`,
  `keep_targets`; hopeless folds held before the run: `hopeless`, `hopeless_groups`.
- live drags, a frame at a time: `live.LiveSession`, `LiveFrame`, the cursor's bound
  (`cursor_bounds`, `clamp_cursor`), what may be written (`storable_float32`); what a
  frame reuses from the last: `live_reuse`; how many frames run with the cursor still:
  `live_rest.RestFrames`.
"""

from .acceptance import FLOAT32_TIE, accept, tie_tolerance
from .harmonic import harmonic_positions
from .live import (
    FINISH_BUDGET,
    FINISH_GO_ON,
    FINISH_KEEP,
    FINISH_LIMIT,
    FINISH_RESTORE,
    FRAME_BUDGET,
    FRAME_ITERATIONS,
    LiveFrame,
    LiveSession,
    clamp_cursor,
    cursor_bounds,
    live_params,
    storable_float32,
    uv_region,
    uv_vertex_corners,
)
from .live_rest import SETTLE_FRAMES, UNTANGLE_FRAMES, RestFrames
from .pipeline import Cancelled, EEGTResult, frozen_note, untangle_and_smooth
from .pipeline_3d import untangle_and_smooth_3d
from .repair import folded_faces, keep_targets

__all__ = ["FINISH_BUDGET", "FINISH_GO_ON", "FINISH_KEEP", "FINISH_LIMIT", "FINISH_RESTORE",
           "FLOAT32_TIE", "FRAME_BUDGET", "FRAME_ITERATIONS", "SETTLE_FRAMES",
           "UNTANGLE_FRAMES", "Cancelled", "EEGTResult", "LiveFrame", "LiveSession",
           "RestFrames", "accept", "clamp_cursor", "cursor_bounds", "folded_faces",
           "frozen_note", "harmonic_positions", "keep_targets", "live_params",
           "storable_float32", "tie_tolerance", "untangle_and_smooth", "untangle_and_smooth_3d",
           "uv_region", "uv_vertex_corners"]
