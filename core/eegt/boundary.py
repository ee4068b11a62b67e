"""Boundary modes: which boundary nodes stay, which slide along the input boundary, which
move freely (beyond the paper, which fixes every boundary node).

- ``fixed`` (default, the paper): boundary, non-manifold and pinned nodes never move.
- ``slide``: a boundary node moves along the polyline of its *input* boundary loop and never
  leaves it. Corners (turning angle above the feature angle), pinned and non-manifold nodes
  (on an edge of three or more faces, or where two boundary loops touch) stay where they are.
  The loop between two fixed nodes is a *chain*; a loop without any fixed node is a closed,
  *periodic* curve. A sliding node's place on its curve is its parameter tau = k + u: segment
  k (from the curve's vertex k, the input position of its k-th node, to vertex k + 1) at the
  fraction u in [0, 1). An EEGT step moves it like a free node, then projects the stitched
  position onto the curve, restricted to tau - REACH gap_prev .. tau + REACH gap_next (the
  parameter gaps to its neighbours on the loop, REACH < 1/2): neighbours moving towards each
  other keep at least 1 - 2 REACH of their gap, so order is kept and no node reaches another.
  Nodes at one point of the input loop (a *stack*: a node dragged onto its neighbour) slide
  apart; at a corner one of them keeps the corner.
- ``free``: only pinned and non-manifold nodes stay.

`BoundaryMotion` carries what the engines need: the movable mask, the sliding nodes with
their curves (`Slide`), and the anchors of the distance weights f(d) (paper eq. 20): the
input positions of the boundary nodes (``slide``; fixed and sliding, since the boundary
curve does not change), of the pinned and non-manifold nodes (``free``; none at all gives a
uniform f = 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import fpmath
from ..mesh.faces import FaceSet, as_faceset
from ..mesh.topology import EdgeInfo, free_nodes
from ..params import BOUNDARY_MODES

__all__ = [
    "BOUNDARY_MODES",
    "SLIDE_REACH",
    "BoundaryMotion",
    "Slide",
    "SlideView",
    "boundary_motion",
    "boundary_structure",
]

SLIDE_REACH = 0.45  # a sliding node moves at most this share of the gap to each neighbour ...
SLIDE_GAP = 0.1  # ... beyond this parameter gap (a tenth of a segment), which it never closes
_LOCATE_CHUNK = 1 << 20  # node/segment pairs per vectorized batch of `Slide.locate`


def _ragged(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(owner, rank) of every entry of rows with `counts` entries each."""
    owner = np.repeat(np.arange(counts.size), counts)
    first = np.cumsum(counts) - counts
    return owner, np.arange(owner.size) - first[owner]


@dataclass(frozen=True)
class BoundaryStructure:
    """Directed boundary edges and what they say about each node (input topology only)."""

    nxt: np.ndarray  # (N,) next node along the boundary (faces CCW: interior on the left), -1
    prv: np.ndarray  # (N,) previous node, -1
    on_boundary: np.ndarray  # (N,) bool: on an edge used by one face
    non_manifold: np.ndarray  # (N,) bool: on an edge of 3+ faces, or where boundary loops touch


def boundary_structure(n_nodes: int, faces) -> BoundaryStructure:
    """The boundary loops' directions and the non-manifold nodes of a face set."""
    fs = as_faceset(faces, n_nodes)
    a = np.concatenate([g.nodes.ravel() for g in fs.groups])
    b = np.concatenate([np.roll(g.nodes, -1, axis=0).ravel() for g in fs.groups])
    key = np.minimum(a, b) * n_nodes + np.maximum(a, b)
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    use = counts[inverse]
    one = use == 1
    ba, bb = a[one], b[one]
    out_deg = np.bincount(ba, minlength=n_nodes)
    in_deg = np.bincount(bb, minlength=n_nodes)
    non_manifold = np.zeros(n_nodes, dtype=bool)
    non_manifold[a[use > 2]] = True
    non_manifold[b[use > 2]] = True
    non_manifold |= (out_deg > 1) | (in_deg > 1) | (out_deg != in_deg)
    nxt = np.full(n_nodes, -1, dtype=np.int64)
    prv = np.full(n_nodes, -1, dtype=np.int64)
    simple = (out_deg[ba] == 1) & (in_deg[bb] == 1)
    nxt[ba[simple]] = bb[simple]
    prv[bb[simple]] = ba[simple]
    on_boundary = (out_deg + in_deg) > 0
    return BoundaryStructure(nxt, prv, on_boundary, non_manifold)


class Slide:
    """Sliding nodes and the input boundary curves they move on (see the module docstring).

    Slot s is sliding node `node[s]`; per slot: its curve, its neighbours on the loop (the
    slot of a sliding neighbour, or -1 and the fixed neighbour's parameter). Per curve: its
    first segment, segment count and whether it is periodic (a loop with no fixed node).
    Per segment: start point (ax, ay), direction (dx, dy) and squared length, from the input
    positions, never changed.
    """

    def __init__(self, node, curve, prev_slot, next_slot, prev_tau, next_tau,
                 seg_first, n_seg, periodic, ax, ay, dx, dy, home):
        self.node = np.asarray(node, dtype=np.int64)
        self.curve = np.asarray(curve, dtype=np.int64)
        self.prev_slot = np.asarray(prev_slot, dtype=np.int64)
        self.next_slot = np.asarray(next_slot, dtype=np.int64)
        self.prev_tau = np.asarray(prev_tau, dtype=np.float64)
        self.next_tau = np.asarray(next_tau, dtype=np.float64)
        self.seg_first = np.asarray(seg_first, dtype=np.int64)
        self.n_seg = np.asarray(n_seg, dtype=np.int64)
        self.periodic = np.asarray(periodic, dtype=bool)
        self.ax, self.ay = np.asarray(ax, np.float64), np.asarray(ay, np.float64)
        self.dx, self.dy = np.asarray(dx, np.float64), np.asarray(dy, np.float64)
        self.len2 = self.dx * self.dx + self.dy * self.dy
        self.home = np.asarray(home, dtype=np.float64)  # each slot's input parameter
        self._sorted_slots = np.argsort(self.node, kind="stable")
        self._sorted_nodes = self.node[self._sorted_slots]
        # `locate` remembers each slot's last position and parameter: a slot asked about
        # again at the same position (most of them, between two stages) costs nothing
        self._known = (*self.point(np.arange(self.size), self.home), self.home.copy())

    @property
    def size(self) -> int:
        return int(self.node.size)

    def slots_of(self, ids: np.ndarray) -> np.ndarray:
        """Slot of each node id in `ids`, -1 for nodes that do not slide."""
        ids = np.asarray(ids, dtype=np.int64)
        pos = np.minimum(np.searchsorted(self._sorted_nodes, ids), self.size - 1)
        hit = self._sorted_nodes[pos] == ids
        return np.where(hit, self._sorted_slots[pos], -1)

    # -- parameters <-> positions ---------------------------------------------------------
    def point(self, slots: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions on the curve of `slots` at parameters `tau` (0 <= tau < n_seg)."""
        k = np.floor(tau)
        seg = self.seg_first[self.curve[slots]] + k.astype(np.int64)
        u = tau - k
        return self.ax[seg] + u * self.dx[seg], self.ay[seg] + u * self.dy[seg]

    def direction(self, slots: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """d(position)/d(tau): the direction of the segment each parameter lies on; on a
        segment of zero length (nodes stacked at one point of the input) the previous
        segment's, the way off the stack back along the curve (its derivative from the
        left at the segment's start), so that a stacked node does not see a zero gradient."""
        c = self.curve[slots]
        k = np.floor(tau).astype(np.int64)
        seg = self.seg_first[c] + k
        dx, dy = self.dx[seg], self.dy[seg]
        flat = self.len2[seg] == 0.0
        if flat.any():
            prev = np.where(self.periodic[c], (k - 1) % self.n_seg[c], k - 1)
            ok = flat & (prev >= 0)
            back = self.seg_first[c[ok]] + prev[ok]
            dx, dy = dx.copy(), dy.copy()
            dx[ok], dy[ok] = self.dx[back], self.dy[back]
        return dx, dy

    def wrap(self, slots: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Parameters of periodic curves brought into [0, n_seg) (others unchanged)."""
        n = self.n_seg[self.curve[slots]].astype(np.float64)
        per = self.periodic[self.curve[slots]]
        t = np.where(per, tau - np.floor(tau / n) * n, tau)
        return np.where(per & (t >= n), t - n, t)

    def locate(self, slots: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
        """Parameters of the points (px, py) on the curves of `slots`: the nearest point of
        the curve (the first nearest segment on ties). For positions made by `point` this is
        their parameter up to round-off."""
        slots = np.asarray(slots, dtype=np.int64)
        px, py = np.asarray(px, np.float64), np.asarray(py, np.float64)
        kx, ky, kt = self._known
        hit = (kx[slots] == px) & (ky[slots] == py)
        out = kt[slots]  # a copy
        if not hit.all():
            miss = np.flatnonzero(~hit)
            t = self._search(slots[miss], px[miss], py[miss])
            out[miss] = t
            kx[slots[miss]], ky[slots[miss]], kt[slots[miss]] = px[miss], py[miss], t
        return out

    def _search(self, slots: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
        """`locate` over every segment of each slot's curve."""
        c = self.curve[slots]
        counts = self.n_seg[c]
        out = np.empty(slots.size)
        cum = np.cumsum(counts)
        start = 0
        while start < slots.size:  # batches of whole slots, about _LOCATE_CHUNK pairs each
            base = int(cum[start - 1]) if start else 0
            stop = max(int(np.searchsorted(cum, base + _LOCATE_CHUNK, side="right")), start + 1)
            owner, k = _ragged(counts[start:stop])
            row = start + owner
            seg = self.seg_first[c[row]] + k
            u, d2 = self._foot(seg, px[row], py[row], 0.0, 1.0)
            first = np.cumsum(counts[start:stop]) - counts[start:stop]
            low = np.minimum.reduceat(d2, first)
            hit = np.flatnonzero(d2 == low[owner])
            own, at = np.unique(owner[hit], return_index=True)
            out[start + own] = k[hit[at]] + u[hit[at]]
            start = stop
        return self.wrap(slots, out)

    def _foot(self, seg, px, py, ulo, uhi) -> tuple[np.ndarray, np.ndarray]:
        """Fraction u of the nearest point of each segment to (px, py), clamped to
        [ulo, uhi], and the squared distance to it (the OpenCL kernel's operation order)."""
        ax, ay, dx, dy, len2 = self.ax[seg], self.ay[seg], self.dx[seg], self.dy[seg], \
            self.len2[seg]
        num = (px - ax) * dx + (py - ay) * dy
        u = np.zeros_like(num)
        np.divide(num, len2, out=u, where=len2 > 0.0)
        u = np.minimum(np.maximum(u, ulo), uhi)
        fx = (ax + u * dx) - px
        fy = (ay + u * dy) - py
        return u, fx * fx + fy * fy

    # -- the EEGT step's projection ----------------------------------------------------------
    def neighbour_tau(self, tau: np.ndarray, slots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Parameters of the previous and next node on the loop of each slot (`tau`: every
        slot's parameter)."""
        ps, ns = self.prev_slot[slots], self.next_slot[slots]
        tp = np.where(ps >= 0, tau[np.maximum(ps, 0)], self.prev_tau[slots])
        tn = np.where(ns >= 0, tau[np.maximum(ns, 0)], self.next_tau[slots])
        return tp, tn

    def project(self, tau: np.ndarray, slots: np.ndarray, px: np.ndarray, py: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """New (tau, x, y) of `slots` whose stitched positions are (px, py): the nearest point
        of the curve within tau -/+ SLIDE_REACH times the gaps to the neighbours' parameters
        `tau` (all slots' parameters before the step: a Jacobi update). A result not strictly
        between the neighbours (round-off at a vanishing gap) keeps the old parameter.
        The OpenCL kernel `slide_project` does these operations in this order."""
        t = tau[slots]
        c = self.curve[slots]
        n = self.n_seg[c].astype(np.float64)
        per = self.periodic[c]
        tp, tn = self.neighbour_tau(tau, slots)
        dp = t - tp
        dp = np.where(per & (dp <= 0.0), dp + n, dp)
        dn = tn - t
        dn = np.where(per & (dn <= 0.0), dn + n, dn)
        lo = t - SLIDE_REACH * np.maximum(dp - SLIDE_GAP, 0.0)
        hi = t + SLIDE_REACH * np.maximum(dn - SLIDE_GAP, 0.0)
        kf = np.floor(lo)
        kl = np.floor(hi)
        kl = np.where(per, kl, np.minimum(kl, n - 1.0))
        counts = np.maximum((kl - kf).astype(np.int64) + 1, 1)
        owner, j = _ragged(counts)
        k = kf[owner] + j  # unwrapped segment number (float, integral)
        kw = np.where(per[owner], k - np.floor(k / n[owner]) * n[owner], k)
        seg = self.seg_first[c[owner]] + kw.astype(np.int64)
        ulo = np.maximum(lo[owner] - k, 0.0)
        uhi = np.minimum(hi[owner] - k, 1.0)
        u, d2 = self._foot(seg, px[owner], py[owner], ulo, uhi)
        first = np.cumsum(counts) - counts
        low = np.minimum.reduceat(d2, first)
        hit = np.flatnonzero(d2 == low[owner])
        _, at = np.unique(owner[hit], return_index=True)
        pick = hit[at]
        tnew = kw[pick] + u[pick]
        tnew = np.where(per & (tnew >= n), tnew - n, tnew)
        a = tnew - tp
        a = np.where(per & (a < 0.0), a + n, a)
        b = tn - tp
        b = np.where(per & (b <= 0.0), b + n, b)
        tnew = np.where((a > 0.0) & (a < b), tnew, t)
        x, y = self.point(slots, tnew)
        return tnew, x, y

    def order_kept(self, tau: np.ndarray, slots: np.ndarray) -> bool:
        """Whether each of `slots` lies strictly between its loop neighbours (cyclically on a
        periodic curve) and every periodic curve is wound once (`tau`: every slot's
        parameter, periodic ones wrapped into [0, n))."""
        if slots.size == 0:
            return True
        t = tau[slots]
        c = self.curve[slots]
        per = self.periodic[c]
        n = self.n_seg[c].astype(np.float64)
        tp, tn = self.neighbour_tau(tau, slots)
        a = t - tp
        a = np.where(per & (a < 0.0), a + n, a)
        b = tn - tp
        b = np.where(per & (b <= 0.0), b + n, b)
        if not bool(np.all((a > 0.0) & (a < b))):
            return False
        if not per.any():
            return True
        # periodic curves: the gaps to the next node, each in (0, n), add up to n once
        ring = np.flatnonzero(self.periodic[self.curve])
        _, tn_r = self.neighbour_tau(tau, ring)
        gap = tn_r - tau[ring]
        gap = np.where(gap > 0.0, gap, gap + self.n_seg[self.curve[ring]])
        turns = np.bincount(self.curve[ring], gap, minlength=self.n_seg.size)
        return bool(np.all(~self.periodic | (turns < 1.5 * self.n_seg)))


def _build_slide(p: np.ndarray, bs: BoundaryStructure, sliding: np.ndarray) -> Slide | None:
    """Chains (fixed node, sliding nodes..., fixed node) and periodic loops of sliding
    nodes, walked once at set-up."""
    s_nodes = np.flatnonzero(sliding)
    if s_nodes.size == 0:
        return None
    curves: list[tuple[list[int], bool]] = []  # (vertex nodes, periodic)
    seen = np.zeros(p.shape[0], dtype=bool)
    starts = np.flatnonzero(~sliding & bs.on_boundary & (bs.nxt >= 0))
    starts = starts[sliding[bs.nxt[starts]]]
    # a fixed node with several outgoing boundary edges (non-manifold) starts no chain here:
    # its neighbours then have no unique `prv`/`nxt` and were made fixed
    for f0 in starts.tolist():
        verts = [f0]
        v = int(bs.nxt[f0])
        while sliding[v]:
            seen[v] = True
            verts.append(v)
            v = int(bs.nxt[v])
        verts.append(v)
        curves.append((verts, False))
    for s0 in s_nodes.tolist():
        if seen[s0]:
            continue
        verts = []
        v = s0
        while not seen[v]:
            seen[v] = True
            verts.append(v)
            v = int(bs.nxt[v])
        curves.append((verts, True))
    node, curve, pos, seg_first, n_seg, periodic = [], [], [], [], [], []
    ax, ay, dx, dy = [], [], [], []
    prev_node, next_node, prev_tau, next_tau = [], [], [], []
    total = 0
    for ci, (verts, per) in enumerate(curves):
        vv = np.asarray(verts, dtype=np.int64)
        a = vv if per else vv[:-1]
        b = np.roll(vv, -1) if per else vv[1:]
        m = a.size
        seg_first.append(total)
        n_seg.append(m)
        periodic.append(per)
        total += m
        ax.append(p[a, 0])
        ay.append(p[a, 1])
        dx.append(p[b, 0] - p[a, 0])
        dy.append(p[b, 1] - p[a, 1])
        inner = vv if per else vv[1:-1]
        k = np.arange(inner.size) + (0 if per else 1)
        node.append(inner)
        curve.append(np.full(inner.size, ci))
        pos.append(k.astype(np.float64))
        prev_node.append(np.roll(vv, 1)[k] if per else vv[k - 1])
        next_node.append(np.roll(vv, -1)[k] if per else vv[k + 1])
        prev_tau.append((k - 1).astype(np.float64))
        next_tau.append((k + 1).astype(np.float64))
    node_a = np.concatenate(node)
    slot = np.full(p.shape[0], -1, dtype=np.int64)
    slot[node_a] = np.arange(node_a.size)
    pn, nn = np.concatenate(prev_node), np.concatenate(next_node)
    return Slide(node_a, np.concatenate(curve), slot[pn], slot[nn], np.concatenate(prev_tau),
                 np.concatenate(next_tau), seg_first, n_seg, periodic, np.concatenate(ax),
                 np.concatenate(ay), np.concatenate(dx), np.concatenate(dy),
                 np.concatenate(pos))


@dataclass(frozen=True)
class SlideView:
    """The sliding nodes of one optimisation problem: the whole mesh (`nodes` None), or a
    sub-mesh whose local node i is global node `nodes[i]`, with every slot's parameter at
    the start (`tau`; the sub-mesh's fixed slots keep it). None `tau`: located from the
    whole mesh's points."""

    slide: Slide
    nodes: np.ndarray | None = None
    tau: np.ndarray | None = None

    def here(self, n_local: int) -> tuple[np.ndarray, np.ndarray]:
        """(slots, local node ids) of the sliding nodes in this problem."""
        if self.nodes is None:
            return np.arange(self.slide.size), self.slide.node
        slots = self.slide.slots_of(self.nodes)
        local = np.flatnonzero(slots >= 0)
        return slots[local], local

    def tau_all(self, points: np.ndarray) -> np.ndarray:
        """Every slot's parameter: those in this problem located at `points` (its local
        (n, 2) positions), the others as in `tau`."""
        s = self.slide
        slots, local = self.here(points.shape[0])
        out = np.array(self.tau, dtype=np.float64) if self.tau is not None else s.home.copy()
        out[slots] = s.locate(slots, points[local, 0], points[local, 1])
        return out

    def sub(self, nodes: np.ndarray, points: np.ndarray) -> SlideView:
        """The view of a sub-mesh whose local node i is this problem's node `nodes[i]`, for
        this problem at `points` (its (n, 2) positions)."""
        nodes = np.asarray(nodes, dtype=np.int64)
        glob = nodes if self.nodes is None else self.nodes[nodes]
        return SlideView(self.slide, glob, self.tau_all(points))


def _stack_end(x: np.ndarray, y: np.ndarray, step: np.ndarray, start: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """(last node, nodes passed) of the walk from each of `start` along the loop links
    `step` (bs.prv or bs.nxt) while the next node sits at the same position."""
    end = start.copy()
    passed = np.zeros(start.size, dtype=np.int64)
    go = np.ones(start.size, dtype=bool)
    for _ in range(x.size):  # as many rounds as the longest stack (1 or 2 in practice)
        nb = step[end]
        go &= (nb >= 0) & (nb != start)
        at = np.maximum(nb, 0)
        go &= (x[at] == x[end]) & (y[at] == y[end])
        if not go.any():
            break
        end[go] = nb[go]
        passed[go] += 1
    return end, passed


def _stacked_sliding(points: np.ndarray, fs: FaceSet, bs: BoundaryStructure, nodes: np.ndarray,
                     cos_limit: float) -> np.ndarray:
    """The sliding ones among `nodes`: sliding candidates that sit on a loop neighbour (a
    *stack* of nodes at one point of the loop, e.g. a node dragged onto its neighbour).
    A stack's turn is measured between the nearest other positions before and after it. A
    smooth stack slides whole. A corner stack keeps one node at the corner (a pinned or
    non-manifold node of the stack, else the one in the fewest faces, the first along the
    loop on ties) and the others slide off it along their curve, which is what untangles
    their faces. A stack without another position on either side stays."""
    x, y = points[:, 0], points[:, 1]
    head, back = _stack_end(x, y, bs.prv, nodes)
    tail, ahead = _stack_end(x, y, bs.nxt, nodes)
    a, b = bs.prv[head], bs.nxt[tail]
    ok = (a >= 0) & (b >= 0)
    a, b = np.maximum(a, 0), np.maximum(b, 0)
    ok &= ((x[a] != x[head]) | (y[a] != y[head])) & ((x[b] != x[tail]) | (y[b] != y[tail]))
    e1x, e1y = x[nodes] - x[a], y[nodes] - y[a]
    e2x, e2y = x[b] - x[nodes], y[b] - y[nodes]
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        cos_turn = (e1x * e2x + e1y * e2y) / (np.sqrt(e1x * e1x + e1y * e1y)
                                              * np.sqrt(e2x * e2x + e2y * e2y))
    smooth = ok & (cos_turn >= cos_limit)
    corner = ok & ~smooth
    # a corner stack whose members all are candidates (`nodes`) needs a keeper
    whole = corner & (np.bincount(head, minlength=x.size)[head] == back + ahead + 1)
    faces_at = np.bincount(np.concatenate([g.nodes.ravel() for g in fs.groups]),
                           minlength=x.size)
    order = np.lexsort((back, faces_at[nodes], head))
    first = np.ones(order.size, dtype=bool)
    first[1:] = head[order[1:]] != head[order[:-1]]
    keeper = np.zeros(nodes.size, dtype=bool)
    keeper[order[first]] = True
    return nodes[smooth | (corner & ~(whole & keeper))]


@dataclass(frozen=True)
class BoundaryMotion:
    """What a boundary mode lets move, for the engines and the global stage."""

    mode: str
    movable: np.ndarray  # (N,) bool: nodes that may move (in 2D, or along their curve)
    slide: Slide | None  # the sliding nodes (a subset of movable), None without
    anchor_x: np.ndarray  # distance-weight anchors: input positions (empty: uniform f = 1)
    anchor_y: np.ndarray
    n_corners: int = 0  # boundary nodes kept fixed as corners (slide)

    @property
    def sliding(self) -> np.ndarray:
        """(N,) bool: the sliding nodes."""
        out = np.zeros(self.movable.size, dtype=bool)
        if self.slide is not None:
            out[self.slide.node] = True
        return out


def boundary_motion(points: np.ndarray, faces: FaceSet, fixed=None, mode: str = "fixed",
                    feature_angle: float = 30.0,
                    edges: EdgeInfo | None = None) -> BoundaryMotion | None:
    """The movable nodes of a boundary mode (None for ``fixed``: the engines' own path).

    `points` (N, 2) are the input positions the curves and anchors are taken from; `fixed`
    pins extra nodes as in `free_nodes`. A boundary node is a corner when its turning angle
    (between the incoming and the outgoing boundary edge) exceeds `feature_angle` degrees.
    Nodes at one point of the loop (a zero-length edge: a node dragged onto its neighbour)
    are judged as one stack (`_stacked_sliding`). `edges`: the faces' EdgeInfo, if known."""
    if mode not in BOUNDARY_MODES:
        raise ValueError(f"unknown boundary mode {mode!r} (choose from "
                         f"{', '.join(BOUNDARY_MODES)})")
    n = points.shape[0]
    interior = free_nodes(n, faces, fixed, edges=edges)  # also checks pins and orientation
    if mode == "fixed":
        return None
    fs = as_faceset(faces, n)
    bs = boundary_structure(n, fs)
    used = fs.used_nodes(n)
    pinned = np.zeros(n, dtype=bool) if fixed is None else np.asarray(fixed).astype(bool)
    candidates = used & bs.on_boundary & ~bs.non_manifold & ~pinned
    n_corners = 0
    if mode == "free":
        movable = interior | candidates
        slide = None
        anchors = used & ~movable
    else:
        has = candidates & (bs.nxt >= 0) & (bs.prv >= 0)
        i = np.flatnonzero(has)
        e1x = points[i, 0] - points[bs.prv[i], 0]
        e1y = points[i, 1] - points[bs.prv[i], 1]
        e2x = points[bs.nxt[i], 0] - points[i, 0]
        e2y = points[bs.nxt[i], 1] - points[i, 1]
        l1 = np.sqrt(e1x * e1x + e1y * e1y)
        l2 = np.sqrt(e2x * e2x + e2y * e2y)
        cos_limit = fpmath.sin_cos(math.radians(float(feature_angle)))[1]
        with np.errstate(invalid="ignore", divide="ignore"):
            cos_turn = (e1x * e2x + e1y * e2y) / (l1 * l2)
        smooth = (l1 > 0.0) & (l2 > 0.0) & (cos_turn >= cos_limit)
        sliding = np.zeros(n, dtype=bool)
        sliding[i[smooth]] = True
        stacked = (l1 == 0.0) | (l2 == 0.0)
        if stacked.any():
            sliding[_stacked_sliding(points, fs, bs, i[stacked], cos_limit)] = True
        n_corners = int(np.count_nonzero(candidates & ~sliding))
        slide = _build_slide(np.asarray(points, dtype=np.float64), bs, sliding)
        movable = interior | sliding
        anchors = used & ~interior
    if not movable.any():
        raise ValueError("every node is fixed (boundary or pinned): nothing to optimize")
    ax = np.ascontiguousarray(points[anchors, 0], dtype=np.float64)
    ay = np.ascontiguousarray(points[anchors, 1], dtype=np.float64)
    return BoundaryMotion(mode, movable, slide, ax, ay, n_corners)
