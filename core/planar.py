"""Run the pipeline on a planar mesh that lives in 3D, writing results back in its plane."""

from __future__ import annotations

import numpy as np

from .params import EEGTParams
from .pipeline import EEGTResult, Progress, untangle_and_smooth
from .plane import PlaneFrame

__all__ = ["untangle_and_smooth_3d"]


def untangle_and_smooth_3d(
    points3d,
    faces,
    fixed=None,
    params: EEGTParams | None = None,
    backend: str = "numpy",
    progress: Progress | None = None,
    tol: float = 1e-5,
    project: bool = False,
) -> EEGTResult:
    """Like untangle_and_smooth for (N, 3) points on a plane; result points are (N, 3).

    Nodes that did not move keep their input coordinates bit for bit; moved nodes are
    placed on the fitted plane.
    """
    original = np.array(points3d, dtype=np.float64)
    frame = PlaneFrame.fit(original, faces, tol=tol, project=project)
    res = untangle_and_smooth(frame.to_2d(original), faces, fixed, params, backend, progress)
    out = original.copy()
    if res.status != "cancelled":
        moved = res.moved & np.any(res.points != frame.to_2d(original), axis=1)
        out[moved] = frame.to_3d(res.points[moved])
    res.points = out
    return res
