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
_MAX_CELLS = 16  # a box over more grid cells than this is tested against every box


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


def _pairs_within_groups(items: np.ndarray, starts: np.ndarray,
                         sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every pair (i < j by position) inside each run items[start:start + size]."""
    n = int(sizes.sum())
    if n == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    pos = np.arange(n) - np.repeat(np.cumsum(sizes) - sizes, sizes)  # position in its run
    later = np.repeat(sizes, sizes) - 1 - pos  # partners after it
    first = np.repeat(np.arange(n), later)
    step = np.arange(int(later.sum())) - np.repeat(np.cumsum(later) - later, later) + 1
    idx = np.repeat(starts, sizes) + pos
    return items[idx[first]], items[idx[first] + step]


def candidate_pairs(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(P, 2) index pairs i < j of boxes [lo, hi] (each (T, 2)) that overlap with positive
    extent on both axes, each pair once: a uniform grid of cells about the median box size;
    boxes spanning many cells are compared with every box instead."""
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
    key = cx * ny + cy
    order = np.argsort(key, kind="stable")
    key, owner = key[order], owner[order]
    run = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]]))
    sizes = np.diff(np.concatenate([run, [key.size]]))
    a, b = _pairs_within_groups(owner, run, sizes)
    found = [np.stack([a, b], axis=1)]
    # big boxes against everything, a block of them at a time
    bigs = np.flatnonzero(big)
    block = max(1, _CHUNK // t)
    for s in range(0, bigs.size, block):
        rows = bigs[s:s + block]
        hit = ((lo[rows, None, 0] < hi[None, :, 0]) & (lo[None, :, 0] < hi[rows, None, 0])
               & (lo[rows, None, 1] < hi[None, :, 1]) & (lo[None, :, 1] < hi[rows, None, 1]))
        r, c = np.nonzero(hit)
        found.append(np.stack([rows[r], c], axis=1))
    pairs = np.concatenate(found)
    pairs = np.sort(pairs, axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    pairs = np.unique(pairs[:, 0] * t + pairs[:, 1])
    i, j = pairs // t, pairs % t
    keep = ((lo[i, 0] < hi[j, 0]) & (lo[j, 0] < hi[i, 0])
            & (lo[i, 1] < hi[j, 1]) & (lo[j, 1] < hi[i, 1]))
    return np.stack([i[keep], j[keep]], axis=1)


def triangles_overlap(p: np.ndarray, ta: np.ndarray, tb: np.ndarray,
                      rel_tol: float = 1e-12) -> np.ndarray:
    """(P,) whether triangles ta[k] and tb[k] (node triples) share interior area: no edge
    direction of either separates them (separating-axis test). Projections that overlap by
    at most ``rel_tol`` times the axis length and the coordinates' magnitude count as
    touching (shared edges and corners project to identical values)."""
    A = p[ta]  # (P, 3, 2)
    B = p[tb]
    scale = max(float(np.abs(p).max()), np.finfo(float).tiny) if p.size else 1.0
    ok = np.ones(ta.shape[0], dtype=bool)
    for tri in (A, B):
        for k in range(3):
            e = tri[:, (k + 1) % 3] - tri[:, k]
            axis = np.stack([e[:, 1], -e[:, 0]], axis=1)  # (P, 2) edge normal
            pa = np.einsum("pkd,pd->pk", A, axis)
            pb = np.einsum("pkd,pd->pk", B, axis)
            depth = np.minimum(pa.max(axis=1), pb.max(axis=1)) - np.maximum(pa.min(axis=1),
                                                                            pb.min(axis=1))
            length = np.sqrt((axis * axis).sum(axis=1))
            ok &= depth > rel_tol * length * scale
    return ok


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
