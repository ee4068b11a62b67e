"""Consistent face orientation: which faces to reverse so that every interior edge is walked
once in each direction (what `topology.free_nodes` requires), for meshes whose files store
faces clockwise, counterclockwise or mixed (FEM element node orders often are).

Two faces sharing an interior edge (an edge of exactly two faces) must walk it in opposite
directions: each such edge says whether its two faces keep the same orientation or opposite
ones. Those relations are solved for every connected component at once by a vectorized
union-find (hooking of roots onto smaller roots, then pointer jumping, carrying each face's
parity relative to its root), no Python loop per face or per component. A relation that
contradicts the others closes a loop of faces that comes back reversed: the surface is not
orientable (a Moebius-like strip) and is refused with one line.

Edges of one face (boundary) or of more than two (non-manifold) relate nothing: the core
holds their nodes anyway and asks nothing of their directions, so the components are joined
through manifold edges only.

Each component's orientation is then chosen by topology, not by each face's own sign: its
faces oriented consistently, its total signed area is the area its boundary encloses, which
folded (tangled) faces inside it do not change; the component is turned so that this area is
positive (in 3D: so that its vector area points the way of the mesh's normal, the axis of
that normal's largest coordinate positive, z first on a tie). Without points each
component keeps the order of its first face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .faces import FaceSet, as_faceset, next_corner

__all__ = ["FaceOrientation", "orient_faces", "reverse_faces"]


@dataclass(frozen=True)
class FaceOrientation:
    """The faces to reverse (`flip`, (F,) bool) and the connected components through
    manifold edges (`component`, (F,) int64 in 0..n_components-1, numbered by their first
    face)."""

    flip: np.ndarray
    component: np.ndarray
    n_components: int

    @property
    def n_flipped(self) -> int:
        return int(np.count_nonzero(self.flip))

    def apply(self, faces: FaceSet) -> FaceSet:
        """`faces` with the flipped faces reversed (`reverse_faces`)."""
        return reverse_faces(faces, self.flip)


def reverse_faces(faces: FaceSet, flip: np.ndarray) -> FaceSet:
    """The same faces in the same order with the corner order of the `flip`ped ones reversed
    (each keeps its first corner: a b c d -> a d c b). `faces` itself when none is."""
    flip = np.asarray(flip, dtype=bool)
    if flip.shape != (faces.n_faces,):
        raise ValueError(f"flip must be an ({faces.n_faces},) bool array, got shape {flip.shape}")
    if not flip.any():
        return faces
    start = np.repeat(faces.offsets[:-1], faces.counts)
    count = np.repeat(faces.counts, faces.counts)
    pos = np.arange(faces.n_corners, dtype=np.int64) - start
    src = np.where(np.repeat(flip, faces.counts), start + (count - pos) % count, start + pos)
    out = FaceSet(faces.offsets, faces.indices[src])
    out._valid_from = faces._valid_from  # the same nodes in each face: the same checks hold
    return out


def _relations(fs: FaceSet, n_nodes: int) -> tuple[np.ndarray, ...]:
    """The manifold edges as relations: (face f, face g, same, lo, hi) per edge of exactly
    two faces, `same` when both walk it the same way (f and g need opposite orientations)."""
    a = fs.indices
    b = a[next_corner(fs)]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * n_nodes + hi
    order = np.argsort(key)  # which of an edge's two corners comes first does not matter
    ks = key[order]
    start = np.flatnonzero(np.concatenate([[True], ks[1:] != ks[:-1]]))
    count = np.diff(np.append(start, ks.size))
    pair = start[count == 2]
    c0, c1 = order[pair], order[pair + 1]
    face_of = np.repeat(np.arange(fs.n_faces, dtype=np.int64), fs.counts)
    same = (a[c0] < b[c0]) == (a[c1] < b[c1])
    return face_of[c0], face_of[c1], same, lo[c0], hi[c0]


def _compress(parent: np.ndarray, par: np.ndarray) -> None:
    """Pointer jumping until every face points at its root; `par` becomes each face's
    parity relative to that root (in place)."""
    while True:
        up = parent[parent]
        if np.array_equal(up, parent):
            return
        par ^= par[parent]
        parent[:] = up


def _solve(n_faces: int, f: np.ndarray, g: np.ndarray, same: np.ndarray,
           lo: np.ndarray, hi: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """(root, parity) per face: the smallest face of its component and whether it needs
    the opposite orientation of that face. ValueError when a relation contradicts the
    rest."""
    parent = np.arange(n_faces, dtype=np.int64)
    par = np.zeros(n_faces, dtype=bool)
    winner = np.empty(n_faces, dtype=np.int64)
    bad_lo, bad_hi = [], []
    while f.size:
        _compress(parent, par)
        rf, rg = parent[f], parent[g]
        rel = par[f] ^ par[g] ^ same  # needed parity between the two roots
        inside = rf == rg
        if inside.any():  # settled for good: they must agree with the tree
            wrong = inside & rel
            if wrong.any():
                bad_lo.append(lo[wrong])
                bad_hi.append(hi[wrong])
            keep = ~inside
            f, g, same, lo, hi = f[keep], g[keep], same[keep], lo[keep], hi[keep]
            rf, rg, rel = rf[keep], rg[keep], rel[keep]
        if not f.size:
            break
        top, low = np.maximum(rf, rg), np.minimum(rf, rg)
        # each root `top` hooks onto one smaller root it is related to: whichever link the
        # scatter kept, its own parent and parity (smaller and smaller roots: no cycle)
        link = np.arange(top.size, dtype=np.int64)
        winner[top] = link
        won = winner[top] == link
        parent[top[won]] = low[won]
        par[top[won]] = rel[won]
    if bad_lo:
        lo_all, hi_all = np.concatenate(bad_lo), np.concatenate(bad_hi)
        k = int(np.argmin(lo_all * n_nodes + hi_all))
        raise ValueError(
            "faces cannot be oriented consistently: the loop of faces through edge "
            f"({int(lo_all[k])}, {int(hi_all[k])}) comes back reversed (a non-orientable, "
            "Moebius-like surface)")
    _compress(parent, par)
    return parent, par


def _vector_areas(points: np.ndarray, fs: FaceSet) -> np.ndarray:
    """(F, 3) twice each face's vector area (the shoelace sums about the centre of the used
    nodes' bounding box; x and y zero for 2D points)."""
    used = points[fs.used_nodes(points.shape[0])]
    q = points - (0.5 * used.min(axis=0) + 0.5 * used.max(axis=0))
    a, b = fs.indices, fs.indices[next_corner(fs)]
    out = np.zeros((fs.n_faces, 3))
    starts = fs.offsets[:-1]
    for k, (i, j) in enumerate(((1, 2), (2, 0), (0, 1))):
        if q.shape[1] == 2 and k < 2:
            continue
        qi, qj = q[:, i], q[:, j]
        out[:, k] = np.add.reduceat(qi[a] * qj[b] - qj[a] * qi[b], starts)
    return out


def orient_faces(faces, n_nodes: int, points=None) -> FaceOrientation:
    """Which faces to reverse so that every edge of two faces is walked once each way, per
    connected component (through such edges); with `points` ((N, 2) or (N, 3)), each
    component turned so that its total signed area is positive (see the module's notes).
    ValueError (one line) when no consistent orientation exists (a non-orientable
    surface)."""
    fs = as_faceset(faces, n_nodes)
    f, g, same, lo, hi = _relations(fs, n_nodes)
    root, parity = _solve(fs.n_faces, f, g, same, lo, hi, n_nodes)
    roots, component = np.unique(root, return_inverse=True)
    flip = parity.copy()
    if points is not None:
        p = np.asarray(points, dtype=np.float64)
        if p.ndim != 2 or p.shape[0] != n_nodes or p.shape[1] not in (2, 3):
            raise ValueError(f"points must be an ({n_nodes}, 2) or ({n_nodes}, 3) array, "
                             f"got shape {p.shape}")
        if not np.isfinite(p[fs.used_nodes(n_nodes)]).all():
            raise ValueError("points must be finite")
        sign = np.where(parity, -1.0, 1.0)  # each face as its component's first face has it
        area = _vector_areas(p, fs) * sign[:, None]
        total = np.stack([np.bincount(component, area[:, k], roots.size) for k in range(3)],
                         axis=1)
        normal = total[int(np.argmax((total * total).sum(axis=1)))]
        axis = (2, 1, 0)[int(np.argmax(np.abs(normal[[2, 1, 0]])))]
        if normal[axis] < 0:
            normal = -normal
        against = (total * normal).sum(axis=1) < 0
        flip ^= against[component]
    return FaceOrientation(flip, component.astype(np.int64), int(roots.size))
