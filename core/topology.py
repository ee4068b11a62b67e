"""Edge analysis: which nodes are on the boundary or on non-manifold edges (always fixed)."""

from __future__ import annotations

import numpy as np

from .faces import FaceSet, as_faceset

__all__ = ["EdgeInfo", "boundary_nodes", "edge_info", "free_nodes"]


class EdgeInfo:
    """Undirected edges of a face set with their use counts and orientation conflicts."""

    def __init__(self, faces: FaceSet, n_nodes: int):
        a = np.concatenate([g.nodes.ravel() for g in faces.groups])
        b = np.concatenate([np.roll(g.nodes, -1, axis=0).ravel() for g in faces.groups])
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        # one sort of (edge key, direction bit): runs of equal keys are the uses of an edge
        key = (lo * n_nodes + hi) * 2 + (a < b)
        key.sort()
        edge = key >> 1
        first = np.flatnonzero(np.concatenate([[True], edge[1:] != edge[:-1]]))
        uniq = edge[first]
        counts = np.diff(np.append(first, key.size))
        self.n_nodes = n_nodes
        self.lo = uniq // n_nodes
        self.hi = uniq % n_nodes
        self.counts = counts
        # An interior edge of a consistently oriented surface is used once in each
        # direction; twice in the same direction means neighbouring faces disagree.
        forward = np.add.reduceat(key & 1, first)
        self.conflict = (counts == 2) & (forward != 1)

    def boundary_mask(self) -> np.ndarray:
        """(n_nodes,) bool: nodes of edges used by one face or by more than two."""
        mask = np.zeros(self.n_nodes, dtype=bool)
        open_edge = self.counts != 2
        mask[self.lo[open_edge]] = True
        mask[self.hi[open_edge]] = True
        return mask


def edge_info(faces, n_nodes: int) -> EdgeInfo:
    return EdgeInfo(as_faceset(faces, n_nodes), n_nodes)


def boundary_nodes(n_nodes: int, faces) -> np.ndarray:
    """(n_nodes,) bool: topological boundary and non-manifold nodes (never moved)."""
    return edge_info(faces, n_nodes).boundary_mask()


def free_nodes(n_nodes: int, faces, fixed=None) -> np.ndarray:
    """(N,) bool: nodes the method may move (not boundary, non-manifold, pinned or loose)."""
    fs = as_faceset(faces, n_nodes)
    edges = EdgeInfo(fs, n_nodes)
    if edges.conflict.any():
        k = int(np.flatnonzero(edges.conflict)[0])
        raise ValueError(
            f"faces are not consistently oriented: edge ({int(edges.lo[k])}, {int(edges.hi[k])}) "
            f"is used twice in the same direction ({int(edges.conflict.sum())} such edges; "
            "recalculate normals)"
        )
    free = fs.used_nodes(n_nodes) & ~edges.boundary_mask()
    if fixed is not None:
        pinned = np.asarray(fixed)
        if pinned.shape != (n_nodes,):
            raise ValueError(f"fixed must be an ({n_nodes},) bool array, got shape {pinned.shape}")
        if pinned.dtype.kind not in "biuf":
            raise ValueError(f"fixed must be an ({n_nodes},) bool array, got {pinned.dtype} values")
        free &= ~pinned.astype(bool)
    return free
