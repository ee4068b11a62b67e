"""Planar meshes in 3D (docs/method.md, section 5): fit the plane, map to 2D and back.

The plane normal is the mesh's vector area. Summed face by face, the interior edges cancel
(each is walked once in each direction), so it equals the Newell sum over the open (boundary
and non-manifold) edges alone; it is computed that way, so interior nodes, tangled or not,
do not enter it at all, not even through round-off. Projecting with that normal makes the
domain's total signed area positive, i.e. the faces' stored order the valid orientation.

Everything here is explicit elementwise arithmetic in a fixed order (no matrix product,
dot or norm routine): BLAS/LAPACK pick kernels per CPU, and the frame must be bit-identical
on every x86-64 machine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..fpmath import add_reduce
from .faces import FaceSet, as_faceset
from .points import check_points
from .topology import EdgeInfo, checked_edges, free_nodes

__all__ = ["PlaneFrame", "open_edges"]


def _dot3(q: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Row-wise q . w for (N, 3) q and one (3,) vector, in a fixed order (no BLAS)."""
    return q[:, 0] * w[0] + q[:, 1] * w[1] + q[:, 2] * w[2]


def _norm3(w: np.ndarray) -> float:
    """Euclidean length of one 3-vector, in a fixed order (no BLAS)."""
    x, y, z = float(w[0]), float(w[1]), float(w[2])
    return math.sqrt(x * x + y * y + z * z)


def open_edges(fs: FaceSet, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The edges whose directed uses do not cancel (boundary and non-manifold edges): their
    nodes lo < hi in ascending ``lo * n + hi`` order and their net count of lo -> hi walks
    (float64). Interior edges, walked once each way, are not in it."""
    return EdgeInfo(fs, n).open_edges()


def _vector_area(q: np.ndarray, edges: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """Vector area 0.5 * sum of net * (q_lo x q_hi) over the open edges, in their order:
    only boundary and non-manifold nodes enter."""
    e0, e1, w = edges
    c = np.cross(q[e0], q[e1])
    return np.array([0.5 * add_reduce(w * c[:, k]) for k in range(3)])


@dataclass(frozen=True)
class PlaneFrame:
    """An orthonormal frame (origin, u, v, normal) of a planar mesh's plane."""

    origin: np.ndarray  # (3,)
    u: np.ndarray  # (3,) in-plane axis
    v: np.ndarray  # (3,) in-plane axis, u x v = normal
    normal: np.ndarray  # (3,) unit normal
    max_offset: float  # largest distance of a used node from the plane
    fixed_offset: float = 0.0  # with project: largest distance of a fixed node from it
    size: float = 0.0  # diagonal of the used nodes' bounding box (the tolerance's scale)

    @classmethod
    def fit(cls, points3d, faces, used=None, tol: float = 1e-5, project: bool = False,
            fixed=None, edges: EdgeInfo | None = None) -> PlaneFrame:
        """Fit the plane; without ``project``, refuse (ValueError) a node farther than
        ``tol * size`` from it.

        Without ``project`` the plane goes through the centroid of the used nodes and every
        used node must lie within the tolerance (docs/method.md 5 and 7: a non-planar mesh is
        refused).

        With ``project`` (the user asked to flatten the mesh) nothing is refused for being
        off the plane, and the plane is the one the nodes that never move define: the fixed
        nodes (boundary and non-manifold nodes, plus ``fixed``, the caller's extra pins, the
        same meaning as in ``untangle_and_smooth``). Its origin is their centroid, its
        normal the vector area, which depends on the boundary only. A mesh engineer who
        projects a bulged or noisy interior expects it to land on the plane of its outline
        (which does not move), not on a plane shifted by the bulge, as the all-node
        centroid would be. A least-squares fit (smallest-variance direction) would need
        LAPACK's eigensolver, whose bits depend on the CPU; for the nearly planar outlines
        this option is meant for, the vector area gives the same plane to well within the
        tolerance and is exactly reproducible. Fixed nodes off that plane stay where they
        are (they never move, docs/method.md 4); ``fixed_offset`` says how far the farthest one is,
        for the caller to report.

        ``edges``: the faces' EdgeInfo when the caller has it (from a Blender mesh's edge
        table: ``EdgeInfo.from_table``); None: computed here.
        """
        p = check_points(points3d, 3)
        fs = as_faceset(faces, p.shape[0])
        edges = checked_edges(edges, fs, p.shape[0])
        used = fs.used_nodes(p.shape[0]) if used is None else np.asarray(used, dtype=bool)
        anchor = used
        if project:  # fixed: boundary, pins
            anchor = used & ~free_nodes(p.shape[0], fs, fixed, edges=edges)
            if not anchor.any():  # a closed surface pinned nowhere: fall back to all nodes
                anchor = used
        every = bool(anchor.all()) and p.flags.c_contiguous  # no copy: the same sum
        origin = (p if every else p[anchor]).mean(axis=0)
        q = p - origin
        area = _vector_area(q, edges.open_edges())
        norm = _norm3(area)
        all_used = bool(used.all())
        span = np.array([np.ptp(p[:, k] if all_used else p[used, k]) for k in range(3)])
        size = _norm3(span)
        if size == 0 or norm <= 1e-12 * size * size:
            raise ValueError("mesh has zero total area: cannot tell its plane or orientation")
        normal = area / norm
        helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
        u = np.cross(helper, normal)
        u = u / _norm3(u)
        v = np.cross(normal, u)
        offsets = np.abs(_dot3(q, normal))
        max_offset = float((offsets if all_used else offsets[used]).max())
        if anchor is used and all_used:
            worst = int(np.argmax(offsets))
        else:
            check = np.flatnonzero(anchor)
            worst = int(check[np.argmax(offsets[check])])
        if project:
            return cls(origin, u, v, normal, max_offset, float(offsets[worst]), size)
        if offsets[worst] > tol * size:
            raise ValueError(
                f"mesh is not planar: node {worst} is {offsets[worst]:.3g} from the best plane "
                f"(tolerance {tol * size:.3g}, {tol:g} of its size)"
            )
        return cls(origin, u, v, normal, max_offset, 0.0, size)

    def to_2d(self, points3d) -> np.ndarray:
        """(N, 2) in-plane coordinates: ((p - origin) . u, (p - origin) . v)."""
        q = np.asarray(points3d, dtype=np.float64) - self.origin
        return np.column_stack([_dot3(q, self.u), _dot3(q, self.v)])

    def to_3d(self, points2d) -> np.ndarray:
        """(N, 3) points of the plane: origin + x u + y v (each coordinate (o + x u) + y v)."""
        p = np.asarray(points2d, dtype=np.float64)
        out = np.empty((p.shape[0], 3))
        x, y = p[:, 0], p[:, 1]
        for k in range(3):
            out[:, k] = self.origin[k] + x * self.u[k]
            out[:, k] += y * self.v[k]
        return out

    def foot(self, points3d) -> np.ndarray:
        """(N, 3) orthogonal projections onto the plane: p - ((p - origin) . n) n.

        Same in-plane position as ``to_3d(to_2d(p))``, but a node already on the plane
        (offset exactly 0) comes back bit for bit.
        """
        p = np.asarray(points3d, dtype=np.float64)
        off = _dot3(p - self.origin, self.normal)
        return p - off[:, None] * self.normal
