"""What a live drag keeps between its frames (core.run.live), each piece the same bits as
measuring again: the still fixed nodes' distances per element, the grabbed nodes' distances
where they can matter, the quality of the faces as the caller has them.
"""

from __future__ import annotations

import numpy as np

from ..eegt.distance import NearestBoundary
from ..mesh.faces import FaceSet
from ..metrics.face_quality import Stats, stats_of
from ..metrics.mean_ratio import scaled_group_quality
from ..metrics.targets import Targets

__all__ = ["AnchorSearch", "GivenQuality", "StillDistances"]

_DIRECT_PAIRS = 1 << 20  # grabbed node / centroid pairs up to which distances are direct
_BOX_SLACK = 1e-9  # relative margin on the box bound (its rounding)


class AnchorSearch:
    """Exact distance from element centroids to the nearest fixed node during a drag, the
    fixed nodes being the ones that stay (``still``, one ``NearestBoundary``) and the grabbed
    ones at this frame's place (``gx``, ``gy``): the minimum of the two exact distances is
    the distance to the union, bit for bit (a minimum over a set does not depend on how the
    set is split or ordered).

    The still distances are kept per element between queries (``StillDistances``): only
    centroids whose bits changed are measured again. The grabbed nodes are measured only for
    centroids that may be nearer to them than to a still node: a centroid farther from the
    grabbed nodes' bounding box than from its nearest still node keeps the still distance."""

    def __init__(self, still: StillDistances | None, gx: np.ndarray, gy: np.ndarray):
        self.still, self.gx, self.gy = still, gx, gy

    def query(self, qx: np.ndarray, qy: np.ndarray) -> np.ndarray:
        if self.gx.size == 0:
            return self.still.query(qx, qy)
        if self.still is None:
            return _nearest(self.gx, self.gy, qx, qy)
        out = self.still.query(qx, qy).copy()
        # a lower bound of the distance to the grabbed nodes: to their bounding box
        bx = np.maximum(np.maximum(self.gx.min() - qx, qx - self.gx.max()), 0.0)
        by = np.maximum(np.maximum(self.gy.min() - qy, qy - self.gy.max()), 0.0)
        box = np.sqrt(bx * bx + by * by) * (1.0 - _BOX_SLACK)
        near = np.flatnonzero(~(out < box))  # NaN centroids too
        if near.size:
            out[near] = np.minimum(out[near], _nearest(self.gx, self.gy, qx[near], qy[near]))
        return out


def _nearest(bx: np.ndarray, by: np.ndarray, qx: np.ndarray, qy: np.ndarray) -> np.ndarray:
    """Exact distance from each (qx, qy) to the nearest (bx, by): over all pairs while they
    are few, else by a ``NearestBoundary`` (the same minimum of the same squares)."""
    if bx.size * qx.size > _DIRECT_PAIRS:
        return NearestBoundary(bx, by).query(qx, qy)
    dx = bx[:, None] - qx[None, :]
    dy = by[:, None] - qy[None, :]
    dx *= dx
    dy *= dy
    dx += dy
    return np.sqrt(np.minimum.reduce(dx, axis=0))


class StillDistances:
    """Distances from element centroids to the nearest of a drag's fixed nodes that stay,
    kept per element: a query measures only the centroids whose bits differ from the last
    query's (the rest keep their distance, the same bits as measuring them again)."""

    def __init__(self, search: NearestBoundary):
        self.search = search
        self.qx = self.qy = self.d = None
        self.measured = 0  # centroids measured by the last query

    def query(self, qx: np.ndarray, qy: np.ndarray) -> np.ndarray:
        if self.d is None or self.d.size != qx.size:
            self.qx, self.qy = qx.copy(), qy.copy()
            self.d = self.search.query(qx, qy)
            self.measured = qx.size
            return self.d
        moved = np.flatnonzero((qx != self.qx) | (qy != self.qy))
        self.measured = moved.size
        if moved.size:
            mx, my = qx[moved], qy[moved]
            self.d[moved] = self.search.query(mx, my)
            self.qx[moved], self.qy[moved] = mx, my
        return self.d


class GivenQuality:
    """Per-face mean ratio of the positions as the caller has them (``pipeline.as_given``),
    kept between calls: ``stats`` measures only the faces with a corner whose bits changed
    since the last call (a face's quality depends on its own corners only), then the
    ``mesh_stats`` of the whole mesh over the (F,) face-order array, as the cold run has it."""

    def __init__(self, fs: FaceSet, targets: Targets | None):
        self.fs = fs
        self.corners = ([None] * len(fs.groups) if targets is None
                        else [t.corners for t in targets.groups])
        self.pos: np.ndarray | None = None
        self.q = np.empty(fs.n_faces)

    def stats(self, given: np.ndarray) -> Stats:
        moved = None if self.pos is None else np.any(given != self.pos, axis=1)
        for g, corners in zip(self.fs.groups, self.corners):
            if moved is None:
                cols = slice(None)
            else:
                cols = np.flatnonzero(moved[g.nodes].any(axis=0))
                if cols.size == 0:
                    continue
            nodes = g.nodes[:, cols]
            part = None if corners is None else (corners[0][:, cols], corners[1][:, cols])
            self.q[g.ids[cols]] = scaled_group_quality(given[nodes, 0], given[nodes, 1], part)
        self.pos = given.copy()
        return stats_of([self.q])
