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

    Fixed nodes (boundary, non-manifold, ``fixed``) keep their input coordinates bit for
    bit, and so does every node whose 2D result equals its 2D input; when the result is not
    better than the input (``Stats.better_than``) no node moves. Moved nodes are placed on
    the fitted plane. With ``project`` the plane is the fixed nodes' (see
    ``PlaneFrame.fit``) and every free node ends on it: the optimised ones at their result,
    the others at their orthogonal projection.
    """
    original = np.array(points3d, dtype=np.float64)
    frame = PlaneFrame.fit(original, faces, tol=tol, project=project, fixed=fixed)
    flat = frame.to_2d(original)
    res = untangle_and_smooth(flat, faces, fixed, params, backend, progress)
    out = original.copy()
    if res.status != "cancelled":
        moved = res.moved & np.any(res.points != flat, axis=1)
        if not res.after.better_than(res.before):
            moved[:] = False
            res.after = res.before
        out[moved] = frame.to_3d(res.points[moved])
        if project:
            rest = res.moved & ~moved
            out[rest] = frame.foot(original[rest])
    res.points = out
    return res
