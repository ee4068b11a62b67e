"""Reference meshes as target shapes (`target="reference"`): each face is pulled towards its
own shape in a mesh of the same topology, e.g. the undeformed mesh of a mesh deformed by a
moving body, so that grading and anisotropy (boundary layers) survive the untangling.

The reference's per-corner points become the per-face targets of core.metrics.targets (only each
face's shape counts: a reference in other units, moved or turned, gives the same targets).
A reference face that is inverted, degenerate or not strictly convex falls back to the
regular polygon (`n_target_fallback`). A reference of the wrong size, with non-finite
coordinates, clockwise (negative total signed area) or of zero area is refused with a
one-line ValueError; in 3D, so is one that is not planar.
"""

from __future__ import annotations

import numpy as np

from ..fpmath import add_reduce, float64_copy
from ..mesh.faces import FaceSet, as_faceset
from ..mesh.plane import PlaneFrame

__all__ = ["reference_targets", "reference_to_2d"]


def _signed_area(p: np.ndarray, fs: FaceSet) -> float:
    total = 0.0
    for g in fs.groups:
        x, y = p[g.nodes, 0], p[g.nodes, 1]
        total += add_reduce(x * np.roll(y, -1, axis=0) - np.roll(x, -1, axis=0) * y)
    return 0.5 * total


def _unit_scaled(r: np.ndarray) -> np.ndarray:
    """r times the power of two that brings its largest |coordinate| into [0.5, 1) (exact;
    unchanged when all are 0)."""
    _, e = np.frexp(np.max(np.abs(r)))
    return np.ldexp(r, -e)


def _unit_centred(r: np.ndarray, used: np.ndarray) -> np.ndarray:
    """The used nodes (the others at 0) centred on their mean and scaled by a power of two
    to a largest |coordinate| in [0.5, 1): scaled first, so that the mean cannot overflow (a
    reference near 1e308), and again once centred, so that a small mesh far from the origin
    keeps its area clear of underflow. The sign of the total area is then right at any
    finite scale."""
    s = _unit_scaled(np.where(used[:, None], r, 0.0))
    s = s - s[used].mean(axis=0)
    return _unit_scaled(np.where(used[:, None], s, 0.0))


def _checked(reference_points, fs: FaceSet, n_nodes: int, width: int
             ) -> tuple[np.ndarray, np.ndarray]:
    """(the reference as a float64 (N, width) copy, the (N,) mask of nodes used by `fs`);
    ValueError (one line) unless it is that shape with finite used nodes."""
    if reference_points is None:
        raise ValueError("target 'reference' needs a reference mesh (reference_points: the "
                         "same mesh's vertices in their reference positions)")
    try:
        r = float64_copy(reference_points)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"reference_points must be an array of numbers ({exc})") from None
    if r.ndim != 2 or r.shape[1] != width:
        raise ValueError(f"reference_points must be an (N, {width}) array, got shape {r.shape}")
    if r.shape[0] != n_nodes:
        raise ValueError(f"reference mesh has {r.shape[0]} vertices, the mesh has {n_nodes} "
                         "(it must have the same topology)")
    used = fs.used_nodes(n_nodes)
    if not np.isfinite(r[used]).all():
        bad = int(np.count_nonzero(~np.isfinite(r[used]).all(axis=1)))
        raise ValueError(f"reference mesh has {bad} vertices with NaN or infinite coordinates")
    return r, used


def reference_targets(reference_points, faces, n_nodes: int) -> np.ndarray:
    """(n_corners, 2) targets: the reference's position of every face corner (the faces'
    corner order), from an (N, 2) reference with the faces counterclockwise."""
    fs = as_faceset(faces, n_nodes)
    r, used = _checked(reference_points, fs, n_nodes, 2)
    area = _signed_area(_unit_centred(r, used), fs)
    if area < 0.0:
        raise ValueError("reference mesh is clockwise (its total signed area is negative): "
                         "it must have the faces' orientation")
    if not area > 0.0:
        raise ValueError("reference mesh has zero total area")
    return r[fs.indices]


def reference_to_2d(reference3d, faces, n_nodes: int, tol: float = 1e-5) -> np.ndarray:
    """(N, 2) coordinates of an (N, 3) planar reference in its own plane, oriented so that
    its faces are counterclockwise (the plane's normal is its vector area); ValueError (one
    line) when it is not planar within `tol` of its size."""
    fs = as_faceset(faces, n_nodes)
    r, used = _checked(reference3d, fs, n_nodes, 3)
    # fitted at a largest |coordinate| in [0.5, 1) (a power of two: the same plane and bits,
    # but its sums and squares can neither overflow nor underflow), then scaled back
    _, e = np.frexp(np.max(np.abs(r[used])))
    unit = np.ldexp(np.where(used[:, None], r, 0.0), -e)
    try:
        frame = PlaneFrame.fit(unit, fs, tol=tol)
    except ValueError as exc:
        raise ValueError(f"reference {str(exc).splitlines()[0]}") from None
    return np.ldexp(frame.to_2d(unit), e)
