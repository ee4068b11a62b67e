"""A live drag's escalation (core.run.live): the foldover-free stage on the tangled region.

EEGT alone cannot open a fold where a node was pulled past its neighbours. When a frame's
EEGT iterations leave a face inverted that a move can change, the drag escalates: each frame
then runs ``core.optimize.untangle_global`` (NumPy) on the region around the inverted faces
(``Neighbourhood.submesh``: the faces within ``RINGS[level]`` rings of them, the sub-mesh's
outer nodes and the grabbed nodes fixed) for as many iterations as the frame's time allows
(from the last solve's seconds per element iteration), and the solve is resumable: the
region's eps continuation (``core.optimize.Resume``) goes from one frame to the next, so
frame N+1 goes on where frame N stopped, as one long solve split into frames would (only
the L-BFGS memory starts afresh each frame). The region is cut again only when an inverted
face lies outside it or it grows: one step of ``RINGS`` (then the whole mesh) after
``GROW_AFTER`` solves and ``GROW_ITERATIONS`` iterations without progress (a new low of the
inverted count or a rise of the worst corner det). A fold the largest region does not open
(``STUCK_AFTER`` solves, ``STUCK_ITERATIONS`` iterations without progress, or the optimizer
giving up) is held: left inverted, no longer solved, until the mesh is valid again.
docs/live.md describes what a drag does with it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..mesh.faces import FaceSet
from ..metrics.face_quality import inverted_corners
from ..metrics.targets import Targets, corner_factors
from ..optimize import GlobalOptions, Resume, untangle_global
from ..optimize.submesh import Neighbourhood

__all__ = ["GROW_AFTER", "MAX_REGION", "RINGS", "SPREAD", "STUCK_AFTER", "RegionRepair",
           "RepairStep", "carried"]

RINGS = (3, 6, 12, 24, 48)  # rings around the inverted faces, level by level (then the whole)
GROW_AFTER = 4  # solves in a row without progress ...
GROW_ITERATIONS = 200  # ... of this many iterations together: the next level
PROGRESS_RISE = 0.05  # a rise of the worst det by this x |det| (or a new low of the
#                       inverted count) is progress
MAX_REGION = 20_000  # elements a region may have (a larger solve does not fit a frame)
REPAIR_ITERATIONS = 300  # L-BFGS iterations of one solve without a time budget, and at most
MIN_ITERATIONS = 3  # ... and at least (the solve is resumed: short ones add up)
POLISH = 20  # guarded polish iterations once the region is valid (a barely valid region
#              folds again at the next move of the grabbed nodes)
WHOLE_SHARE = 0.5  # a region of more than this share of the elements: the whole mesh instead
STUCK_AFTER = 12  # solves of the largest region in a row without progress ...
STUCK_ITERATIONS = 600  # ... of this many iterations together: the fold is given up on
SPREAD = 3.0  # `carried`: the grabbed node's move reaches this x its length around it
FRONT = 2.0  # ... and at least this x its length ahead (a box with room for the move: the
#              falloff's steepest slope is 1.5 / front, so that ahead keeps 1 - 1.5 / FRONT
#              of every det)
SIDES = (3.0, 2.0, 1.0, 0.5, 0.25, 0.125)  # ... across it: the first of these x its length
#                                            that leaves that room
MAX_CARRIED = 64  # grabbed nodes `carried` moves one by one at most (more: no carried start)


def _lengths(a: np.ndarray, c: np.ndarray, length: float) -> tuple[float, float, float]:
    """`carried`'s box for one grabbed node: (front, back, side) lengths such that no node
    that stays (at ``a`` along the move, ``c`` across it, relative to the grabbed node) is
    strictly inside (-back, front) x (-side, side), front >= ``FRONT`` x the move's
    ``length`` (the widest side of ``SIDES`` that allows it), each at most ``SPREAD`` x it."""
    reach = SPREAD * length
    for share in SIDES:
        side = share * length
        near = np.abs(c) < side
        ahead, behind = a[near & (a > 0.0)], a[near & (a <= 0.0)]
        front = min(float(ahead.min()) if ahead.size else reach, reach)
        back = min(float(-behind.max()) if behind.size else reach, reach)
        if front >= FRONT * length and back > 0.0:
            return front, back, side
    return 0.0, 0.0, 0.0


def falloff(t: np.ndarray) -> np.ndarray:
    """The smooth step 1 - 3 t^2 + 2 t^3 of t clipped to [0, 1]: 1 at 0 and 0 from 1 on,
    flat at both ends, slope at most 1.5 (at t = 0.5)."""
    t = np.clip(t, 0.0, 1.0)
    return 1.0 - t * t * (3.0 - 2.0 * t)


def carried(points: np.ndarray, grab: np.ndarray, target: np.ndarray, moving: np.ndarray
            ) -> np.ndarray | None:
    """A fold-free start for a grabbed move: ``points`` (N, 2; valid) with the grabbed
    nodes at ``target`` ((k, 2) in ``grab`` order, one move d for all) and the ``moving``
    nodes ((N,) bool) carried along by d phi. phi is 1 at a grabbed node and falls to 0
    in a box around it, f(a) h(c) with a, c the place along and across d: f falls from 1
    to 0 over ``front`` ahead and ``back`` behind, h over ``side`` either way, each along
    the smooth step `falloff` (``_lengths``: no node that stays inside the box; the largest
    of several); several grabbed nodes: the largest phi. The map x + phi(x) d has the det
    1 + d . grad(phi), lowered only by the slope ahead (at most 1.5 / front, times h <= 1),
    so front >= ``FRONT`` |d| keeps at least 1 - 1.5 / FRONT of it. A corner triangle
    sees phi at its three nodes only, and the linear phi across a thin triangle can be
    much steeper than phi itself: a smooth phi, flat at the grabbed node and at the box's
    edges, keeps that close to its own slope, where a peaked one (linear falls, a ridge
    through the grabbed node) flips thin cells that straddle the ridge (a cylinder's
    Unwrap: cells of aspect 15). None: no move, more than ``MAX_CARRIED`` grabbed nodes,
    grabbed nodes moved differently, or no box fits (a node that stays within ``FRONT`` |d|
    ahead)."""
    grab = np.asarray(grab, dtype=np.int64)
    target = np.asarray(target, dtype=np.float64).reshape(-1, 2)
    if grab.size == 0 or grab.size > MAX_CARRIED:
        return None
    moves = target - points[grab]
    d = moves[0]
    length = float(np.sqrt(d[0] * d[0] + d[1] * d[1]))
    if length == 0.0 or not np.all(moves == d):
        return None
    ux, uy = d[0] / length, d[1] / length
    stays = ~moving
    stays[grab] = False
    mx, my = points[moving, 0], points[moving, 1]
    phi = np.zeros(mx.size)
    for g in grab.tolist():
        gx, gy = points[g, 0], points[g, 1]
        sx, sy = points[stays, 0] - gx, points[stays, 1] - gy
        front, back, side = _lengths(sx * ux + sy * uy, sx * uy - sy * ux, length)
        if front <= 0.0:
            return None
        rx, ry = mx - gx, my - gy
        a, c = rx * ux + ry * uy, np.abs(rx * uy - ry * ux)
        f = falloff(np.where(a > 0.0, a / front, -a / back))
        phi = np.maximum(phi, f * falloff(c / side))
    out = points.copy()
    out[moving, 0] = mx + phi * d[0]
    out[moving, 1] = my + phi * d[1]
    out[grab] = target
    return out


@dataclass(frozen=True)
class RepairStep:
    """One frame's solves on the region: the new positions and what they did."""

    points: np.ndarray  # (N, 2) the whole mesh, the region's free nodes moved
    n_bad: int  # elements still inverted (not skipped, not held)
    iterations: int  # L-BFGS iterations of its solves
    solves: int
    region_faces: int  # faces of the last sub-mesh solved
    rings: int  # its rings around the inverted faces (-1: the whole mesh)
    seconds: float


class _Region:
    """One cut sub-mesh and its resumable continuation."""

    def __init__(self, cut, elems: np.ndarray, rings: int):
        (self.groups, self.nodes, self.free, self.factors), self.elems = cut, elems
        self.rings = rings
        self.resume = Resume()


class RegionRepair:
    """The foldover-free stage of one drag on its tangled region, frame after frame.

    ``fs`` the drag's faces, ``free`` (N,) the nodes that may move (the grabbed ones not),
    ``targets`` the drag's target shapes (None: regular polygons). ``solve`` runs one frame's
    share; ``reset`` ends the escalation (the mesh is valid)."""

    def __init__(self, fs: FaceSet, free: np.ndarray, targets: Targets | None = None):
        self.fs, self.free = fs, free
        factors = None if targets is None else corner_factors(targets, fs)
        self.near = Neighbourhood(fs.by_arity(), free, factors)
        self.elem_face = fs.arity_order()  # element -> face id
        self.held = np.zeros(self.elem_face.size, dtype=bool)  # folds given up on
        self.per_element = 0.0  # seconds per iteration and sub-mesh element (last solve)
        self.active = False  # escalated
        self.solves = 0
        self.region: _Region | None = None
        self._calm()

    def restart(self) -> None:
        """A new start (the grabbed nodes moved): the next solve cuts its region afresh
        with a fresh continuation (the level stays)."""
        self.region = None
        self.low, self.top_det, self.since, self.since_its = None, None, 0, 0

    def reset(self) -> None:
        """The mesh is valid: the escalation ends (a later fold starts from the smallest
        region, and the folds given up on are tried again)."""
        self._calm()
        self.region = None
        self.held[:] = False
        self.active = False

    def _calm(self) -> None:
        self.level, self.low, self.top_det = 0, None, None
        self.since, self.since_its = 0, 0
        self.top, self.gave_up = False, False

    @property
    def stuck(self) -> bool:
        """The largest region has been solved ``STUCK_AFTER`` times in a row (and
        ``STUCK_ITERATIONS`` iterations) without progress, or the optimizer gave up on it:
        no move it finds opens the fold."""
        return self.top and (self.gave_up or (self.since >= STUCK_AFTER
                                              and self.since_its >= STUCK_ITERATIONS))

    def bad_elements(self, points: np.ndarray, skip: np.ndarray) -> np.ndarray:
        """(E,) bool, ``Neighbourhood`` order: elements inverted at ``points`` that a move
        can change (not ``skip``: frozen, (E,) bool) and not held."""
        return inverted_corners(points, self.fs)[self.elem_face] & ~skip & ~self.held

    def iterations(self, seconds: float | None, elements: int) -> int:
        """Iterations a solve of ``elements`` elements gets for ``seconds`` (None: no limit),
        from the last solve's time per element iteration."""
        if seconds is None:
            return REPAIR_ITERATIONS
        if self.per_element <= 0.0:
            return MIN_ITERATIONS
        its = int(seconds / (self.per_element * max(elements, 1)))
        return int(np.clip(its, MIN_ITERATIONS, REPAIR_ITERATIONS))

    def solve(self, points: np.ndarray, skip: np.ndarray, until: float | None) -> RepairStep:
        """Solves on the region around the inverted elements of ``points`` (N, 2; normalised,
        not changed; ``skip`` (E,) bool: frozen elements) until none is inverted or the time
        ``until`` (a ``time.perf_counter`` value; None: one solve of ``REPAIR_ITERATIONS``).
        Each solve goes on with the region's continuation from the last one (this frame's or
        an earlier frame's); the region is cut again when an inverted element lies outside
        it, the level grows without progress, and a fold the largest region does not open is
        held (``held``)."""
        t0 = time.perf_counter()
        self.active = True
        pts = points.copy()
        bad = self.bad_elements(pts, skip)
        its = solves = 0
        while bad.any():
            left = None if until is None else until - time.perf_counter()
            if left is not None and left <= 0.0 and solves:
                break
            reg = self._region(bad)
            n_its = self.iterations(left, int(reg.elems.size))
            if not reg.free.any():  # nothing in the region can move: hold it
                self.held |= bad
                bad[:] = False
                break
            opts = GlobalOptions(max_iter=n_its, polish_iter=min(POLISH, n_its),
                                 long_polish=False, lift_rounds=0)
            t1 = time.perf_counter()
            sub_pts, info = untangle_global(pts[reg.nodes], reg.groups, reg.free, opts,
                                            factors=reg.factors, resume=reg.resume)
            done = int(info["iterations"])
            if done:
                self.per_element = (time.perf_counter() - t1) / (done * max(reg.elems.size, 1))
            moved = reg.nodes[reg.free]
            pts[moved] = sub_pts[reg.free]
            its, solves = its + done, solves + 1
            self.solves += 1
            bad = self.bad_elements(pts, skip)
            self._progress(int(bad.sum()), float(info["min_det"]), done,
                           bool(info.get("gave_up")))
            if self.stuck:  # give these folds up
                self.held |= bad
                bad[:] = False
            if until is None:
                break
        reg = self.region
        return RepairStep(pts, int(bad.sum()), its, solves,
                          0 if reg is None else int(reg.elems.size),
                          0 if reg is None else reg.rings, time.perf_counter() - t0)

    def _region(self, bad: np.ndarray) -> _Region:
        """The region of this level around ``bad``: the last one while it holds every bad
        element, else cut again (a fresh continuation)."""
        reg = self.region
        if reg is not None and reg.rings == self._rings() and \
                not np.setdiff1d(np.flatnonzero(bad), reg.elems, assume_unique=True).size:
            return reg
        seed = bad.copy()
        if reg is not None:  # the region only grows while the escalation lasts
            seed[reg.elems] = True
        rings = self._rings()
        cut, elems = self._submesh(seed, rings)
        if rings >= 0 and elems.size > WHOLE_SHARE * self.elem_face.size:
            rings = -1
            cut, elems = self._submesh(seed, rings)
        while elems.size > MAX_REGION and rings != 0:  # too large for a frame: smaller
            rings = RINGS[0] if rings < 0 else rings // 2
            cut, elems = self._submesh(bad, rings)
            self.top = True
        self.top |= rings < 0
        self.region = _Region(cut, elems, rings)
        return self.region

    def _rings(self) -> int:
        return RINGS[self.level] if self.level < len(RINGS) else -1

    def _submesh(self, seed: np.ndarray, rings: int):
        """The sub-mesh within ``rings`` rings of the seed elements (-1: every element)."""
        if rings < 0:
            return self.near.submesh(np.ones_like(seed), 0)
        return self.near.submesh(seed, rings)

    def _progress(self, n_bad: int, min_det: float, its: int, gave_up: bool) -> None:
        """A new low of the inverted count or a rise of the worst det, or one more solve
        without: the level grows after ``GROW_AFTER`` of those that took
        ``GROW_ITERATIONS`` iterations together (or when the optimizer gave up)."""
        if self.low is None or n_bad < self.low or min_det > self.top_det + \
                PROGRESS_RISE * abs(self.top_det):
            self.low = n_bad if self.low is None else min(self.low, n_bad)
            self.top_det = min_det if self.top_det is None else max(self.top_det, min_det)
            self.since, self.since_its = 0, 0
            return
        self.since += 1
        self.since_its += its
        self.gave_up |= self.top and gave_up
        grow = gave_up or (self.since >= GROW_AFTER and self.since_its >= GROW_ITERATIONS)
        if grow and not self.top:
            self.level += 1
            self.low, self.top_det, self.since, self.since_its = None, None, 0, 0
