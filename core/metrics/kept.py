"""Corners kept as given (docs/method.md 3, "What counts as inverted"): the one rule for which
faces are inverted outside the paper's mode.

A face is inverted when its signed area is not positive or when a corner that a move can
change (one of its three vertices is free) is folded (det <= 0). A corner whose three
vertices are all fixed and which is straight (180 degrees: a knife cut or a partial loop cut
leaves a vertex in the middle of an edge) or concave (the reentrant corner of an L-shaped
n-gon) is *kept as given* when the face is a simple counterclockwise polygon: no move can
change it, and a polygonal solver or Blender takes the face as valid.

Quality of a face with kept corners: the mean ratio of the polygon of its other vertices
(the kept vertices left out, one at a time until no straight or concave corner of fixed
vertices only is left). A straight vertex left out leaves the same shape (a pentagon with a
vertex in the middle of an edge is measured as the quad it looks like); a concave one is
measured by the face's outline across the notch (an L-shaped hexagon as the pentagon that
spans its reentrant corner): the part of the face that moves can shape. The face is
moreover inverted (quality 0) when its signed area is not positive or a corner of the face
itself that is not kept is folded, whatever its outline.

The rule depends on which vertices are fixed, so it is decided once per run from the input
(`kept_corners`), and every measurement of the run goes through `Kept` (the faces measured,
`measured`, and the check of the face itself, `check`). A mesh without such corners has
no `Kept` (None) and is measured exactly as before, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mesh.faces import FaceSet, as_faceset

__all__ = ["FixedCorners", "Kept", "fixed_corners", "kept_corners", "kept_note"]


@dataclass(frozen=True)
class FixedCorners:
    """One arity group's faces with a fixed node (`cols`, columns of the group) and their
    corners: `det` ((n, len(cols)) > 0 where the face turns counterclockwise), `nxt` / `prv`
    the next and previous corner's nodes, `fix` / `fix_n` / `fix_p` whether the corner's,
    the next and the previous node are fixed. A corner made of fixed nodes only
    (`fix & fix_n & fix_p`) with `det <= 0` is one that no move can change: frozen
    (core.run.pipeline.frozen_faces) or kept as given (`kept_corners`)."""

    cols: np.ndarray
    nodes: np.ndarray
    nxt: np.ndarray
    prv: np.ndarray
    det: np.ndarray
    fix: np.ndarray
    fix_n: np.ndarray
    fix_p: np.ndarray

    @property
    def unchangeable(self) -> np.ndarray:
        """(n, len(cols)) bool: corners of fixed nodes only that are straight or folded."""
        return self.fix & self.fix_n & self.fix_p & (self.det <= 0.0)


def fixed_corners(x: np.ndarray, y: np.ndarray, g, free: np.ndarray) -> FixedCorners:
    """The `FixedCorners` of arity group `g` at the points (x, y) with movable nodes `free`
    (only faces with a fixed node can have a corner no move changes)."""
    fixed = ~free[g.nodes]
    cols = np.flatnonzero(fixed.any(axis=0))
    nodes = g.nodes[:, cols]
    nxt, prv = np.roll(nodes, -1, axis=0), np.roll(nodes, 1, axis=0)
    det = (x[nxt] - x[nodes]) * (y[prv] - y[nodes]) - (y[nxt] - y[nodes]) * (
        x[prv] - x[nodes])
    return FixedCorners(cols, nodes, nxt, prv, det, fixed[:, cols], ~free[nxt], ~free[prv])


@dataclass(frozen=True)
class Kept:
    """The kept corners of a mesh: `faces` (the caller's), `measured` (the same faces with the
    kept vertices left out, same face numbers), `corner` ((n_corners,) bool in the caller's
    corner order: left out), `ids` (the faces with a kept corner), `n_straight` and
    `n_concave` (kept corners of each kind)."""

    faces: FaceSet
    measured: FaceSet
    corner: np.ndarray
    ids: np.ndarray
    n_straight: int
    n_concave: int

    @property
    def n_faces(self) -> int:
        """Faces with a kept corner."""
        return int(self.ids.size)

    def check(self, points: np.ndarray, q: np.ndarray) -> np.ndarray:
        """`q` ((F,) quality of `measured`) with 0 for the faces with a kept corner whose
        signed area is not positive or whose own corners that are not kept fold."""
        p = np.asarray(points, dtype=np.float64)
        q = q.copy()
        for f in self.ids:
            a, b = int(self.faces.offsets[f]), int(self.faces.offsets[f + 1])
            ring = p[self.faces.indices[a:b], :2]
            det = _corner_dets(ring)
            if not (_area2(ring) > 0.0 and (det[~self.corner[a:b]] > 0.0).all()):
                q[f] = 0.0
        return q


def kept_note(kept: Kept) -> str:
    """The sentence that reports the faces kept as given (the run's message)."""
    n = kept.n_faces
    kinds = [f"{k} {w}" for k, w in ((kept.n_straight, "straight"), (kept.n_concave, "concave"))
             if k]
    return (f"{n} face{'s' if n != 1 else ''} kept as given ({' and '.join(kinds)} corner"
            f"{'s' if kept.n_straight + kept.n_concave != 1 else ''} of fixed vertices only: "
            "valid, measured without those vertices)")


def kept_corners(points: np.ndarray, faces, free: np.ndarray) -> Kept | None:
    """The corners kept as given (module docstring) of the faces at `points` (the caller's
    coordinates: where the signs are judged) with the movable nodes `free`; None when there
    are none."""
    p = np.asarray(points, dtype=np.float64)
    fs = as_faceset(faces, p.shape[0])
    x, y = p[:, 0], p[:, 1]
    candidates = []
    for g in fs.groups:
        fc = fixed_corners(x, y, g, free)
        candidates.append(g.ids[fc.cols[fc.unchangeable.any(axis=0)]])
    ids = np.sort(np.concatenate(candidates)) if candidates else np.zeros(0, np.int64)
    if ids.size == 0:
        return None
    corner = np.zeros(fs.n_corners, dtype=bool)
    kept_ids, n_straight, n_concave = [], 0, 0
    for f in ids:
        a, b = int(fs.offsets[f]), int(fs.offsets[f + 1])
        nodes = fs.indices[a:b]
        left = _left_out(p[nodes, :2], ~free[nodes])
        if left is None:
            continue
        corner[a:b] = left
        kept_ids.append(int(f))
        dets = _corner_dets(p[nodes, :2])[left]
        n_straight += int(np.count_nonzero(dets == 0.0))
        n_concave += int(np.count_nonzero(dets != 0.0))  # concave here or once measured
    if not kept_ids:
        return None
    offsets = np.concatenate([[0], np.cumsum(fs.counts - np.add.reduceat(
        corner.astype(np.int64), fs.offsets[:-1]))])
    measured = FaceSet(offsets, fs.indices[~corner], p.shape[0])
    return Kept(fs, measured, corner, np.asarray(kept_ids, dtype=np.int64), n_straight,
                n_concave)


def _corner_dets(ring: np.ndarray) -> np.ndarray:
    """(n,) det of each corner of a polygon (> 0: counterclockwise there)."""
    nxt, prv = np.roll(ring, -1, axis=0) - ring, np.roll(ring, 1, axis=0) - ring
    return nxt[:, 0] * prv[:, 1] - nxt[:, 1] * prv[:, 0]


def _area2(ring: np.ndarray) -> float:
    """Twice the signed area of a polygon."""
    x, y = ring[:, 0], ring[:, 1]
    return float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _simple(ring: np.ndarray) -> bool:
    """No two edges of the polygon meet but neighbours at their shared vertex (and no
    vertex repeats)."""
    n = ring.shape[0]
    if np.unique(ring, axis=0).shape[0] != n:
        return False
    for i in range(n):
        a, b = ring[i], ring[(i + 1) % n]
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue
            if _segments_meet(a, b, ring[j], ring[(j + 1) % n]):
                return False
    return True


def _orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def _on_segment(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> bool:
    """c, collinear with a and b, lies on the segment ab."""
    return bool(min(a[0], b[0]) <= c[0] <= max(a[0], b[0])
                and min(a[1], b[1]) <= c[1] <= max(a[1], b[1]))


def _segments_meet(a, b, c, d) -> bool:
    """The closed segments ab and cd have a point in common."""
    o1, o2, o3, o4 = _orient(a, b, c), _orient(a, b, d), _orient(c, d, a), _orient(c, d, b)
    if ((o1 > 0) != (o2 > 0)) and ((o3 > 0) != (o4 > 0)) and 0 not in (o1, o2, o3, o4):
        return True
    return ((o1 == 0 and _on_segment(a, b, c)) or (o2 == 0 and _on_segment(a, b, d))
            or (o3 == 0 and _on_segment(c, d, a)) or (o4 == 0 and _on_segment(c, d, b)))


def _left_out(ring: np.ndarray, fixed: np.ndarray) -> np.ndarray | None:
    """(n,) bool: the vertices left out of a face's measure, or None when the face is not a
    simple counterclockwise polygon or what is left still has a corner of fixed vertices
    only that is not convex (then nothing is kept: the face is frozen as before)."""
    n = ring.shape[0]
    if not (_area2(ring) > 0.0 and _simple(ring)):
        return None
    left = np.zeros(n, dtype=bool)
    order = list(range(n))
    while len(order) > 3:
        sub = ring[order]
        det = _corner_dets(sub)
        fx = fixed[order]
        stuck = fx & np.roll(fx, -1) & np.roll(fx, 1) & (det <= 0.0)
        if not stuck.any():
            break
        k = int(np.flatnonzero(stuck)[0])
        left[order[k]] = True
        del order[k]
    sub = ring[order]
    det = _corner_dets(sub)
    fx = fixed[order]
    if (fx & np.roll(fx, -1) & np.roll(fx, 1) & (det <= 0.0)).any() or not _area2(sub) > 0.0:
        return None
    return left if left.any() else None
