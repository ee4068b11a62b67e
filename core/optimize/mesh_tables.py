"""Mesh tables of the global stage: polygons stacked by arity, their corner triangles, and
the reference size of every element (what each corner's Jacobian is measured against)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from .. import fpmath

__all__ = ["Factors", "corner_factor_values", "corner_triangles", "mesh_tables", "per_arity",
           "reference_sizes"]

# Per-face target shapes for the energies: arity -> (u00, u01, u11), each (F_n, n) and
# aligned with the groups' rows; corner k's target matrix is s [[u00, u01], [0, u11]]
# (core.metrics.targets.corner_factors). None: the regular polygon everywhere.
Factors = Mapping[int, tuple[np.ndarray, np.ndarray, np.ndarray]]

SIZE_SMOOTHING = 2  # smoothing passes of the reference-size field
EDGE_PIECE = 65536  # edges per piece of the per-edge arithmetic (its temporaries stay in cache)


def mesh_tables(
    groups: Mapping[int, np.ndarray],
) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
    """Stack polygons by arity: per-arity arrays, element arity, directed edges, edge element."""
    faces: list[np.ndarray] = []
    for n in sorted(groups):
        f = np.asarray(groups[n], dtype=np.int64).reshape(-1, int(n))
        if f.shape[0] == 0:
            continue
        if n < 3:
            raise ValueError("polygons need at least 3 nodes")
        faces.append(f)
    if not faces:
        z = np.zeros(0, dtype=np.int64)
        return [], z, np.stack([z, z]), z
    n_edges = sum(f.size for f in faces)
    edges = np.empty((2, n_edges), dtype=np.int64)  # filled in place: no stacked copies
    arity = np.empty(sum(f.shape[0] for f in faces), dtype=np.int64)
    edge_elem = np.empty(n_edges, dtype=np.int64)
    base = at = 0
    for f in faces:
        m, n = f.shape
        arity[base : base + m] = n
        edges[0, at : at + f.size].reshape(m, n)[:] = f
        f.take(np.roll(np.arange(n), -1), axis=1, out=edges[1, at : at + f.size].reshape(m, n))
        edge_elem[at : at + f.size].reshape(m, n)[:] = np.arange(base, base + m)[:, None]
        base, at = base + m, at + f.size
    return faces, arity, edges, edge_elem


def corner_triangles(
    faces: list[np.ndarray], all_corners: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Corner triangles (k, k+1, k-1) and their element ids; triangles give one corner unless
    all_corners (used for the validity count, where it does not matter either)."""
    i0, i1, i2, eid = [], [], [], []
    base = 0
    for f in faces:
        m, n = f.shape
        for k in range(n) if (n > 3 or all_corners) else range(1):
            i0.append(f[:, k])
            i1.append(f[:, (k + 1) % n])
            i2.append(f[:, (k - 1) % n])
            eid.append(base + np.arange(m, dtype=np.int64))
        base += m
    if not i0:
        z = np.zeros(0, dtype=np.int64)
        return z, z, z, z
    return np.concatenate(i0), np.concatenate(i1), np.concatenate(i2), np.concatenate(eid)


def corner_factor_values(
    groups: Mapping[int, np.ndarray], factors: Factors, all_corners: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u00, u01, u11) of every corner triangle, in `corner_triangles`' order."""
    parts: tuple[list[np.ndarray], ...] = ([], [], [])
    for n in sorted(groups):
        if np.asarray(groups[n]).size == 0:
            continue
        for part, u in zip(parts, factors[n], strict=True):
            u = np.asarray(u, dtype=np.float64).reshape(-1, int(n))
            part.extend(u[:, k] for k in (range(n) if (n > 3 or all_corners) else range(1)))
    if not parts[0]:
        z = np.zeros(0)
        return z, z, z
    return tuple(np.concatenate(part) for part in parts)  # type: ignore[return-value]


def per_arity(arity: np.ndarray, fn: Callable[[int], Any]) -> np.ndarray:
    """fn(n) (a float or a tuple of floats) for each entry of an integer arity array,
    evaluated once per distinct n; tuples give one column each."""
    top = int(arity.max()) if arity.size else 0
    if top <= 64:  # the usual case: a lookup table (no sort); rows below 3 are never read
        table = np.array([fn(max(n, 3)) for n in range(top + 1)], dtype=np.float64)
        return table[arity]
    values, inverse = np.unique(arity, return_inverse=True)
    return np.array([fn(int(n)) for n in values], dtype=np.float64)[inverse]


def reference_sizes(
    points: np.ndarray, arity: np.ndarray, edges: np.ndarray, edge_elem: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Reference edge length per element and the smoothed node size.

    Node size = mean length of its incident edges; element size = geometric mean of its
    nodes' sizes, smoothed SIZE_SMOOTHING times through the nodes; then one global factor so
    the regular reference polygons add up to the domain area (which folds cannot change).
    Per-edge arithmetic runs in cache-sized pieces into two edge-length buffers that the
    later gathers reuse (fresh arrays of a million edges cost more to map than to fill).
    """
    n_nodes = points.shape[0]
    n_elem = arity.shape[0]
    x, y = np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1])
    tail, head = edges[0], edges[1]
    m = tail.size
    elen, cross = np.empty(m), np.empty(m)
    for lo in range(0, m, EDGE_PIECE):
        k = slice(lo, min(m, lo + EDGE_PIECE))
        x0, y0, x1, y1 = x.take(tail[k]), y.take(tail[k]), x.take(head[k]), y.take(head[k])
        dx, dy = x1 - x0, y1 - y0
        np.sqrt(dx * dx + dy * dy, out=elen[k])
        np.subtract(x0 * y1, x1 * y0, out=cross[k])
    dom_area = 0.5 * fpmath.add_reduce(cross)
    positive = elen[elen > 0]
    floor = 1e-3 * (fpmath.add_reduce(positive) / positive.size if positive.size else 1.0)
    del positive
    np.maximum(elen, floor, out=elen)
    cnt = np.bincount(tail, minlength=n_nodes).astype(np.float64)
    hn = np.bincount(tail, weights=elen, minlength=n_nodes)
    hn += np.bincount(head, weights=elen, minlength=n_nodes)
    hn /= np.maximum(2.0 * cnt, 1.0)
    hn = np.maximum(hn, floor, out=hn)
    lh = fpmath.log(np.append(hn, floor))  # the floor's log in the same call
    lh, log_floor = lh[:-1], float(lh[-1])
    deg = arity.astype(np.float64)
    gathered = elen  # per-edge scratch from here on
    le = np.bincount(edge_elem, weights=lh.take(tail, out=gathered), minlength=n_elem) / deg
    for _ in range(SIZE_SMOOTHING):
        lh = np.bincount(tail, weights=le.take(edge_elem, out=gathered), minlength=n_nodes)
        lh = np.where(cnt > 0, lh / np.maximum(cnt, 1.0), log_floor)
        le = np.bincount(edge_elem, weights=lh.take(tail, out=gathered), minlength=n_elem) / deg
    size = fpmath.exp(le)
    ref_area = arity * size**2 / (4.0 * per_arity(arity, fpmath.tan_pi_over))
    total = fpmath.add_reduce(ref_area)
    if dom_area > 0.0 and total > 0.0:
        size = size * np.sqrt(dom_area / total)
    return size, fpmath.exp(lh)
