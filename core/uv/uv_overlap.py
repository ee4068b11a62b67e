"""Overlaps inside UV islands: faces that cover part of another face of the same island.

Flipped faces (inverted in their island's orientation) are the visible half of a fold; the
other half is made of valid-looking faces lying over their neighbours, which no orientation
test sees. This module finds them directly: faces are split into triangles, a uniform grid
proposes pairs whose bounding boxes meet, and the separating-axis test keeps the pairs whose
interiors overlap (touching along a shared edge or corner is no overlap). Faces the caller
knows to be valid simple polygons that need not be convex (``exact``: the faces with a
corner kept as given, ``core.metrics.kept``, such as an L-shaped hexagon) are cut into
triangles inside them (ear clipping), not fanned across their notch. Faces of different
islands are never compared: where islands lie relative to each other is the layout's
business, not a tangle. NumPy only, vectorized over triangles and pairs.
"""

from __future__ import annotations

import numpy as np

from ..mesh.faces import FaceSet

__all__ = ["candidate_pairs", "face_triangles", "overlapping_faces", "triangles_overlap"]

_CHUNK = 1 << 20  # pairs per narrow-phase batch (memory bound)
_MAX_CELLS = 64  # a box over more grid cells than this is tested against every box


def face_triangles(points: np.ndarray, fs: FaceSet,
                   exact: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """((T, 3) nodes, (T,) face) triangles covering every face: a quad is cut along the
    diagonal whose two triangles turn the same way (its interior one), other n-gons are
    fanned from their first corner (exact for the convex faces of a valid layout), but the
    n-gons of ``exact`` ((F,) bool: simple counterclockwise polygons, convex or not), which
    are cut by ear clipping (exact for them)."""
    tris, owner = [], []
    ears = np.zeros(fs.n_faces, dtype=bool) if exact is None else \
        np.asarray(exact, dtype=bool)
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
        clip = ears[g.ids]
        fan, ids = nd[:, ~clip], g.ids[~clip]
        for k in range(1, g.n - 1):
            tris.append(np.stack([fan[0], fan[k], fan[k + 1]], axis=1))
            owner.append(ids)
        for col in np.flatnonzero(clip):
            cut = _ear_clipped(points, nd[:, col])
            tris.append(cut)
            owner.append(np.full(cut.shape[0], g.ids[col]))
    return np.concatenate(tris).astype(np.int64), np.concatenate(owner).astype(np.int64)


def _ear_clipped(points: np.ndarray, ring: np.ndarray) -> np.ndarray:
    """(n - 2, 3) triangles of a simple counterclockwise polygon (its nodes ``ring``) that
    cover it exactly: ears (a convex corner whose triangle holds no other vertex of the
    polygon, its border included) cut off one at a time; the rest fanned if none is left
    (a polygon that is not simple after all). Straight corners are never ears (their
    triangle has no area)."""
    idx = [int(v) for v in ring]
    out = []

    def orient(a: int, b: int, c: int) -> float:
        return float((points[b, 0] - points[a, 0]) * (points[c, 1] - points[a, 1])
                     - (points[b, 1] - points[a, 1]) * (points[c, 0] - points[a, 0]))

    while len(idx) > 3:
        m = len(idx)
        for k in range(m):
            a, b, c = idx[k - 1], idx[k], idx[(k + 1) % m]
            if orient(a, b, c) <= 0.0:
                continue
            if any(orient(a, b, v) >= 0.0 and orient(b, c, v) >= 0.0 and orient(c, a, v) >= 0.0
                   for v in idx if v not in (a, b, c)):
                continue
            out.append((a, b, c))
            del idx[k]
            break
        else:
            break
    out += [(idx[0], idx[k], idx[k + 1]) for k in range(1, len(idx) - 1)]
    return np.array(out, dtype=np.int64).reshape(-1, 3)


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
    """(P,) whether triangles ta[k] and tb[k] (node triples, each of nonzero area) share
    interior area. Neighbours across an edge overlap exactly when their third corners lie
    on the same side of that edge; any other pair when no edge direction of either
    separates them (separating-axis test). Overlaps up to ``rel_tol`` times the
    coordinates' magnitude count as touching (shared edges and corners project to
    identical values)."""
    scale = max(float(np.abs(p).max()), np.finfo(float).tiny) if p.size else 1.0
    out = np.zeros(ta.shape[0], dtype=bool)
    eq = ta[:, :, None] == tb[:, None, :]  # (P, 3, 3): corner i of a is corner j of b
    shared = eq.sum(axis=(1, 2))
    out[shared == 3] = True  # the same triangle twice
    edge = np.flatnonzero(shared == 2)
    if edge.size:
        ina, inb = eq[edge].any(axis=2), eq[edge].any(axis=1)
        rows = np.arange(edge.size)
        c = ta[edge, np.argmin(ina, axis=1)]  # the corner of a off the shared edge
        d = tb[edge, np.argmin(inb, axis=1)]
        ends = np.sort(np.where(ina, ta[edge], -1), axis=1)[:, 1:]  # the shared edge
        e0, e1 = ends[rows, 0], ends[rows, 1]
        ex, ey = p[e1, 0] - p[e0, 0], p[e1, 1] - p[e0, 1]
        sc = ex * (p[c, 1] - p[e0, 1]) - ey * (p[c, 0] - p[e0, 0])
        sd = ex * (p[d, 1] - p[e0, 1]) - ey * (p[d, 0] - p[e0, 0])
        tol = rel_tol * np.sqrt(ex * ex + ey * ey) * scale
        out[edge] = ((sc > tol) & (sd > tol)) | ((sc < -tol) & (sd < -tol))
    alive = np.flatnonzero(shared < 2)  # pairs no axis has separated yet
    # corner coordinates as 1D columns: a's x0 x1 x2 y0 y1 y2, then b's (contiguous, fast)
    cols = [p[t[alive, k], d] for t in (ta, tb) for d in (0, 1) for k in range(3)]
    for axis in range(6):
        if alive.size == 0:
            break
        own = 0 if axis < 3 else 6  # the triangle whose edge k gives the axis
        x, y, k = cols[own:own + 3], cols[own + 3:own + 6], axis % 3
        nx = y[(k + 1) % 3] - y[k]  # edge normal (dy, -dx)
        ny = x[k] - x[(k + 1) % 3]
        pa = [cols[i] * nx + cols[3 + i] * ny for i in range(3)]
        pb = [cols[6 + i] * nx + cols[9 + i] * ny for i in range(3)]
        hi = np.minimum(np.maximum(np.maximum(pa[0], pa[1]), pa[2]),
                        np.maximum(np.maximum(pb[0], pb[1]), pb[2]))
        lo = np.maximum(np.minimum(np.minimum(pa[0], pa[1]), pa[2]),
                        np.minimum(np.minimum(pb[0], pb[1]), pb[2]))
        keep = hi - lo > rel_tol * np.sqrt(nx * nx + ny * ny) * scale
        if not keep.all():
            alive = alive[keep]
            cols = [c[keep] for c in cols]
    out[alive] = True
    return out


def overlapping_faces(points: np.ndarray, fs: FaceSet, island: np.ndarray,
                      faces: np.ndarray | None = None,
                      exact: np.ndarray | None = None) -> np.ndarray:
    """(F,) bool: faces (among ``faces``, a bool mask; default all) that share interior area
    with another face of the same island (also among ``faces``). Triangles of zero area
    overlap nothing. ``exact``: (F,) bool, faces that are simple polygons to cut inside
    themselves (``face_triangles``; the faces with a corner kept as given)."""
    p = np.asarray(points, dtype=np.float64)
    out = np.zeros(fs.n_faces, dtype=bool)
    tri, owner = face_triangles(p, fs, exact)
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
