"""Exact nearest-boundary-node distances with NumPy only (no SciPy k-d tree in Blender).

Boundary nodes never move, so the search structure is built once per run: a uniform grid
over the boundary's bounding square, refined level by level like a quadtree. Each cell keeps
only the boundary nodes that can be the nearest one for some point of the cell (a node whose
distance to the cell box exceeds the smallest "farthest distance" of any node cannot win).
A query then scans the short candidate list of its leaf cell. Queries outside the grid (a
tangled node can leave the domain) are answered by brute force.
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np

__all__ = ["NearestBoundary"]

_CHUNK_PAIRS = 1 << 21  # query/candidate pairs handled per vectorized batch


def _ragged_arange(starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Concatenation of arange(s, s + l) for each (s, l), without a Python loop."""
    total = int(lengths.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    seg_first = np.cumsum(lengths) - lengths
    return np.arange(total, dtype=np.int64) + np.repeat(starts - seg_first, lengths)


class NearestBoundary:
    """Distance from query points to the nearest of a fixed set of boundary points."""

    def __init__(self, bx: np.ndarray, by: np.ndarray, leaf_cells: int | None = None):
        self.bx = np.ascontiguousarray(bx, dtype=np.float64)
        self.by = np.ascontiguousarray(by, dtype=np.float64)
        nb = self.bx.size
        if nb == 0:
            raise ValueError("no boundary nodes to measure distances to")
        lo = np.array([self.bx.min(), self.by.min()])
        side = float(max(self.bx.max() - lo[0], self.by.max() - lo[1]))
        side = side * (1 + 1e-9) + 1e-300 if side > 0 else 1.0
        self.origin = lo
        self.side = side
        target = leaf_cells if leaf_cells is not None else max(16, 4 * nb)
        self.levels = int(np.clip(np.ceil(np.log(target) / np.log(4)), 0, 11))
        self._build()

    def _build(self) -> None:
        nb = self.bx.size
        # level 0: one cell, every boundary node a candidate
        cell_ix = np.zeros(1, dtype=np.int64)
        cell_iy = np.zeros(1, dtype=np.int64)
        seg_len = np.array([nb], dtype=np.int64)
        cand = np.arange(nb, dtype=np.int64)
        for level in range(1, self.levels + 1):
            h = self.side / (1 << level)
            # each parent segment is repeated for its 4 children, child-major inside parent
            starts = np.cumsum(seg_len) - seg_len
            child_start = np.repeat(starts, 4)
            child_len = np.repeat(seg_len, 4)
            quad = np.tile(np.arange(4), seg_len.size)
            c_ix = np.repeat(cell_ix, 4) * 2 + (quad & 1)
            c_iy = np.repeat(cell_iy, 4) * 2 + (quad >> 1)
            pc = cand[_ragged_arange(child_start, child_len)]
            owner = np.repeat(np.arange(c_ix.size), child_len)
            x0 = self.origin[0] + c_ix[owner] * h
            y0 = self.origin[1] + c_iy[owner] * h
            px, py = self.bx[pc], self.by[pc]
            dx_near = np.maximum(np.maximum(x0 - px, px - (x0 + h)), 0.0)
            dy_near = np.maximum(np.maximum(y0 - py, py - (y0 + h)), 0.0)
            dx_far = np.maximum(np.abs(px - x0), np.abs(px - (x0 + h)))
            dy_far = np.maximum(np.abs(py - y0), np.abs(py - (y0 + h)))
            near2 = dx_near * dx_near + dy_near * dy_near
            far2 = dx_far * dx_far + dy_far * dy_far
            seg_first = np.cumsum(child_len) - child_len
            bound = np.minimum.reduceat(far2, seg_first)
            keep = near2 <= bound[owner] * (1 + 1e-12)
            cand = pc[keep]
            seg_len = np.bincount(owner[keep], minlength=c_ix.size).astype(np.int64)
            cell_ix, cell_iy = c_ix, c_iy
        g = 1 << self.levels
        self.grid = g
        self.cell_size = self.side / g
        seg_start = np.cumsum(seg_len) - seg_len
        self.leaf_start = np.empty(g * g, dtype=np.int64)
        self.leaf_len = np.empty(g * g, dtype=np.int64)
        flat = cell_iy * g + cell_ix
        self.leaf_start[flat] = seg_start
        self.leaf_len[flat] = seg_len
        self.cand = cand
        self.n_candidate_pairs = int(cand.size)

    def query(self, qx: np.ndarray, qy: np.ndarray) -> np.ndarray:
        """(Q,) Euclidean distance from each (qx, qy) to its nearest boundary point."""
        qx = np.asarray(qx, dtype=np.float64)
        qy = np.asarray(qy, dtype=np.float64)
        out = np.empty(qx.size)
        g = self.grid
        fx = np.floor((qx - self.origin[0]) / self.cell_size)
        fy = np.floor((qy - self.origin[1]) / self.cell_size)
        inside = (fx >= 0) & (fx < g) & (fy >= 0) & (fy < g)
        qin = np.flatnonzero(inside)
        cell = fy[qin].astype(np.int64) * g + fx[qin].astype(np.int64)
        lens = self.leaf_len[cell]
        starts = self.leaf_start[cell]
        bounds = np.searchsorted(np.cumsum(lens), np.arange(0, lens.sum() + 1, _CHUNK_PAIRS)[1:])
        edges = np.unique(np.concatenate([[0], bounds, [qin.size]]))
        for a, b in pairwise(edges):
            ln = lens[a:b]
            pc = self.cand[_ragged_arange(starts[a:b], ln)]
            dx = self.bx[pc] - np.repeat(qx[qin[a:b]], ln)
            dy = self.by[pc] - np.repeat(qy[qin[a:b]], ln)
            d2 = dx * dx + dy * dy
            out[qin[a:b]] = np.minimum.reduceat(d2, np.cumsum(ln) - ln)
        qout = np.flatnonzero(~inside)
        for a in range(0, qout.size, max(1, _CHUNK_PAIRS // self.bx.size)):
            sel = qout[a : a + max(1, _CHUNK_PAIRS // self.bx.size)]
            dx = self.bx[None, :] - qx[sel, None]
            dy = self.by[None, :] - qy[sel, None]
            out[sel] = (dx * dx + dy * dy).min(axis=1)
        return np.sqrt(out)
