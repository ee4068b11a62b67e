"""Target shapes for UV faces: each face's own 3D shape, flattened in its own plane.

A UV face is undistorted when it is similar to its 3D face. The 3D face is measured in its
plane: the Newell normal (its vector area, well defined for non-planar n-gons too) and an
orthonormal frame (u along the first edge, v = normal x u). Its corners, in their stored
order, are then counterclockwise in (u, v), as the faces of a counterclockwise (or
un-mirrored) UV island are: the target needs no flip for any island once mirrored islands
are reflected. Faces with no usable plane (zero vector area or a zero first edge) get NaN
rows, which the core treats as "use the regular polygon".
"""

from __future__ import annotations

import numpy as np

from .faces import FaceSet

__all__ = ["face_shapes_2d"]


def face_shapes_2d(points3d: np.ndarray, fs: FaceSet) -> np.ndarray:
    """(C, 2) in-plane coordinates of every face corner, in ``fs``'s corner order (the
    ``targets`` layout of ``untangle_and_smooth``); NaN rows for faces without a plane."""
    p = np.asarray(points3d, dtype=np.float64)
    out = np.full((fs.n_corners, 2), np.nan)
    for g in fs.groups:
        c = p[g.nodes]  # (n, F, 3)
        nxt = np.roll(c, -1, axis=0)
        normal = np.cross(c, nxt).sum(axis=0)  # Newell: twice the vector area, (F, 3)
        centre = c.mean(axis=0)
        e = c[1] - c[0]
        e = e - (e * normal).sum(axis=1, keepdims=True) * normal / np.maximum(
            (normal * normal).sum(axis=1, keepdims=True), np.finfo(float).tiny)
        nn = np.sqrt((normal * normal).sum(axis=1))
        ne = np.sqrt((e * e).sum(axis=1))
        ok = (nn > 0) & (ne > 0) & np.isfinite(nn) & np.isfinite(ne)
        with np.errstate(invalid="ignore", divide="ignore"):
            u = e / ne[:, None]
            v = np.cross(normal / nn[:, None], u)
        d = c - centre  # (n, F, 3)
        xy = np.stack([(d * u).sum(axis=2), (d * v).sum(axis=2)], axis=2)  # (n, F, 2)
        xy[:, ~ok] = np.nan
        rows = fs.offsets[g.ids][None, :] + np.arange(g.n)[:, None]  # (n, F)
        out[rows.ravel()] = xy.reshape(-1, 2)
    return out
