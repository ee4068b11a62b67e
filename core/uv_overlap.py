"""Overlaps inside UV islands: faces that cover part of another face of the same island.

Flipped faces (inverted in their island's orientation) are the visible half of a fold; the
other half is made of valid-looking faces lying over their neighbours, which no orientation
test sees. This module finds them directly: faces are split into triangles, a uniform grid
proposes pairs whose bounding boxes meet, and the separating-axis test keeps the pairs whose
interiors overlap (touching along a shared edge or corner is no overlap). Faces of different
islands are never compared: where islands lie relative to each other is the layout's
business, not a tangle. NumPy only, vectorized over triangles and pairs.
"""

from __future__ import annotations

import numpy as np

from .faces import FaceSet

__all__ = ["candidate_pairs", "face_triangles", "overlapping_faces", "triangles_overlap"]

_CHUNK = 1 << 20  # pairs per narrow-phase batch (memory bound)
_MAX_CELLS = 64  # a box over more grid cells than this is tested against every box


def face_triangles(points: np.ndarray, fs: FaceSet) -> tuple[np.ndarray, np.ndarray]:
    """((T, 3) nodes, (T,) face) triangles covering every face: a quad is cut along the
    diagonal whose two triangles turn the same way (its interior one), other n-gons are
    fanned from their first corner (exact for the convex faces of a valid layout)."""
    tris, owner = [], []
    for g in fs.groups:
        nd = g.nodes  # (n, F)
        if g.n == 3:
            tris.append(nd.T)
            owner.append(g.ids)
            continue
        if g.n == 4:
            a012 = _area2(points, nd[0], nd[1], nd[2])
            a023 = _area2(points, nd[0], nd[2], nd[3])
            cut02 = np.sign(a012) == np.sign(a023)
            first = np.where(cut02, nd[[0, 1, 2]], nd[[1, 2, 3]])
            second = np.where(cut02, nd[[0, 2, 3]], nd[[1, 3, 0]])
            tris += [first.T, second.T]
            owner += [g.ids, g.ids]
            continue
        for k in range(1, g.n - 1):
            tris.append(np.stack([nd[0], nd[k], nd[k + 1]], axis=1))
            owner.append(g.ids)
    return np.concatenate(tris).astype(np.int64), np.concatenate(owner).astype(np.int64)


def _area2(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Twice the signed area of triangles (a, b, c)."""
    return ((p[b, 0] - p[a, 0]) * (p[c, 1] - p[a, 1])
            - (p[b, 1] - p[a, 1]) * (p[c, 0] - p[a, 0]))


def candidate_pairs(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(P, 2) index pairs i < j of boxes [lo, hi] (each (T, 2)) that overlap with positive
    extent on both axes, each pair once: a uniform grid of cells about the median box size
    (a pair is taken in the one cell holding the low corner of the boxes' intersection);
    boxes spanning many cells are compared with every box instead. Inside a cell the boxes
    are swept along x, so a dense cluster of small boxes costs its overlaps, not its
    square."""
    t = lo.shape[0]
    if t < 2:
        return np.empty((0, 2), np.int64)
    ext = np.max(hi - lo, axis=1)
    positive = ext[ext > 0]
    cell = float(np.median(positive)) if positive.size else 1.0
    origin = lo.min(axis=0)
    c0 = np.floor((lo - origin) / cell).astype(np.int64)
    c1 = np.floor((hi - origin) / cell).astype(np.int64)
    span = c1 - c0 + 1
    ncell = span[:, 0] * span[:, 1]
    big = ncell > _MAX_CELLS
    small = np.flatnonzero(~big)
    # grid: one entry per (box, cell) it covers
    counts = ncell[small]
    owner = np.repeat(small, counts)
    k = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    w = span[owner, 0]
    cx = c0[owner, 0] + k % w
    cy = c0[owner, 1] + k // w
    ny = int(c1[:, 1].max()) + 1
    # within a cell, sweep along x: an entry pairs with the later entries (sorted by their
    # box's low x) that start before its box ends. Lows and highs as ranks among the lows
    # (exact), so one integer key orders (cell, low x)
    lows = np.sort(lo[:, 0])
    r_lo = np.searchsorted(lows, lo[:, 0], side="left")
    r_hi = np.searchsorted(lows, hi[:, 0], side="left")
    cellkey = cx * ny + cy
    sweep = cellkey * (t + 1) + r_lo[owner]
    order = np.argsort(sweep, kind="stable")
    owner, cx, cy, sweep = owner[order], cx[order], cy[order], sweep[order]
    stop = np.searchsorted(sweep, cellkey[order] * (t + 1) + r_hi[owner], side="left")
    later = np.maximum(stop - np.arange(owner.size) - 1, 0)
    first = np.repeat(np.arange(owner.size), later)
    second = first + 1 + (np.arange(int(later.sum())) - np.repeat(np.cumsum(later) - later,
                                                                  later))
    a, b = owner[first], owner[second]
    home = (cx[first] == np.maximum(c0[a, 0], c0[b, 0])) & (
        cy[first] == np.maximum(c0[a, 1], c0[b, 1]))
    found = [np.stack([a[home], b[home]], axis=1)]
    # big boxes against everything, a block of them at a time (big-big pairs once)
    bigs = np.flatnonzero(big)
    block = max(1, _CHUNK // t)
    for s in range(0, bigs.size, block):
        rows = bigs[s:s + block]
        hit = ((lo[rows, None, 0] < hi[None, :, 0]) & (lo[None, :, 0] < hi[rows, None, 0])
               & (lo[rows, None, 1] < hi[None, :, 1]) & (lo[None, :, 1] < hi[rows, None, 1]))
        rr, c = np.nonzero(hit)
        once = ~big[c] | (rows[rr] < c)
        found.append(np.stack([rows[rr[once]], c[once]], axis=1))
    pairs = np.sort(np.concatenate(found), axis=1)
    i, j = pairs[:, 0], pairs[:, 1]
    keep = ((i != j) & (lo[i, 0] < hi[j, 0]) & (lo[j, 0] < hi[i, 0])
            & (lo[i, 1] < hi[j, 1]) & (lo[j, 1] < hi[i, 1]))
    return pairs[keep]


def triangles_overlap(p: np.ndarray, ta: np.ndarray, tb: np.ndarray,
                      rel_tol: float = 1e-12) -> np.ndarray:
    """(P,) whether triangles ta[k] and tb[k] (node triples) share interior area: no edge
    direction of either separates them (separating-axis test). Projections that overlap by
    at most ``rel_tol`` times the axis length and the coordinates' magnitude count as
    touching (shared edges and corners project to identical values)."""
    scale = max(float(np.abs(p).max()), np.finfo(float).tiny) if p.size else 1.0
    ax, ay = p[ta, 0], p[ta, 1]  # (P, 3)
    bx, by = p[tb, 0], p[tb, 1]
    alive = np.arange(ta.shape[0])  # pairs no axis has separated yet
    for ex, ey in ((ax, ay), (bx, by)):
        for k in range(3):
            if alive.size == 0:
                break
            nx = ey[alive, (k + 1) % 3] - ey[alive, k]  # edge normal (dy, -dx)
            ny = ex[alive, k] - ex[alive, (k + 1) % 3]
            pa = ax[alive] * nx[:, None] + ay[alive] * ny[:, None]
            pb = bx[alive] * nx[:, None] + by[alive] * ny[:, None]
            depth = np.minimum(pa.max(axis=1), pb.max(axis=1)) - np.maximum(pa.min(axis=1),
                                                                            pb.min(axis=1))
            alive = alive[depth > rel_tol * np.sqrt(nx * nx + ny * ny) * scale]
    out = np.zeros(ta.shape[0], dtype=bool)
    out[alive] = True
    return out


def overlapping_faces(points: np.ndarray, fs: FaceSet, island: np.ndarray,
                      faces: np.ndarray | None = None) -> np.ndarray:
    """(F,) bool: faces (among ``faces``, a bool mask; default all) that share interior area
    with another face of the same island (also among ``faces``). Triangles of zero area
    overlap nothing."""
    p = np.asarray(points, dtype=np.float64)
    out = np.zeros(fs.n_faces, dtype=bool)
    tri, owner = face_triangles(p, fs)
    if faces is not None:
        keep = np.asarray(faces, dtype=bool)[owner]
        tri, owner = tri[keep], owner[keep]
    if tri.shape[0] < 2:
        return out
    scale = max(float(np.abs(p).max()), np.finfo(float).tiny)
    area = np.abs(_area2(p, tri[:, 0], tri[:, 1], tri[:, 2]))
    solid = area > 1e-12 * scale * scale
    tri, owner = tri[solid], owner[solid]
    xy = p[tri]
    pairs = candidate_pairs(xy.min(axis=1), xy.max(axis=1))
    isl = np.asarray(island)[owner]
    pairs = pairs[(isl[pairs[:, 0]] == isl[pairs[:, 1]])
                  & (owner[pairs[:, 0]] != owner[pairs[:, 1]])]
    for s in range(0, pairs.shape[0], _CHUNK):
        chunk = pairs[s:s + _CHUNK]
        hit = triangles_overlap(p, tri[chunk[:, 0]], tri[chunk[:, 1]])
        out[owner[chunk[hit, 0]]] = True
        out[owner[chunk[hit, 1]]] = True
    return out
