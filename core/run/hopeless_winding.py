"""Parts of a mesh whose fixed boundary winds negatively around some point, found before
the run: no positions of their free nodes make every face valid.

A mesh whose faces are all valid (every corner turns left) covers each point y off its
boundary exactly w(y) times, w the winding number around y of its boundary chain (each
boundary edge walked the way its face walks it): the faces over y each count once, with
their orientation, in the degree of the map, and the degree is that winding number. So
where the chain winds negatively, no valid mesh exists with that boundary. When every node
on the boundary of a connected part is held, the chain is fixed and one such point
certifies the part hopeless: a wall slid through the far field or a periodic boundary, a
border dragged across itself. Its free nodes are held (its inverted faces frozen and
reported with two of its boundary edges that cross), and the rest of the mesh is run as
usual; without the certificate the optimizer searches until it gives up (a 22 766-cell
stator whose blade was slid across its periodic boundary: 457 s, docs/repair.md).

Only crossings of the boundary are examined, and only those of boundary edges with a node
on an inverted face (`MAX_PAIRS` edge pairs at most): the four points around each crossing,
a small step from it along both edges, have the windings w, w + 1, w - 1 (or w + 2, ...),
one of them the lowest near the crossing. A part whose boundary winds negatively without
crossing itself (a hole moved wholly outside its outer boundary) is left to the optimizer.
The work is done in the boundary's own frame (from one of its nodes, scaled by a power of
two to about 1: no overflow whatever the units), and a point is used only well away from
every boundary edge (`CLEAR` in that frame), so a rounding error cannot change its winding
number. NumPy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..mesh.faces import FaceSet, face_subset, next_corner
from ..mesh.topology import EdgeInfo
from ..metrics.face_quality import inverted_corners
from ..uv.uv_layout import components
from .repair import touching

__all__ = ["HopelessWinding", "hopeless_winding", "hopeless_winding_note"]

MAX_PAIRS = 1 << 24  # (edge near a fold, boundary edge) pairs tested at most
STEP = 1e-3  # the points around a crossing: this x the shorter edge along each edge
CLEAR = 1e-9  # ... used only this far or farther from every boundary edge (boundary's frame)


@dataclass(frozen=True)
class HopelessWinding:
    """The held nodes (ascending) and, per certified part, two of its boundary edges that
    cross (node ids a, b, c, d: edges a - b and c - d, in the caller's numbering), the
    boundary's winding number beside that crossing (< 0) and the part's face count."""

    nodes: np.ndarray
    parts: tuple[tuple[int, int, int, int, int, int], ...]


_NONE = HopelessWinding(np.zeros(0, dtype=np.int64), ())


def hopeless_winding(p: np.ndarray, fs: FaceSet, free: np.ndarray,
                     edges: EdgeInfo | None = None) -> HopelessWinding:
    """The free nodes of the connected parts whose boundary is held and winds negatively
    around a point beside one of its crossings (module docstring). `p`: (N, 2+) points,
    `free`: (N,) bool movable nodes, `edges`: the faces' EdgeInfo when the caller has it."""
    p = np.asarray(p, dtype=np.float64)[:, :2]
    n = p.shape[0]
    lo, hi, net = (edges if edges is not None else EdgeInfo(fs, n)).open_edges()
    if lo.size < 3:
        return _NONE
    # the boundary's own frame: from one of its nodes, scaled by a power of two to about 1
    # (no overflow at any units; a point is only used well clear of every edge)
    origin = p[lo[0]].copy()
    reach = float(np.max(np.abs(np.concatenate([p[lo], p[hi]]) - origin)))
    if not 0.0 < reach < np.inf:
        return _NONE
    unit = math.ldexp(1.0, math.frexp(reach)[1])
    near = _near_inverted(p, fs, lo, hi, origin, unit)
    cand = np.flatnonzero(near[lo] | near[hi])
    if cand.size == 0 or cand.size * lo.size > MAX_PAIRS:
        return _NONE
    a, b = (p[lo] - origin) / unit, (p[hi] - origin) / unit
    pts, pairs = _beside_crossings(a, b, cand)
    clear = _clear_of(pts, a, b, CLEAR)
    pts, pairs = pts[clear], pairs[clear]
    w = _winding(pts, a, b, net)
    if not (w < 0).any():
        return _NONE
    return _certified(fs, free, lo, hi, a, b, net, pts[w < 0], pairs[w < 0])


def _near_inverted(p: np.ndarray, fs: FaceSet, lo: np.ndarray, hi: np.ndarray,
                   origin: np.ndarray, unit: float) -> np.ndarray:
    """(N,) bool: the nodes of the inverted faces among those touching the boundary edges
    lo - hi (only those can put a boundary edge near a fold: O(boundary), not O(mesh)),
    judged in the frame (p - origin) / unit."""
    on = np.zeros(p.shape[0], dtype=bool)
    on[lo] = on[hi] = True
    ids = np.flatnonzero(touching(fs, on))
    sub, nodes, _ = face_subset(fs, ids)
    near = np.zeros(p.shape[0], dtype=bool)
    bad = inverted_corners((p[nodes] - origin) / unit, sub)
    for g in sub.groups:
        near[nodes[g.nodes[:, bad[g.ids]]]] = True
    return near


def _beside_crossings(a: np.ndarray, b: np.ndarray, cand: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """((K, 2) points, (K, 2) the two crossing edges of each): points around the proper
    crossings of the edges `cand` with every edge a -> b, four per crossing, STEP x the
    shorter edge from it along each edge, either way."""
    out, pairs = [], []
    for sl in _chunks(cand.size, a.shape[0]):
        i = cand[sl][:, None]
        j = np.arange(a.shape[0])[None, :]
        d1, d2 = b[i] - a[i], b[j] - a[j]  # (I, 1, 2), (1, E, 2)
        r = a[j] - a[i]
        den = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (r[..., 0] * d2[..., 1] - r[..., 1] * d2[..., 0]) / den
            t = (r[..., 0] * d1[..., 1] - r[..., 1] * d1[..., 0]) / den
        hit = (den != 0.0) & (s > 0.0) & (s < 1.0) & (t > 0.0) & (t < 1.0)
        ii, jj = np.nonzero(hit)
        if ii.size == 0:
            continue
        e1, e2 = d1[ii, 0], d2[0, jj]
        x = a[cand[sl]][ii] + s[ii, jj][:, None] * e1
        l1 = np.sqrt(e1[:, 0] * e1[:, 0] + e1[:, 1] * e1[:, 1])
        l2 = np.sqrt(e2[:, 0] * e2[:, 0] + e2[:, 1] * e2[:, 1])
        h = (STEP * np.minimum(l1, l2))[:, None]
        u1, u2 = h * e1 / l1[:, None], h * e2 / l2[:, None]
        out += [x + u1 + u2, x + u1 - u2, x - u1 + u2, x - u1 - u2]
        pairs += [np.column_stack([cand[sl][ii], jj])] * 4
    if not out:
        return np.zeros((0, 2)), np.zeros((0, 2), dtype=np.int64)
    return np.concatenate(out), np.concatenate(pairs)


def _chunks(k: int, e: int):
    """Slices of k items (points, edges) met with each of e edges, so that each slice holds
    about MAX_PAIRS / 16 pairs."""
    rows = max(1, MAX_PAIRS // 16 // max(e, 1))
    return (slice(lo, min(k, lo + rows)) for lo in range(0, k, rows))


def _clear_of(q: np.ndarray, a: np.ndarray, b: np.ndarray, gap: float) -> np.ndarray:
    """(K,) bool: points farther than `gap` from every segment a -> b."""
    keep = np.ones(q.shape[0], dtype=bool)
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    dd = np.maximum(dx * dx + dy * dy, np.finfo(float).tiny)
    for sl in _chunks(q.shape[0], a.shape[0]):
        rx, ry = q[sl, 0:1] - a[:, 0], q[sl, 1:2] - a[:, 1]  # (k, E)
        t = np.clip((rx * dx + ry * dy) / dd, 0.0, 1.0)
        ox, oy = rx - t * dx, ry - t * dy
        keep[sl] = np.min(ox * ox + oy * oy, axis=1) > gap * gap
    return keep


def _winding(q: np.ndarray, a: np.ndarray, b: np.ndarray, net: np.ndarray,
             label: np.ndarray | None = None, n_labels: int = 1) -> np.ndarray:
    """Winding numbers around the points q of the chain of edges a -> b walked `net` times:
    (K,) int, or (K, n_labels) per edge `label` (the crossing rule: an edge crossing the
    horizontal line through q upwards, with q on its left, adds its count; downwards, with
    q on its right, takes it away)."""
    out = np.zeros((q.shape[0], n_labels), dtype=np.int64)
    lab = np.zeros(a.shape[0], dtype=np.int64) if label is None else label
    m = np.rint(net).astype(np.int64)
    for sl in _chunks(q.shape[0], a.shape[0]):
        x, y = q[sl, 0:1], q[sl, 1:2]  # (k, 1)
        left = (b[:, 0] - a[:, 0]) * (y - a[:, 1]) - (x - a[:, 0]) * (b[:, 1] - a[:, 1])
        up = (a[:, 1] <= y) & (b[:, 1] > y) & (left > 0.0)
        down = (a[:, 1] > y) & (b[:, 1] <= y) & (left < 0.0)
        step = m * (up.astype(np.int64) - down)  # (k, E)
        k = step.shape[0]
        bins = (np.arange(k)[:, None] * n_labels + lab[None, :]).ravel()
        out[sl] = np.bincount(bins, step.ravel(), k * n_labels).reshape(k, n_labels)
    return out[:, 0] if label is None else out


def _certified(fs: FaceSet, free: np.ndarray, lo: np.ndarray, hi: np.ndarray, a: np.ndarray,
               b: np.ndarray, net: np.ndarray, pts: np.ndarray, pairs: np.ndarray
               ) -> HopelessWinding:
    """The parts (connected through their faces) whose own boundary is held and winds
    negatively around one of the points `pts` (the boundary's frame, edges a -> b; `pairs`:
    the two boundary edges crossing beside each): their free nodes and a witness each."""
    part = components(free.size, fs.indices, fs.indices[next_corner(fs)])  # by face edges
    k = int(part.max()) + 1
    w = _winding(pts, a, b, net, part[lo], k)  # (K, parts)
    # every boundary node of the part held (an edge's two nodes are in one part)
    whole = np.bincount(part[lo], free[lo] | free[hi], k) == 0
    n_faces = np.bincount(part[fs.indices[fs.offsets[:-1]]], minlength=k)  # first corners
    nodes, parts = [], []
    for c in np.flatnonzero(whole & (w < 0).any(axis=0)):
        i = int(np.argmin(w[:, c]))
        members = np.flatnonzero((part == c) & free)
        if members.size == 0:
            continue
        nodes.append(members)
        e, f = pairs[i]
        parts.append((int(lo[e]), int(hi[e]), int(lo[f]), int(hi[f]), int(w[i, c]),
                      int(n_faces[c])))
    if not nodes:
        return _NONE
    return HopelessWinding(np.sort(np.concatenate(nodes)), tuple(parts))


def hopeless_winding_note(h: HopelessWinding) -> str:
    """The clause that tells why a certified part's free nodes are held."""
    if not h.parts:
        return ""

    def one(a: int, b: int, c: int, d: int, w: int, faces: int) -> str:
        return (f"the fixed boundary of {faces} faces crosses itself (its edges {a}-{b} and "
                f"{c}-{d}) and winds {w} times beside that crossing: faces that are all "
                "valid cover each point as many times as their boundary winds around it, so "
                "no positions of their free vertices make them valid (their free vertices "
                "are held)")

    more = len(h.parts) - 2
    return "; ".join(one(*t) for t in h.parts[:2]) + (f"; {more} more such parts"
                                                       if more > 0 else "")
