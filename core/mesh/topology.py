"""Edge analysis: which nodes are on the boundary or on non-manifold edges (always fixed).

`EdgeInfo` is the analysis of a face set: which faces use each undirected edge, and which
way round. It is built by one sort of every corner's edge, or, for a mesh that keeps an
edge table (Blender does), from that table by one count per edge (`EdgeInfo.from_table`).
Both keep the same edges with the same counts, so the same boundary, conflicts and open
edges; only their order in the arrays differs, and what depends on an order
(`open_edges`, `first_conflict`) sorts.
"""

from __future__ import annotations

import numpy as np

from .faces import FaceSet, as_faceset

__all__ = ["EdgeInfo", "boundary_nodes", "edge_info", "free_nodes"]

_CHUNK = 1 << 16  # corners per block of the table check (small, reused temporaries)


class EdgeInfo:
    """The edges of a face set that are not plain interior edges: used by one face or by
    more than two (open, non-manifold), or by two faces walking them the same way
    (conflicting). An interior edge of a consistently oriented surface (two faces, one each
    way) fixes nothing and is not kept.

    Per kept edge: its nodes ``lo < hi``, ``counts`` (faces using it), ``net`` (walks
    lo -> hi minus walks hi -> lo) and ``conflict`` (two faces walk it the same way).
    """

    n_nodes: int
    lo: np.ndarray
    hi: np.ndarray
    counts: np.ndarray
    net: np.ndarray
    conflict: np.ndarray
    in_key_order: bool  # edges in ascending lo * n_nodes + hi

    def __init__(self, faces: FaceSet, n_nodes: int):
        # one sort of (edge key, direction bit): runs of equal keys are the uses of an edge
        key = np.empty(faces.n_corners, dtype=np.int64)
        less = np.empty(max(g.size for g in faces.groups), dtype=bool)
        at = 0
        for g in faces.groups:  # written in place: no corner-sized temporaries
            for k in range(g.n):
                x, y = g.nodes[k], g.nodes[(k + 1) % g.n]
                part = key[at:at + g.size]
                np.minimum(x, y, out=part)
                part *= n_nodes - 1
                part += x
                part += y  # min * n + max
                part *= 2
                part += np.less(x, y, out=less[:g.size])
                at += g.size
        key.sort()
        edge = key >> 1
        first = np.flatnonzero(np.concatenate([[True], edge[1:] != edge[:-1]]))
        uniq = edge[first]
        del edge
        counts = np.diff(np.append(first, key.size))
        forward = np.add.reduceat(key & 1, first)
        keep = np.flatnonzero((counts != 2) | (forward != 1))
        uniq = uniq[keep]
        self._set(n_nodes, uniq // n_nodes, uniq % n_nodes, counts[keep], forward[keep], True)

    def _set(self, n_nodes: int, lo: np.ndarray, hi: np.ndarray, counts: np.ndarray,
             forward: np.ndarray, in_key_order: bool) -> None:
        self.n_nodes = int(n_nodes)
        self.lo, self.hi, self.counts = lo, hi, counts
        self.net = 2 * forward - counts
        # An interior edge of a consistently oriented surface is used once in each
        # direction; twice in the same direction means neighbouring faces disagree.
        self.conflict = (counts == 2) & (self.net != 0)
        self.in_key_order = in_key_order

    @classmethod
    def from_table(cls, a: np.ndarray, b: np.ndarray, edge_of: np.ndarray,
                   edge_nodes: np.ndarray, n_nodes: int) -> EdgeInfo | None:
        """The analysis of faces whose directed edges are a -> b (every corner's, any
        order, node ids below n_nodes < 2**31), given the edge of an (E, 2) table each one
        walks (``edge_of``): one count per table edge instead of a sort of every corner.
        The kept edges are in table order. None when the table does not fit the faces (a
        corner whose edge is not {a, b}, a repeated node, two used table edges joining the
        same nodes): the caller then builds ``EdgeInfo(faces, n)``."""
        table = np.ascontiguousarray(edge_nodes, dtype=np.int32)
        n_edges = table.shape[0] if table.ndim == 2 else 0
        if a.size == 0 or n_nodes >= 2**31 or n_edges == 0 or table.shape[1] != 2:
            return None
        if edge_of.min() < 0 or edge_of.max() >= n_edges:
            return None
        ends = table.view(np.int64).ravel()  # both ends of an edge as one int64
        for at in range(0, a.size, _CHUNK):
            x, y, e = a[at:at + _CHUNK], b[at:at + _CHUNK], edge_of[at:at + _CHUNK]
            named = ends[e]
            if np.any(x == y) or not np.all((named == _packed(x, y)) | (named == _packed(y, x))):
                return None
        counts = np.bincount(edge_of, minlength=n_edges)
        forward = np.bincount(edge_of[a < b], minlength=n_edges)
        used = counts > 0
        first, second = table[:, 0], table[:, 1]
        if not used.all():
            first, second = first[used], second[used]
        key = np.minimum(first, second).astype(np.int64)
        key *= n_nodes
        key += np.maximum(first, second)
        key.sort()
        if np.any(key[1:] == key[:-1]):  # a node pair named twice: the counts are split
            return None
        del key
        keep = np.flatnonzero(used & ((counts != 2) | (forward != 1)))
        x, y = table[keep, 0], table[keep, 1]
        info = cls.__new__(cls)
        info._set(n_nodes, np.minimum(x, y).astype(np.int64), np.maximum(x, y).astype(np.int64),
                  counts[keep], forward[keep], False)
        return info

    def renumbered(self, lut: np.ndarray, n_nodes: int) -> EdgeInfo:
        """The same analysis with node i renamed lut[i] (an increasing map of the used
        nodes onto 0..n_nodes-1: edge ends keep their order)."""
        out = EdgeInfo.__new__(EdgeInfo)
        out.__dict__.update(self.__dict__)
        out.n_nodes, out.lo, out.hi = int(n_nodes), lut[self.lo], lut[self.hi]
        return out

    def _by_key(self, mask: np.ndarray) -> np.ndarray:
        """Indices of the masked edges in ascending key order."""
        ids = np.flatnonzero(mask)
        if self.in_key_order:
            return ids
        return ids[np.argsort(self.lo[ids] * self.n_nodes + self.hi[ids], kind="stable")]

    def open_edges(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The edges whose directed uses do not cancel (boundary and non-manifold edges):
        their nodes lo < hi in ascending ``lo * n + hi`` order and their net count of
        lo -> hi walks (float64). Interior edges, walked once each way, are not in it."""
        ids = self._by_key(self.net != 0)
        return self.lo[ids], self.hi[ids], self.net[ids].astype(np.float64)

    def first_conflict(self) -> tuple[int, int] | None:
        """The conflicting edge (lo, hi) of smallest key, or None."""
        if not self.conflict.any():
            return None
        k = int(self._by_key(self.conflict)[0])
        return int(self.lo[k]), int(self.hi[k])

    def boundary_mask(self) -> np.ndarray:
        """(n_nodes,) bool: nodes of edges used by one face or by more than two."""
        mask = np.zeros(self.n_nodes, dtype=bool)
        open_edge = self.counts != 2
        mask[self.lo[open_edge]] = True
        mask[self.hi[open_edge]] = True
        return mask


def _packed(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Each pair (x, y) of int32-range ids as one int64 (the bytes of two int32s)."""
    out = np.empty((x.size, 2), dtype=np.int32)
    out[:, 0], out[:, 1] = x, y
    return out.view(np.int64).ravel()


def edge_info(faces, n_nodes: int) -> EdgeInfo:
    return EdgeInfo(as_faceset(faces, n_nodes), n_nodes)


def boundary_nodes(n_nodes: int, faces) -> np.ndarray:
    """(n_nodes,) bool: topological boundary and non-manifold nodes (never moved)."""
    return edge_info(faces, n_nodes).boundary_mask()


def pinched_faces(faces: FaceSet, n_nodes: int, border: np.ndarray | None = None) -> np.ndarray:
    """(F,) bool: faces with a corner at an inner node (not boundary or non-manifold) that
    only two faces use. Their angles there add up to a full turn, so the two are never both
    convex: such a pair always keeps an inverted face, whatever moves. `border`: the faces'
    `boundary_nodes` when the caller has them (None: computed here)."""
    if border is None:
        border = boundary_nodes(n_nodes, faces)
    inner_pair = (np.bincount(faces.indices, minlength=n_nodes) == 2) & ~border
    face_of = np.repeat(np.arange(faces.n_faces), faces.counts)
    return np.bincount(face_of, inner_pair[faces.indices], faces.n_faces) > 0


def checked_edges(edges: EdgeInfo | None, faces: FaceSet, n_nodes: int) -> EdgeInfo:
    """``edges`` when given (a caller's analysis of these faces, e.g. from a mesh's edge
    table), else the faces' own."""
    if edges is None:
        return EdgeInfo(faces, n_nodes)
    if not isinstance(edges, EdgeInfo) or edges.n_nodes != n_nodes:
        raise ValueError(f"edges must be the EdgeInfo of these faces over {n_nodes} nodes")
    return edges


def free_nodes(n_nodes: int, faces, fixed=None, edges: EdgeInfo | None = None) -> np.ndarray:
    """(N,) bool: nodes the method may move (not boundary, non-manifold, pinned or loose).
    ``edges``: the faces' EdgeInfo when the caller has it (None: computed here)."""
    fs = as_faceset(faces, n_nodes)
    edges = checked_edges(edges, fs, n_nodes)
    bad = edges.first_conflict()
    if bad is not None:
        raise ValueError(
            f"faces are not consistently oriented: edge ({bad[0]}, {bad[1]}) "
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
