"""Groups of free nodes that no positions can make valid, found before the run.

A connected group of free nodes (free nodes joined by shared faces, every other node of
those faces fixed) moves inside a rim of fixed nodes. The signed areas of the group's faces
add up to a constant whatever the group does: each edge between two of its faces is walked
once each way and cancels, so the sum is the shoelace sum over the edges that are left, and
those join fixed nodes only. A valid face has a positive area (its corners all turn left),
so when that constant is not positive the faces cannot all be valid: the rim is folded over
itself (a pinned ring turned inside out, a hole dragged across the outer boundary). Such a
group is held, as a single hopeless node is (core/run/hopeless.py), and the rest of the
mesh is untangled as usual; without the certificate the optimizer would search until it
gives up.

Only groups that touch a tangled face are examined, found by growing rings from those
faces' free nodes (at most MAX_RINGS passes over the faces, stopping once MAX_VISIT nodes
are reached): a group is small when it closes within that. Meshes of more than MAX_CORNERS
face corners are not examined (the passes would cost more than the run they save; the
optimizer gives up on such a fold after a few rounds without progress), nor are tangles
with more than MAX_VISIT free nodes. A group with a node on an edge that no other face of it
shares (the mesh boundary: a sliding node) has no constant sum and is left to the
optimizer, as is one whose sum is within the margin of zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mesh.faces import FaceSet
from ..metrics.face_quality import inverted_corners

__all__ = ["HopelessGroups", "hopeless_groups", "hopeless_groups_note"]

MAX_CORNERS = 1 << 19  # meshes with more face corners are not examined (each ring is a
# pass over every face: about 10 ms per 100k faces; there the optimizer's no-progress stop,
# core/optimize/stages.STALL_ROUNDS, ends a hopeless fold instead)
MAX_RINGS = 8  # rings grown from the tangled faces: groups wider than this are not examined
MAX_VISIT = 1 << 12  # nodes visited at most (groups are small; a wide tangle is not one)
MARGIN = 1e-9  # certified when the sum is below -MARGIN x (the rim's size)^2
_NONE = np.iinfo(np.int64).max


@dataclass(frozen=True)
class HopelessGroups:
    """The held nodes (all groups) and, per group, its nodes, its faces and the constant
    sum of their signed areas (in the caller's units)."""

    nodes: np.ndarray  # (K,) int64 node ids, ascending
    groups: tuple[tuple[tuple[int, ...], tuple[int, ...], float], ...]


def _tangled_seeds(p: np.ndarray, fs: FaceSet, free: np.ndarray) -> np.ndarray:
    """(N,) bool: free nodes of faces with a corner that does not turn left."""
    seeds = np.zeros(free.size, dtype=bool)
    bad = inverted_corners(p, fs)
    for g in fs.groups:
        hit = g.nodes[:, bad[g.ids]]
        seeds[hit[free[hit]]] = True
    return seeds


def _grow(fs: FaceSet, free: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """(N,) bool: the free nodes within MAX_RINGS face rings of the seeds (through free
    nodes), fewer once MAX_VISIT are reached."""
    seen, front = seeds.copy(), seeds
    for _ in range(MAX_RINGS):
        new = np.zeros_like(seen)
        for g in fs.groups:
            hit = front[g.nodes].any(axis=0)
            if hit.any():
                nodes = g.nodes[:, hit]
                new[nodes[free[nodes]]] = True
        new &= ~seen
        if not new.any():
            break
        seen |= new
        front = new
        if np.count_nonzero(seen) > MAX_VISIT:
            break
    return seen


def _labels(fs: FaceSet, free: np.ndarray, seen: np.ndarray, hold: np.ndarray
            ) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray, np.ndarray]:
    """Per face group: (face columns touching a seen node, their (n, S) nodes); the (N,)
    group label of each seen node (its group's smallest node id once settled); and (N,) bool
    over labels: the groups that are not closed (a free node outside the seen set, a node
    that cannot be held, or not settled within the passes)."""
    lab = np.full(free.size, _NONE, dtype=np.int64)
    idx = np.flatnonzero(seen)
    lab[idx] = idx
    sub = []
    for g in fs.groups:
        cols = np.flatnonzero(seen[g.nodes].any(axis=0))
        sub.append((cols, g.nodes[:, cols]))
    for _ in range(MAX_RINGS + 2):
        changed = False
        for _cols, nodes in sub:
            if nodes.size == 0:
                continue
            fr = free[nodes]
            low = np.where(fr, lab[nodes], _NONE).min(axis=0)
            lower = fr & (low < lab[nodes])
            if lower.any():
                np.minimum.at(lab, nodes[lower], np.broadcast_to(low, nodes.shape)[lower])
                changed = True
        if not changed:
            break
    opened = np.zeros(free.size, dtype=bool)
    for _cols, nodes in sub:
        if nodes.size == 0:
            continue
        fr = free[nodes]
        lf = np.where(fr, lab[nodes], _NONE)
        low = lf.min(axis=0)
        high = np.where(fr, lf, -1).max(axis=0)
        mixed = (low != high) | (fr & ~seen[nodes]).any(axis=0) | \
            (fr & ~hold[nodes]).any(axis=0)
        for bad in (low[mixed], high[mixed]):
            opened[bad[(bad >= 0) & (bad < _NONE)]] = True
    return sub, lab, opened


def hopeless_groups(p: np.ndarray, fs: FaceSet, free: np.ndarray,
                    can_hold: np.ndarray | None = None) -> HopelessGroups:
    """The small groups of free nodes (within `can_hold`, default: all free) whose faces'
    signed areas add up to a constant that is not positive: no positions make them all
    valid. `p`: (N, 2+) float64 points, `free`: (N,) bool movable nodes."""
    none = HopelessGroups(np.zeros(0, dtype=np.int64), ())
    p = np.asarray(p, dtype=np.float64)[:, :2]
    if fs.n_corners > MAX_CORNERS:
        return none
    hold = free if can_hold is None else free & can_hold
    seeds = _tangled_seeds(p, fs, free)
    if not seeds.any() or np.count_nonzero(seeds) > MAX_VISIT:
        return none
    seen = _grow(fs, free, seeds)
    sub, lab, opened = _labels(fs, free, seen, hold)
    x, y = p[:, 0], p[:, 1]
    face_l, lab_l, area_l, edge_l = [], [], [], []
    for g, (cols, nodes) in zip(fs.groups, sub, strict=True):
        if cols.size == 0:
            continue
        fl = np.where(free[nodes], lab[nodes], _NONE).min(axis=0)
        nxt = np.roll(nodes, -1, axis=0)
        face_l.append(g.ids[cols])
        lab_l.append(fl)
        area_l.append((x[nodes] * y[nxt] - x[nxt] * y[nodes]).sum(axis=0) / 2.0)
        edge_l.append((np.repeat(fl[None], g.n, axis=0).ravel(), nodes.ravel(), nxt.ravel()))
    face, flab, area = (np.concatenate(v) for v in (face_l, lab_l, area_l))
    # an edge that no face walks the other way (the mesh's boundary, a non-manifold edge)
    # must join fixed nodes: a free node on one has no closed fan around it (a face across
    # an edge with a free node holds that node, so it is one of the group's faces here)
    el, ea, eb = (np.concatenate([e[k] for e in edge_l]) for k in range(3))
    n = np.int64(free.size)
    touch = free[ea] | free[eb]
    single = touch.copy()
    single[touch] = ~np.isin(eb[touch] * n + ea[touch], ea * n + eb)
    opened[el[single]] = True
    held, groups = [], []
    closed = np.unique(flab[~opened[flab]])
    for label in closed:
        mine = flab == label
        members = np.flatnonzero((lab == label) & free)
        rim = np.unique(np.concatenate([ea[el == label], eb[el == label]]))
        span = np.ptp(p[rim], axis=0)
        size2 = float(span[0] * span[0] + span[1] * span[1])
        total = float(area[mine].sum())
        if total < -MARGIN * size2:
            held.extend(int(v) for v in members)
            groups.append((tuple(int(v) for v in members),
                           tuple(int(f) for f in np.sort(face[mine])), total))
    if not held:
        return none
    return HopelessGroups(np.asarray(sorted(held), dtype=np.int64), tuple(groups))


def hopeless_groups_note(h: HopelessGroups, area_unit: float = 1.0) -> str:
    """The clause that tells why certified groups are held (ids 0-based, in the caller's
    order; the first few groups and nodes); `area_unit`: the caller's area of one unit of
    the points the groups were found on."""
    if not h.groups:
        return ""

    def one(nodes: tuple[int, ...], faces: tuple[int, ...], total: float) -> str:
        shown = ", ".join(str(v) for v in nodes[:6]) + (", ..." if len(nodes) > 6 else "")
        return (f"nodes {shown} are held: their {len(faces)} faces cannot all be valid at "
                f"once (their signed areas add up to {total * area_unit:.6g} wherever these "
                "nodes go, the area their rim of fixed vertices encloses)")

    text = "; ".join(one(*grp) for grp in h.groups[:3])
    more = len(h.groups) - 3
    return text + (f"; {more} more groups" if more > 0 else "")
