"""Run the pipeline on a planar mesh that lives in 3D, writing results back in its plane."""

from __future__ import annotations

import numpy as np

from ..mesh.faces import as_faceset
from ..mesh.plane import PlaneFrame
from ..mesh.points import check_points
from ..mesh.topology import EdgeInfo, free_nodes
from ..metrics.reference_shapes import reference_to_2d
from ..params import EEGTParams
from .pipeline import EEGTResult, Progress, normalisation, untangle_and_smooth

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
    targets=None,
    reference_points=None,
) -> EEGTResult:
    """Like untangle_and_smooth for (N, 3) points on a plane; result points are (N, 3).

    Fixed nodes (boundary, non-manifold, ``fixed``) keep their input coordinates bit for
    bit, and so does every node whose 2D result equals its 2D input; when the result is not
    better than the input (``Stats.better_than``) no node moves. Moved nodes are placed on
    the fitted plane. With ``project`` the plane is the fixed nodes' (see
    ``PlaneFrame.fit``) and every free node ends on it: the optimised ones at their result,
    the others at their orthogonal projection. Like the 2D core, it works in centred
    coordinates scaled by a power of two, so units from 1e-300 to 1e300 give the same result.
    ``targets`` are per-corner 2D target shapes, passed through as they are (intrinsic 2D
    shapes, see untangle_and_smooth). ``reference_points`` (target "reference") may be (N, 3),
    a planar reference anywhere in space (taken in its own plane, faces counterclockwise;
    refused when not planar within ``tol``), or (N, 2).
    """
    original = check_points(points3d, 3)
    fs = as_faceset(faces, original.shape[0])
    # centred on the fixed nodes, which define the plane: a plane z = 0 stays exactly z = 0
    edges = EdgeInfo(fs, original.shape[0])  # one analysis for the rim, the plane and the run
    rim = fs.used_nodes(original.shape[0]) & ~free_nodes(original.shape[0], fs, fixed,
                                                         edges=edges)
    center, scale = normalisation(original, fs, centre_on=rim)
    work = (original - center) / scale
    frame = PlaneFrame.fit(work, faces, tol=tol, project=project, fixed=fixed, edges=edges)
    flat = frame.to_2d(work)
    if reference_points is not None and np.ndim(reference_points) == 2 and \
            np.shape(reference_points)[1] == 3:
        reference_points = reference_to_2d(reference_points, fs, original.shape[0], tol)
    res = untangle_and_smooth(flat, faces, fixed, params, backend, progress, targets,
                              reference_points, edges)
    out = original.copy()
    if res.status != "cancelled":
        moved = res.moved & np.any(res.points != flat, axis=1)
        if not res.after.better_than(res.before):
            moved[:] = False
            res.after = res.before
        out[moved] = frame.to_3d(res.points[moved]) * scale + center
        if project:
            rest = res.moved & ~moved
            # the foot in the caller's units: in-plane coordinates stay bit for bit
            off = frame.foot(work[rest]) - work[rest]
            out[rest] = original[rest] + off * scale
    res.points = out
    return res
