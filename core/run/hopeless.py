"""Free nodes that no position can make valid, found before the run (with a certificate).

In a face where a free node is the only free node, every corner that touches it is twice a
signed triangle area, an affine function ``c . x + d`` of its position x (the corners that
do not touch it are constants), and the face is valid when all of those are > 0. Whatever
the other free nodes do, those faces can all be valid only where these open half-planes
meet. When they do not, the optimizer can only fail, and it takes minutes to find out (tens
of thousands of iterations on a nine-node U-shaped star). A node whose neighbours are all
fixed is the whole story of its star; a node with free neighbours is examined on its faces
without them (a relaxation: an empty region still proves the fold hopeless).

Emptiness is decided without an LP solver (Blender ships NumPy only): by Helly's theorem
in the plane, open half-planes that do not meet contain three (or two) that already do not,
and by Motzkin's alternative three rows do not meet exactly when a combination
``sum l_i (c_i . x + d_i)`` with weights ``l_i >= 0`` (not all 0) has no x in it and a
constant value <= 0: then those corners cannot all be positive wherever the node goes. For
three rows the weights are ``l = (c2 x c3, c3 x c1, c1 x c2)`` (the 2D cross product),
valid when they share a sign; two rows fail together only when their ``c`` are exactly
opposite. Every triple of a node's rows is tried at once (NumPy). The node is certified
only with a margin (the combination's constant, as a distance, below ``-1e-9`` times the
size of its star), so a star that is only just solvable is never held (nor one whose
region shrinks to a point, such as three lines through one fixed node: the optimizer's).

Only candidate nodes are examined: free nodes that are the only free node of some face,
found with two passes over the face corners (tens of ms for a million quads), and of those
only the ones with a corner below the margin where they are now. A star with more than
`MAX_ROWS` rows (dozens of faces), or beyond `MAX_TRIPLES` triples in one run, is left to
the optimizer. Groups of free nodes whose faces fold together are examined by
core/run/hopeless_groups.py (the area their fixed rim encloses).

The run holds a certified node (it leaves the free set): its inverted faces become frozen
faces, reported with the certificate, and the rest of the mesh is untangled as usual.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from ..mesh.faces import FaceSet

__all__ = ["Hopeless", "hopeless_nodes", "hopeless_note"]

MAX_ROWS = 96  # rows (corners touching the node) above which a node is not examined
MARGIN = 1e-9  # the certificate's constant must be below -MARGIN * star size
MIN_SPREAD = 1e-6  # sum of a triple's weights (unit normals): below, too flat to trust
MAX_TRIPLES = 1 << 23  # triples examined per run at most (stars beyond: left to the optimizer)
_CHUNK = 1 << 20  # triples examined per NumPy pass


def _length(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """|(x, y)| with IEEE-exact operations only (NumPy's hypot is dispatched by CPU feature:
    the same bits on every machine); the caller's coordinates are scaled to a power-of-two
    unit size, so the squares neither overflow nor underflow."""
    return np.sqrt(x * x + y * y)


@dataclass(frozen=True)
class Hopeless:
    """The certified nodes and, per node, the faces (one to three) whose corners cannot all
    be positive together."""

    nodes: np.ndarray  # (K,) int64 node ids, ascending
    witness: tuple[tuple[int, ...], ...]  # per node: the certificate's face ids


def _free_count(g, free: np.ndarray) -> np.ndarray:
    """(F,) free nodes per face of group `g` (one gather per corner row, small integers)."""
    out = np.zeros(g.size, dtype=np.uint8 if g.n < 256 else np.int64)
    for row in g.nodes:
        out += free[row]
    return out


def _candidates(fs: FaceSet, free: np.ndarray, can_hold: np.ndarray, n_nodes: int,
                counts: list[np.ndarray]) -> np.ndarray:
    """Nodes in `can_hold` (free) that are the only free node of at least one face: one
    pass over the corners of the faces with one free node."""
    lone = np.zeros(n_nodes, dtype=bool)  # free node of a face with one free node
    for g, cnt in zip(fs.groups, counts, strict=True):
        one = cnt == 1
        if one.any():
            nodes = g.nodes[:, one]
            lone[nodes[free[nodes]]] = True
    lone &= can_hold
    return np.flatnonzero(lone)


def _rows(p: np.ndarray, fs: FaceSet, cand: np.ndarray, n_nodes: int,
          counts: list[np.ndarray]):
    """Per constraint row (a corner touching a candidate in a face where it is the only
    free node): its node, face, A - x0, B - x0 (the corner's area is cross(A - x, B - x) > 0)."""
    is_cand = np.zeros(n_nodes, dtype=bool)
    is_cand[cand] = True
    node_l, face_l, a_l, b_l = [], [], [], []
    for g, cnt in zip(fs.groups, counts, strict=True):
        hit = is_cand[g.nodes] & (cnt == 1)  # (n, F): the candidate's corner (one per face)
        k, j = np.nonzero(hit)
        if k.size == 0:
            continue
        n = g.n
        nodes = g.nodes[:, j]  # (n, R) the faces' nodes
        # ring[s + 2] = the node s places after the candidate in its face
        ring = nodes[(k + np.arange(-2, 3)[:, None]) % n, np.arange(k.size)]
        x = ring[2]
        # corner at x: (A, B) = (next, prev); at prev: (prev2, prev); at next: (next, next2)
        pairs = [(ring[3], ring[1])]
        if n > 3:
            pairs += [(ring[0], ring[1]), (ring[3], ring[4])]
        for a, b in pairs:
            node_l.append(x)
            face_l.append(g.ids[j])
            a_l.append(a)
            b_l.append(b)
    node = np.concatenate(node_l)
    face = np.concatenate(face_l)
    a, b = np.concatenate(a_l), np.concatenate(b_l)
    order = np.argsort(node, kind="stable")
    node, face, a, b = node[order], face[order], a[order], b[order]
    x0 = p[node]
    return node, face, p[a] - x0, p[b] - x0


def _certify(c: np.ndarray, d: np.ndarray, size: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """For K stars of m rows each (c: (K, m, 2), d: (K, m), size: (K,)): which are empty,
    and the (K, 3) rows of a certificate (any order; a pair repeats a row)."""
    k_n, m = d.shape
    found = np.zeros(k_n, dtype=bool)
    which = np.zeros((k_n, 3), dtype=np.int64)
    norm = _length(c[..., 0], c[..., 1])
    ok = norm > 0.0
    safe = np.where(ok, norm, 1.0)
    u = c / safe[..., None]  # unit normals (0 for a row that does not depend on the node)
    e = np.where(ok, d / safe, np.inf)  # signed distances of x0 (constant rows: never used)
    limit = -MARGIN * size[:, None]
    # cross[k, a, b] = u_a x u_b: the weights of every pair and triple
    cross = u[:, :, None, 0] * u[:, None, :, 1] - u[:, :, None, 1] * u[:, None, :, 0]
    if m >= 2:  # exactly opposite pairs
        i, j = np.array(list(combinations(range(m), 2))).T
        dot = u[:, i, 0] * u[:, j, 0] + u[:, i, 1] * u[:, j, 1]
        bad = (cross[:, i, j] == 0.0) & (dot < 0.0) & (e[:, i] + e[:, j] < limit)
        hit = bad.any(axis=1)
        best = np.argmax(bad, axis=1)
        which[hit] = np.stack([i[best], j[best], j[best]], axis=1)[hit]
        found |= hit
    if m >= 3:
        tri = np.array(list(combinations(range(m), 3)))
        step = max(1, _CHUNK // max(1, k_n))
        for s in range(0, tri.shape[0], step):
            i, j, k = tri[s:s + step].T
            li, lj, lk = cross[:, j, k], cross[:, k, i], cross[:, i, j]
            total = li + lj + lk
            flip = total < 0.0
            li, lj, lk, total = (np.where(flip, -v, v) for v in (li, lj, lk, total))
            good = (li >= 0.0) & (lj >= 0.0) & (lk >= 0.0) & (total >= MIN_SPREAD)
            with np.errstate(invalid="ignore"):  # inf * 0 of a constant row: not good
                const = li * e[:, i] + lj * e[:, j] + lk * e[:, k]
            bad = good & (const < limit * total)
            hit = bad.any(axis=1) & ~found
            best = np.argmax(bad, axis=1)
            which[hit] = np.stack([i[best], j[best], k[best]], axis=1)[hit]
            found |= hit
    return found, which


def hopeless_nodes(p: np.ndarray, fs: FaceSet, free: np.ndarray,
                   can_hold: np.ndarray | None = None) -> Hopeless:
    """The free nodes (within `can_hold`, default: all free) whose neighbours are all fixed
    and whose faces no position of theirs can make all valid, with certificates.

    `p`: (N, 2+) float64 points (the run's coordinates), `free`: (N,) bool movable nodes."""
    n_nodes = free.size
    none = Hopeless(np.zeros(0, dtype=np.int64), ())
    hold = free if can_hold is None else free & can_hold
    counts = [_free_count(g, free) for g in fs.groups]
    cand = _candidates(fs, free, hold, n_nodes, counts)
    if cand.size == 0:
        return none
    node, face, a, b = _rows(np.asarray(p, dtype=np.float64)[:, :2], fs, cand, n_nodes,
                             counts)
    # row i: cross(A - x, B - x) = c . y + d with y = x - x0
    c = np.stack([a[:, 1] - b[:, 1], b[:, 0] - a[:, 0]], axis=1)
    d = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    starts = np.flatnonzero(np.r_[True, node[1:] != node[:-1]])
    counts = np.diff(np.r_[starts, node.size])
    reach = np.maximum(_length(a[:, 0], a[:, 1]), _length(b[:, 0], b[:, 1]))
    size = np.maximum.reduceat(reach, starts)
    # a star whose corners are all positive where the node is now is not hopeless; the
    # others need a corner below -MARGIN * size (a certificate's constant is a mean of them)
    with np.errstate(invalid="ignore", divide="ignore"):
        dist = d / _length(c[:, 0], c[:, 1])
    worst = np.minimum.reduceat(np.where(np.isnan(dist), np.inf, dist), starts)
    tangled = worst < -MARGIN * size
    held, witness = [], []
    budget = MAX_TRIPLES
    for m in np.unique(counts[tangled]):
        pick = tangled & (counts == m)
        cost = max(1, m * (m - 1) * (m - 2) // 6)
        if m > MAX_ROWS or budget < cost:
            continue
        s = starts[pick][:budget // cost]
        budget -= s.size * cost
        idx = s[:, None] + np.arange(m)  # (K, m) rows of each star
        found, which = _certify(c[idx], d[idx], size[pick][:s.size])
        for r in np.flatnonzero(found):
            held.append(int(node[s[r]]))
            witness.append(tuple(sorted({int(face[idx[r, w]]) for w in which[r]})))
    if not held:
        return none
    order = np.argsort(held)
    return Hopeless(np.asarray(held, dtype=np.int64)[order],
                    tuple(witness[i] for i in order))


def hopeless_note(h: Hopeless) -> str:
    """The clause that tells why certified nodes are held (node and face ids 0-based, in the
    caller's order; the first few nodes)."""
    if h.nodes.size == 0:
        return ""
    def faces(w: tuple[int, ...]) -> str:
        return f"faces {', '.join(str(f) for f in w)} cannot all be valid at once"

    if h.nodes.size == 1:
        return (f"node {int(h.nodes[0])} is held: with the other vertices of its faces that "
                f"touch it fixed, no position of it makes them valid ({faces(h.witness[0])})")
    why = [f"node {int(v)}: {faces(w)}" for v, w in zip(h.nodes[:3], h.witness[:3],
                                                         strict=False)]
    more = f"; {h.nodes.size - 3} more" if h.nodes.size > 3 else ""
    return (f"{h.nodes.size} nodes are held: with the other vertices of their faces fixed, no "
            f"position of one makes them valid ({'; '.join(why)}{more})")
