"""Edge analysis: which nodes are on the boundary or on non-manifold edges (always fixed)."""

from __future__ import annotations

import numpy as np

from .faces import FaceSet, as_faceset

__all__ = ["EdgeInfo", "boundary_nodes", "edge_info"]


class EdgeInfo:
    """Undirected edges of a face set with their use counts and orientation conflicts."""

    def __init__(self, faces: FaceSet, n_nodes: int):
        a = np.concatenate([g.nodes.ravel() for g in faces.groups])
        b = np.concatenate([np.roll(g.nodes, -1, axis=0).ravel() for g in faces.groups])
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        key = lo * n_nodes + hi
        uniq, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
        self.n_nodes = n_nodes
        self.lo = uniq // n_nodes
        self.hi = uniq % n_nodes
        self.counts = counts
        # An interior edge of a consistently oriented surface is used once in each
        # direction; twice in the same direction means neighbouring faces disagree.
        forward = np.bincount(inverse, weights=(a < b), minlength=uniq.size)
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
