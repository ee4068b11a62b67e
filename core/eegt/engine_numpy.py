"""The NumPy backend: one EEGT iteration over all elements at once (the reference engine).

State is structure-of-arrays (x, y float64 node coordinates); faces are grouped by arity and
each group's corner coordinates are gathered as (n, F) arrays. Stitching scatters the
weighted corner moves to nodes with `np.bincount` over one precomputed corner->node array.
Every update is a Jacobi update: all moves are computed from the old positions, then applied.
"""

from __future__ import annotations

import numpy as np

from ..choices import NUMPY_ENGINE
from ..fpmath import add_reduce, power
from ..mesh.csr import bincount_csr, ragged_arange
from ..mesh.faces import FaceSet
from ..metrics.face_quality import Stats, stats_of
from ..metrics.mean_ratio import group_quality
from ..metrics.targets import Targets
from ..params import EEGTParams
from .boundary import BoundaryMotion
from .distance import NearestBoundary
from .transform import edge_sum, group_transform_delta

__all__ = ["DIST_FLOOR", "NumpyEngine", "distance_weight", "quality_weight", "step_size", "stitch"]

DIST_FLOOR = 1e-3  # d_j never below this fraction of the mean edge length
_DIRECT_PAIRS = 1 << 14  # centroid/fixed-node pairs up to which distances skip the quadtree


# -- the paper's terms (twins in opencl/eegt_kernels.cl under the same names) ---------------
def step_size(q: np.ndarray, a: float) -> np.ndarray:
    """lambda = a (1 - q) per element (paper eq. 17): a good element moves little."""
    return a * (1.0 - q)


def distance_weight(d: np.ndarray, lbar: float, c: float) -> np.ndarray:
    """The distance weight f(d) = (lbar / d)^c (paper eq. 20): elements near the fixed
    boundary pull harder. d is clamped to DIST_FLOOR lbar, so a centroid on a fixed node
    weighs a finite amount."""
    return power(lbar / np.maximum(d, DIST_FLOOR * lbar), c)


def quality_weight(q: np.ndarray, eta: float, inverted_weight: float) -> np.ndarray:
    """The quality weight g(q) = (1 - q)^eta, `inverted_weight` (the paper's 5) for an
    inverted element, q = 0 (paper eq. 21): bad elements pull harder. q may round to
    1 + 1 ulp on a regular face, so 1 - q is clamped at 0 (a negative base gives NaN for
    eta not an integer)."""
    return np.where(q > 0, power(np.maximum(1.0 - q, 0.0), eta), inverted_weight)


def stitch(
    corner_nodes: np.ndarray,
    wdx: np.ndarray,
    wdy: np.ndarray,
    w: np.ndarray,
    free: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The stitching (paper eq. 18): every free node moves by the weighted mean
    sum_j w_j d_j / sum_j w_j of its corners' moves d_j (`wdx`, `wdy`: w_j d_j, `w`: w_j, one
    per corner, the corners' nodes in `corner_nodes`); a node whose weights sum to 0 stays.
    np.bincount adds each node's corners in corner order (the OpenCL gather's order)."""
    n = free.size
    sx = np.bincount(corner_nodes, wdx, minlength=n)
    sy = np.bincount(corner_nodes, wdy, minlength=n)
    sw = np.bincount(corner_nodes, w, minlength=n)
    moving = free & (sw > 0)
    dx = np.zeros(n)
    dy = np.zeros(n)
    np.divide(sx, sw, out=dx, where=moving)
    np.divide(sy, sw, out=dy, where=moving)
    return dx, dy


def edge_lengths(x: np.ndarray, y: np.ndarray, groups) -> tuple[float, float]:
    """(lbar, smallest element mean edge length > 0) of the positions (x, y): lbar is the
    mean over all elements of their mean edge length (the span when that is not positive)."""
    m = np.concatenate([edge_sum(x[g.nodes], y[g.nodes]) / g.n for g in groups])
    lbar = add_reduce(m) / m.size
    positive = m[m > 0]
    span = float(max(np.ptp(x), np.ptp(y))) or 1.0
    if not np.isfinite(lbar) or lbar <= 0:
        lbar = span
    return lbar, float(positive.min()) if positive.size else span


class _FixedNodeDistance:
    """Distance from element centroids to the nearest fixed node: over all pairs while they
    are few (small meshes), else by the `NearestBoundary` quadtree, built on first use and
    refined for the first centroids seen. Both give the exact minimum of the same
    (bx - qx)^2 + (by - qy)^2, so the result does not depend on which one answers."""

    def __init__(self, bx: np.ndarray, by: np.ndarray, hint_x, hint_y, min_cell: float):
        if bx.size == 0:
            raise ValueError("no boundary nodes to measure distances to")
        self.bx, self.by = bx, by
        self._hints = (hint_x, hint_y, min_cell)
        self._tree: NearestBoundary | None = None

    @property
    def tree(self) -> NearestBoundary:
        if self._tree is None:
            hx, hy, min_cell = self._hints
            self._tree = NearestBoundary(self.bx, self.by, hx, hy, min_cell=min_cell)
        return self._tree

    def query(self, qx: np.ndarray, qy: np.ndarray) -> np.ndarray:
        if self.bx.size * qx.size > _DIRECT_PAIRS:
            return self.tree.query(qx, qy)
        dx = self.bx[:, None] - qx[None, :]  # (fixed node, query)
        dy = self.by[:, None] - qy[None, :]
        dx *= dx
        dy *= dy
        dx += dy
        return np.sqrt(np.minimum.reduce(dx, axis=0))


_UNIFORM = object()  # distance weights without anchors: f = 1 for every element


class NumpyEngine:
    """Holds the mesh state of one run (an `Engine`, core/eegt/engine.py); the pipeline drives
    it iteration by iteration."""

    name = NUMPY_ENGINE

    def __init__(
        self,
        points: np.ndarray,
        faces: FaceSet,
        free: np.ndarray,
        params: EEGTParams,
        targets: Targets | None = None,
        motion: BoundaryMotion | None = None,
    ):
        """The arguments are an `EngineInput`'s (core/eegt/engine.py)."""
        self._setup(points, faces, free, params, None, targets, motion)

    def restarted(self, points: np.ndarray, distance=None,
                  keep_quality: bool = False) -> NumpyEngine:
        """A fresh engine for the same run at new positions whose fixed nodes are where they
        are here: it shares the nearest-boundary search (its queries are exact, whatever
        element centroids it was refined for) instead of building another one. `distance`:
        a search over the fixed nodes at their new positions when some moved (an object whose
        `query(qx, qy)` returns the exact nearest distances, core.run.live). `keep_quality`:
        faces whose nodes all keep this engine's bits keep their quality (a face's quality
        depends on its own corners only: the same bits), the others are measured."""
        engine = NumpyEngine.__new__(NumpyEngine)
        known = (self.x, self.y, self.q) if keep_quality else None
        engine._setup(points, self.faces, self.free, self.params, distance or self._distance,
                      self.targets, self.motion, defer_distances=True,  # may never be stepped
                      known=known)
        engine._node_corners = self._node_corners  # the same faces
        return engine

    @classmethod
    def initial_state(cls, points: np.ndarray, faces: FaceSet, free: np.ndarray,
                      params: EEGTParams, targets: Targets | None = None,
                      motion: BoundaryMotion | None = None) -> NumpyEngine:
        """The state at `points` (lbar, quadtree, q) with the distance weights left to the
        first step (`inv_d_pow` None): the OpenCL engine's initial state, made on the host."""
        engine = cls.__new__(cls)
        engine._setup(points, faces, free, params, None, targets, motion, defer_distances=True)
        return engine

    @property
    def nearest(self) -> NearestBoundary | None:
        """The quadtree over the fixed nodes (refined for the first engine's centroids);
        None when the distance weights are uniform (no anchors)."""
        return None if self._distance is _UNIFORM else self._distance.tree

    def _setup(self, points, faces: FaceSet, free, params: EEGTParams, nearest, targets,
               motion: BoundaryMotion | None = None, defer_distances: bool = False,
               known=None) -> None:
        """State at `points`; `nearest`: distances to these fixed nodes (None: set them up);
        defer_distances: leave the distance weights to the first step (`inv_d_pow` None:
        this engine's `step`, or the OpenCL engine's on the device), the same values later;
        `known`: (x, y, per-group q) of another state of these faces, whose q faces with
        unchanged corners keep."""
        self.params = params
        self.faces = faces
        self.targets = targets
        self.motion = motion
        self.slide = None if motion is None else motion.slide
        # per group: its GroupTargets, or None (the paper's regular polygon)
        self.group_targets = [None] * len(faces.groups) if targets is None else targets.groups
        self.x = np.ascontiguousarray(points[:, 0], dtype=np.float64).copy()
        self.y = np.ascontiguousarray(points[:, 1], dtype=np.float64).copy()
        self.n_nodes = self.x.size
        self.free = np.ascontiguousarray(free, dtype=bool)
        self.groups = faces.groups
        self.corner_nodes = np.concatenate([g.nodes.ravel() for g in self.groups])
        self._node_corners: tuple[np.ndarray, ...] | None = None  # `_faces_with`'s table
        self.q = self._quality_all() if known is None else self._quality_since(*known)
        self.lbar, min_edge = self._edge_lengths()
        needs_centroids = nearest is None or not (defer_distances or nearest is _UNIFORM)
        centroids = self._centroids() if needs_centroids else None
        if nearest is None and motion is not None:
            nearest = _UNIFORM
            if motion.anchor_x.size:
                nearest = _FixedNodeDistance(
                    motion.anchor_x, motion.anchor_y, *centroids, 0.5 * min_edge
                )
        if nearest is None:
            fixed_idx = np.flatnonzero(~self.free & faces.used_nodes(self.n_nodes))
            nearest = _FixedNodeDistance(
                self.x[fixed_idx], self.y[fixed_idx], *centroids, 0.5 * min_edge
            )
        self._distance = nearest
        if self.slide is not None:  # the sliding nodes' parameters on their curves
            s = self.slide
            self.tau = s.locate(np.arange(s.size), self.x[s.node], self.y[s.node])
            self.tau_old = self.tau.copy()
            self.slot = np.full(self.n_nodes, -1, dtype=np.int64)
            self.slot[s.node] = np.arange(s.size)
        self.inv_d_pow: list[np.ndarray] = []
        self.iteration = 0
        if defer_distances and self._distance is not _UNIFORM:
            self.inv_d_pow = None
        else:
            self._refresh_distances(centroids)
        self.best_x = self.x.copy()
        self.best_y = self.y.copy()

    # -- helpers -------------------------------------------------------------------------
    def _gather(self, g) -> tuple[np.ndarray, np.ndarray]:
        return self.x[g.nodes], self.y[g.nodes]

    def _centroids(self) -> tuple[np.ndarray, np.ndarray]:
        """Vertex centroids of all elements, groups concatenated."""
        cs = [self._gather(g) for g in self.groups]
        return np.concatenate([X.mean(0) for X, _ in cs]), np.concatenate(
            [Y.mean(0) for _, Y in cs]
        )

    def _edge_lengths(self) -> tuple[float, float]:
        """(lbar, smallest element mean edge length > 0) of the current positions."""
        return edge_lengths(self.x, self.y, self.groups)

    def _refresh_distances(self, centroids: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """f_j = (lbar / d_j)^c from element vertex centroids (those of the current positions,
        computed unless given) to the nearest fixed node."""
        if self._distance is _UNIFORM:  # no anchors: every element weighs the same
            self.inv_d_pow = [np.ones(g.size) for g in self.groups]
            return
        cx, cy = self._centroids() if centroids is None else centroids
        f = distance_weight(self._distance.query(cx, cy), self.lbar, self.params.c)
        self.inv_d_pow = np.split(f, np.cumsum([g.size for g in self.groups])[:-1])

    def _quality_all(self) -> list[np.ndarray]:
        return [
            group_quality(*self._gather(g), None if t is None else t.corners)
            for g, t in zip(self.groups, self.group_targets)
        ]

    def _quality_since(self, x: np.ndarray, y: np.ndarray, q: list[np.ndarray]) -> list[np.ndarray]:
        """`_quality_all`, measuring only the faces with a corner whose bits differ from
        (x, y), where the per-group qualities were `q`."""
        moved = (self.x != x) | (self.y != y)
        return self._quality_at([np.flatnonzero(moved[g.nodes].any(axis=0))
                                 for g in self.groups], q)

    def _quality_at(self, columns: list[np.ndarray], q: list[np.ndarray]) -> list[np.ndarray]:
        """`_quality_all`, measuring only the faces ``columns`` (per group), where the
        per-group qualities were `q` (a face's quality is its own corners': the same bits
        as measuring every face)."""
        out = []
        for g, t, qg, cols in zip(self.groups, self.group_targets, q, columns):
            qg = qg.copy()
            if cols.size:
                nodes = g.nodes[:, cols]
                corners = None if t is None else (t.corners[0][:, cols], t.corners[1][:, cols])
                qg[cols] = group_quality(self.x[nodes], self.y[nodes], corners)
            out.append(qg)
        return out

    # -- the iteration -------------------------------------------------------------------
    def stats(self) -> Stats:
        """Stats of the current positions."""
        return stats_of(self.q)

    def _node_moves(self) -> tuple[np.ndarray, np.ndarray]:
        """Every free node's move: each element's transform (stretch and shrink, step size
        lambda) weighted by w = f(d) g(q) (eq. 20-21), then stitched (eq. 18)."""
        p = self.params
        wx, wy, ww = [], [], []
        for g, q, f, t in zip(self.groups, self.q, self.inv_d_pow, self.group_targets):
            X, Y = self._gather(g)
            DX, DY = group_transform_delta(X, Y, step_size(q, p.a), p.scaling, t)
            w = f * quality_weight(q, p.eta, p.inverted_weight)
            wx.append((DX * w).ravel())
            wy.append((DY * w).ravel())
            ww.append(np.broadcast_to(w, DX.shape).ravel())
        cat = np.concatenate if len(self.groups) > 1 else (lambda parts: parts[0])
        return stitch(self.corner_nodes, cat(wx), cat(wy), cat(ww), self.free)

    def step(self, phase: str) -> Stats:
        """One transform + stitch iteration; in 'smooth', nodes of new inverted faces go back.

        A diverging run (a free boundary drifting away) can pass 1e154, where squared edges
        overflow to inf and the faces there read too low a quality (0 for a triangle), the
        same as on the OpenCL device; the run keeps its best iterate. That overflow is part
        of the result (the twins agree bit for bit), so it is not warned about."""
        with np.errstate(over="ignore"):
            return self._step(phase)

    def _step(self, phase: str) -> Stats:
        self.iteration += 1
        if self.inv_d_pow is None or (
            self.iteration > 1 and (self.iteration - 1) % self.params.distance_refresh == 0
        ):
            self._refresh_distances()
        dx, dy = self._node_moves()
        moving = self.free & ((dx != 0) | (dy != 0))
        old_x, old_y = self.x.copy(), self.y.copy()
        np.add(self.x, dx, out=self.x, where=moving)
        np.add(self.y, dy, out=self.y, where=moving)
        if self.slide is not None:
            self._slide(moving)
        self.q = self._quality_all()
        if phase == "smooth":
            self._revert_inverted(old_x, old_y)
        return self.stats()

    def _slide(self, moving: np.ndarray) -> None:
        """Sliding nodes that moved go to the nearest point of their curve within their
        reach (core.eegt.boundary.Slide.project), from the parameters before the step."""
        s = self.slide
        np.copyto(self.tau_old, self.tau)
        sel = np.flatnonzero(moving[s.node])
        if sel.size == 0:
            return
        nodes = s.node[sel]
        tau, x, y = s.project(self.tau_old, sel, self.x[nodes], self.y[nodes])
        self.tau[sel] = tau
        self.x[nodes] = x
        self.y[nodes] = y

    def _revert_inverted(self, old_x: np.ndarray, old_y: np.ndarray) -> None:
        """Move every node of a face that became inverted back, until none is inverted.
        A pass measures again only the faces with a node it moved back (the others keep
        their qualities): a revert that spreads ring by ring over a large moved region
        costs passes over those rings, not over the whole mesh each time."""
        moved = (self.x != old_x) | (self.y != old_y)
        bad = [np.flatnonzero(q == 0.0) for q in self.q]  # per group: the faces to look at
        while True:
            back = np.zeros(self.n_nodes, dtype=bool)
            for g, cols in zip(self.groups, bad):
                back[g.nodes[:, cols].ravel()] = True
            back &= moved
            if not back.any():
                return
            self.x[back] = old_x[back]
            self.y[back] = old_y[back]
            moved &= ~back
            if self.slide is not None:
                slots = self.slot[back]
                slots = slots[slots >= 0]
                self.tau[slots] = self.tau_old[slots]
            # only a face with a node moved back changed: it alone may be inverted now (a
            # face inverted before has every moved node back, or none to move back)
            touched = self._faces_with(back)
            self.q = self._quality_at(touched, self.q)
            bad = [cols[qg[cols] == 0.0] for qg, cols in zip(self.q, touched)]

    def _faces_with(self, nodes: np.ndarray) -> list[np.ndarray]:
        """Per group, the faces (sorted columns) with a node in ``nodes`` ((N,) bool), from
        a node -> corner table built on first use."""
        if self._node_corners is None:
            ptr, order = bincount_csr(self.corner_nodes, self.n_nodes)
            group = np.concatenate([np.full(g.nodes.size, i) for i, g in
                                    enumerate(self.groups)])
            column = np.concatenate([np.tile(np.arange(g.size), g.nodes.shape[0])
                                     for g in self.groups])
            self._node_corners = (ptr, group[order], column[order])
        ptr, group, column = self._node_corners
        ids = np.flatnonzero(nodes)
        at = ragged_arange(ptr[ids], ptr[ids + 1] - ptr[ids])
        g_at, c_at = group[at], column[at]
        return [np.unique(c_at[g_at == i]) for i in range(len(self.groups))]

    # -- best iterate --------------------------------------------------------------------
    def save_best(self) -> None:
        np.copyto(self.best_x, self.x)
        np.copyto(self.best_y, self.y)

    def best_points(self) -> np.ndarray:
        return np.column_stack([self.best_x, self.best_y])

    def points(self) -> np.ndarray:
        return np.column_stack([self.x, self.y])
