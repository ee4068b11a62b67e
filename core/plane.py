"""Planar meshes in 3D (SPEC section 5): fit the plane, map to 2D and back.

The plane normal is the mesh's vector area (sum of face area vectors): interior tangling
cannot change it, since it is fixed by the boundary. Projecting with that normal makes the
domain's total signed area positive, i.e. the faces' stored order the valid orientation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .faces import as_faceset

__all__ = ["PlaneFrame"]


@dataclass(frozen=True)
class PlaneFrame:
    origin: np.ndarray  # (3,)
    u: np.ndarray  # (3,) in-plane axis
    v: np.ndarray  # (3,) in-plane axis, u x v = normal
    normal: np.ndarray  # (3,) unit normal
    max_offset: float  # largest distance of a used node from the plane

    @classmethod
    def fit(cls, points3d, faces, used=None, tol: float = 1e-5, project: bool = False):
        """Fit the plane; refuse (ValueError) nodes farther than tol * size unless `project`."""
        p = np.array(points3d, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"points must be an (N, 3) array, got shape {p.shape}")
        bad = ~np.isfinite(p).all(axis=1)
        if bad.any():
            raise ValueError(f"node {int(np.flatnonzero(bad)[0])} has a NaN or infinite coordinate")
        fs = as_faceset(faces, p.shape[0])
        used = fs.used_nodes(p.shape[0]) if used is None else np.asarray(used, dtype=bool)
        origin = p[used].mean(axis=0)
        q = p - origin
        area = np.zeros(3)
        for g in fs.groups:
            P = q[g.nodes]  # (n, F, 3)
            area += 0.5 * np.cross(P, np.roll(P, -1, axis=0)).sum(axis=(0, 1))
        norm = float(np.linalg.norm(area))
        size = float(np.linalg.norm(np.ptp(p[used], axis=0)))
        if size == 0 or norm <= 1e-12 * size * size:
            raise ValueError("mesh has zero total area: cannot tell its plane or orientation")
        normal = area / norm
        helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
        u = np.cross(helper, normal)
        u /= np.linalg.norm(u)
        v = np.cross(normal, u)
        offsets = np.abs(q[used] @ normal)
        worst = int(np.argmax(offsets))
        max_offset = float(offsets[worst])
        if max_offset > tol * size and not project:
            node = int(np.flatnonzero(used)[worst])
            raise ValueError(
                f"mesh is not planar: node {node} is {max_offset:.3g} from the best plane "
                f"(tolerance {tol * size:.3g}, {tol:g} of its size)"
            )
        return cls(origin, u, v, normal, max_offset)

    def to_2d(self, points3d) -> np.ndarray:
        q = np.asarray(points3d, dtype=np.float64) - self.origin
        return np.column_stack([q @ self.u, q @ self.v])

    def to_3d(self, points2d) -> np.ndarray:
        p = np.asarray(points2d, dtype=np.float64)
        return self.origin + p[:, :1] * self.u + p[:, 1:2] * self.v
