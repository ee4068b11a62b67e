"""Run the pipeline on a planar mesh that lives in 3D, writing results back in its plane."""

from __future__ import annotations

import numpy as np

from ..mesh.faces import FaceSet, as_faceset
from ..mesh.plane import PlaneFrame
from ..mesh.points import check_points
from ..mesh.topology import EdgeInfo, free_nodes
from ..metrics.face_quality import Stats, mesh_stats
from ..metrics.reference_shapes import reference_to_2d
from ..params import EEGTParams
from .acceptance import accept, tie_tolerance
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
    edges: EdgeInfo | None = None,
    stored: np.dtype | type = np.float64,
) -> EEGTResult:
    """Like untangle_and_smooth for (N, 3) points on a plane; result points are (N, 3).

    Fixed nodes (boundary, non-manifold, ``fixed``) keep their input coordinates bit for
    bit, and so does every node whose 2D result equals its 2D input; when the result is not
    accepted over the input (``core.run.accept``) no node moves. Moved nodes are placed on
    the fitted plane. With ``project`` the plane is the fixed nodes' (see
    ``PlaneFrame.fit``) and every free node ends on it: the optimised ones at their result,
    the others at their orthogonal projection. Like the 2D core, it works in centred
    coordinates scaled by a power of two, so units from 1e-300 to 1e300 give the same result.
    ``targets`` are per-corner 2D target shapes, passed through as they are (intrinsic 2D
    shapes, see untangle_and_smooth). ``reference_points`` (target "reference") may be (N, 3),
    a planar reference anywhere in space (taken in its own plane, faces counterclockwise;
    refused when not planar within ``tol``), or (N, 2). ``edges``: the faces' edge analysis
    when the caller has it (as in untangle_and_smooth).

    ``stored``: the type the caller keeps positions in. float64: the points as computed.
    float32 (Blender's vertex positions): the points are returned rounded to float32 (an
    (N, 3) float32 array; the input should hold float32 values) and judged as rounded: the
    stats of the rounded copy in the plane (``after``) must be accepted over the input's
    with float32 ties (``accept(before, after, np.float32)``), else only the projection of
    ``project`` is returned (or the input) and the status says so.
    """
    tie_tolerance(stored)  # float64 or float32, checked before the run
    original = check_points(points3d, 3)
    fs = as_faceset(faces, original.shape[0])
    # centred on the fixed nodes, which define the plane: a plane z = 0 stays exactly z = 0
    if edges is None:  # one analysis for the rim, the plane and the run
        edges = EdgeInfo(fs, original.shape[0])
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
        if not accept(res.before, res.after):
            moved[:] = False
            res.after = res.before
        place = _Placing(original, work, res, frame, center, scale, project)
        out = place(moved)
        if np.dtype(stored) != np.float64:
            out = _stored_float32(res, out, place, moved, fs, res.targets)
    if np.dtype(stored) != np.float64 and out.dtype != np.float32:
        out = out.astype(np.float32)
    res.points = out
    return res


class _Placing:
    """The 3D points of a run's result: the nodes of a mask at their 2D result on the plane,
    with ``project`` the other free nodes at their foot on it, the rest as given."""

    def __init__(self, original: np.ndarray, work: np.ndarray, res: EEGTResult,
                 frame: PlaneFrame, center: np.ndarray, scale: float, project: bool):
        self.original, self.work, self.res, self.frame = original, work, res, frame
        self.center, self.scale, self.project = center, scale, project

    def __call__(self, moved: np.ndarray) -> np.ndarray:
        """(N, 3) float64: ``moved`` nodes at the result, the projection, the rest as given."""
        out = self.original.copy()
        res, frame = self.res, self.frame
        out[moved] = frame.to_3d(res.points[moved]) * self.scale + self.center
        if self.project:
            rest = res.moved & ~moved
            # the foot in the caller's units: in-plane coordinates stay bit for bit
            off = frame.foot(self.work[rest]) - self.work[rest]
            out[rest] = self.original[rest] + off * self.scale
        return out

    def stats(self, points: np.ndarray, fs: FaceSet, targets) -> Stats:
        """The stats of (N, 3) ``points`` in the plane, measured as the input's are (the
        run's corners kept as given left out)."""
        flat = self.frame.to_2d((points.astype(np.float64) - self.center) / self.scale)
        return mesh_stats(flat, fs, targets, self.res.kept)


def _stored_float32(res: EEGTResult, out: np.ndarray, place: _Placing, moved: np.ndarray,
                    fs: FaceSet, targets) -> np.ndarray:
    """The result rounded to float32 when its rounded copy is accepted over the input
    (``res.after``: its stats), else the input with only the projection of ``project`` (its
    stats), the status and message saying so."""
    given = place.original.astype(np.float32)
    rounded = out.astype(np.float32)
    if moved.any() and np.any(rounded != given):
        after = place.stats(rounded, fs, targets)
        if accept(res.before, after, np.float32):
            res.after = after
            _claim_no_more(res)
            return rounded
        _refused(res)
    if not place.project:
        return given
    projected = place(np.zeros_like(moved)).astype(np.float32)
    if np.any(projected != given):
        res.after = place.stats(projected, fs, targets)
        _claim_no_more(res)
    return projected


def _refused(res: EEGTResult) -> None:
    """The input kept: ``after`` is ``before``, the status and message say why."""
    note = "the result was not better than the input once stored as float32: input kept"
    res.after = res.before
    if res.status == "failed":
        res.message += f"; {note}"
    elif res.before.n_inverted:
        res.status = "failed"
        res.message = (f"failed: {note} with {res.before.n_inverted} inverted faces; the run: "
                       f"{res.message}")
    else:
        res.status = "valid"
        res.message += f"; {note}"


def _claim_no_more(res: EEGTResult) -> None:
    """A run whose stored points have an inverted face is 'failed' (never claims more)."""
    if res.after.n_inverted and res.status != "failed":
        res.status = "failed"
        res.message = (f"failed: {res.after.n_inverted} faces are inverted once stored as "
                       f"float32; the run: {res.message}")
