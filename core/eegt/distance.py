"""Exact nearest-boundary-node distances with NumPy only (no SciPy k-d tree in Blender).

Boundary nodes never move, so the search structure is built once per run: a uniform grid
over the boundary's bounding square, refined level by level like a quadtree. Each cell keeps
only the boundary nodes that can be the nearest one for some point of the cell (a node whose
distance to the cell box exceeds the smallest "farthest distance" of any node cannot win).
Cells with more than a few candidates are split (an adaptive quadtree), so a query scans
a short list wherever the boundary is dense. Queries outside the grid (a
tangled node can leave the domain) are answered by brute force.
"""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np

from ..mesh.csr import morton, ragged_arange

__all__ = ["NearestBoundary"]

_CHUNK_PAIRS = 1 << 21  # query/candidate pairs handled per vectorized batch


class NearestBoundary:
    """Distance from query points to the nearest of a fixed set of boundary points."""

    def __init__(
        self,
        bx: np.ndarray,
        by: np.ndarray,
        hint_x: np.ndarray | None = None,
        hint_y: np.ndarray | None = None,
        min_cell: float = 0.0,
        leaf_size: int = 16,
        leaf_hints: int = 256,
    ):
        """Build over boundary points (bx, by). Cells are refined only where the hint points
        (the queries expected, e.g. element centroids) lie, down to about `min_cell`."""
        self.bx = np.ascontiguousarray(bx, dtype=np.float64)
        self.by = np.ascontiguousarray(by, dtype=np.float64)
        nb = self.bx.size
        if nb == 0:
            raise ValueError("no boundary nodes to measure distances to")
        lo = np.array([self.bx.min(), self.by.min()])
        side = float(max(self.bx.max() - lo[0], self.by.max() - lo[1]))
        side = side if side > 0 else 1.0
        # a margin of half the size on every side: tangled centroids may leave the domain
        self.side = 2.0 * side
        self.origin = lo - 0.5 * side
        finest = min_cell if min_cell > 0 else self.side / 4096
        m, e = math.frexp(self.side / finest)  # ceil(log2(ratio)), exactly (no libm)
        self.depth = int(min(max(e - (m == 0.5), 1), 30))
        codes = None  # the hints' finest cells in Z order, sorted: counts per cell by range
        if hint_x is not None:
            codes = np.sort(morton(*self._cell_coords(np.asarray(hint_x), np.asarray(hint_y))))
        self._build(leaf_size, leaf_hints, codes)

    def _cell_coords(self, qx: np.ndarray, qy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Integer cell coordinates at the finest level (clipped into the root square)."""
        scale = (1 << self.depth) / self.side
        top = (1 << self.depth) - 1
        ix = np.clip(np.floor((qx - self.origin[0]) * scale), 0, top).astype(np.int64)
        iy = np.clip(np.floor((qy - self.origin[1]) * scale), 0, top).astype(np.int64)
        return ix, iy

    def _build(self, leaf_size: int, leaf_hints: int, codes: np.ndarray | None) -> None:
        """Split cells with more than `leaf_size` candidates and more than `leaf_hints` hints
        (codes: the hints' sorted Z-order codes at the finest level; None: no hints)."""
        nb = self.bx.size
        cell_ix = np.zeros(1, dtype=np.int64)
        cell_iy = np.zeros(1, dtype=np.int64)
        seg_len = np.array([nb], dtype=np.int64)
        cand = np.arange(nb, dtype=np.int64)
        self.child: list[np.ndarray] = []  # per level: first child's index, or -1 for a leaf
        self.leaf_start: list[np.ndarray] = []  # per level: leaf segment in self.cand
        self.leaf_len: list[np.ndarray] = []
        leaf_parts: list[np.ndarray] = []
        n_leaf_pairs = 0
        for level in range(self.depth + 1):
            seg_first = np.cumsum(seg_len) - seg_len
            split = seg_len > leaf_size if level < self.depth else np.zeros(seg_len.size, bool)
            if codes is not None and split.any():
                shift = np.uint64(2 * (self.depth - level))
                first = morton(cell_ix, cell_iy) << shift  # each cell's range of codes
                n_hints = (np.searchsorted(codes, first + (np.uint64(1) << shift))
                           - np.searchsorted(codes, first))
                split &= n_hints > leaf_hints
            child = np.full(seg_len.size, -1, dtype=np.int64)
            child[split] = 4 * np.arange(int(split.sum()))
            leaf_start = np.full(seg_len.size, -1, dtype=np.int64)
            leaf = ~split
            leaf_start[leaf] = n_leaf_pairs + np.cumsum(seg_len[leaf]) - seg_len[leaf]
            n_leaf_pairs += int(seg_len[leaf].sum())
            leaf_parts.append(cand[ragged_arange(seg_first[leaf], seg_len[leaf])])
            self.child.append(child)
            self.leaf_start.append(leaf_start)
            self.leaf_len.append(np.where(leaf, seg_len, 0))
            if not split.any():
                break
            # children of split cells, 4 per parent, each starting from the parent's list
            p_first, p_len = seg_first[split], seg_len[split]
            quad = np.tile(np.arange(4), p_len.size)
            c_ix = np.repeat(cell_ix[split], 4) * 2 + (quad & 1)
            c_iy = np.repeat(cell_iy[split], 4) * 2 + (quad >> 1)
            c_len = np.repeat(p_len, 4)
            pc = cand[ragged_arange(np.repeat(p_first, 4), c_len)]
            owner = np.repeat(np.arange(c_ix.size), c_len)
            h = self.side / (1 << (level + 1))
            x0 = self.origin[0] + c_ix[owner] * h
            y0 = self.origin[1] + c_iy[owner] * h
            px, py = self.bx[pc], self.by[pc]
            dx_near = np.maximum(np.maximum(x0 - px, px - (x0 + h)), 0.0)
            dy_near = np.maximum(np.maximum(y0 - py, py - (y0 + h)), 0.0)
            dx_far = np.maximum(np.abs(px - x0), np.abs(px - (x0 + h)))
            dy_far = np.maximum(np.abs(py - y0), np.abs(py - (y0 + h)))
            near2 = dx_near * dx_near + dy_near * dy_near
            far2 = dx_far * dx_far + dy_far * dy_far
            bound = np.minimum.reduceat(far2, np.cumsum(c_len) - c_len)
            keep = near2 <= bound[owner] * (1 + 1e-12)
            cand = pc[keep]
            seg_len = np.bincount(owner[keep], minlength=c_ix.size).astype(np.int64)
            cell_ix, cell_iy = c_ix, c_iy
        self.cand = np.concatenate(leaf_parts)
        self.n_candidate_pairs = int(self.cand.size)

    def _locate(self, qx: np.ndarray, qy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Leaf candidate segment (start, length) of each query inside the root square."""
        ix, iy = self._cell_coords(qx, qy)
        node = np.zeros(qx.size, dtype=np.int64)
        start = np.empty(qx.size, dtype=np.int64)
        length = np.empty(qx.size, dtype=np.int64)
        active = np.arange(qx.size)
        for level, child in enumerate(self.child):
            ch = child[node]
            leaf = ch < 0
            start[active[leaf]] = self.leaf_start[level][node[leaf]]
            length[active[leaf]] = self.leaf_len[level][node[leaf]]
            keep = ~leaf
            active, ch = active[keep], ch[keep]
            if active.size == 0:
                break
            shift = self.depth - level - 1
            quad = ((ix[active] >> shift) & 1) + 2 * ((iy[active] >> shift) & 1)
            node = ch + quad
        return start, length

    def query(self, qx: np.ndarray, qy: np.ndarray) -> np.ndarray:
        """(Q,) Euclidean distance from each (qx, qy) to its nearest boundary point."""
        qx = np.asarray(qx, dtype=np.float64)
        qy = np.asarray(qy, dtype=np.float64)
        out = np.empty(qx.size)
        lim = self.side * (1 - 1e-12)
        inside = (
            (qx >= self.origin[0])
            & (qx - self.origin[0] < lim)
            & (qy >= self.origin[1])
            & (qy - self.origin[1] < lim)
        )
        qin = np.flatnonzero(inside)
        starts, lens = self._locate(qx[qin], qy[qin])
        csum = np.cumsum(lens)
        cuts = np.searchsorted(
            csum, np.arange(_CHUNK_PAIRS, int(csum[-1]) if csum.size else 0, _CHUNK_PAIRS)
        )
        edges = np.unique(np.concatenate([[0], cuts, [qin.size]]))
        for a, b in pairwise(edges):
            ln = lens[a:b]
            pc = self.cand[ragged_arange(starts[a:b], ln)]
            dx = self.bx[pc] - np.repeat(qx[qin[a:b]], ln)
            dy = self.by[pc] - np.repeat(qy[qin[a:b]], ln)
            d2 = dx * dx + dy * dy
            out[qin[a:b]] = np.minimum.reduceat(d2, np.cumsum(ln) - ln)
        qout = np.flatnonzero(~inside)
        step = max(1, _CHUNK_PAIRS // self.bx.size)
        for a in range(0, qout.size, step):
            sel = qout[a : a + step]
            dx = self.bx[None, :] - qx[sel, None]
            dy = self.by[None, :] - qy[sel, None]
            out[sel] = (dx * dx + dy * dy).min(axis=1)
        return np.sqrt(out)
