"""A resting drag that yields: the grabbed nodes pulled towards the cursor through valid
layouts only (core.run.live).

With the grabbed nodes pinned at the cursor a fold may have no opening at all (the layout
around the cursor has no room for the node where it was pulled: a non-convex border, a
narrow part of an island), or none the region's solves find while the cursor rests. Then
the frames go back to the drag's last layout with no movable face inverted (the base),
let the grabbed nodes go and pull them towards the cursor: the foldover-free energy at its
floor eps (guarded: every trial step that would make a corner det non-positive is
rejected, so each iterate is as valid as the base) plus ``weight`` |x_grab - cursor|^2,
the weight rising while the frames run. A node the layout lets through reaches the cursor
(and is put exactly there once its corners stay positive); one the layout blocks stops
where the barrier holds it, with the layout valid all the way. The pull runs on the faces
near the drag's remaining way (``PULL_REACH``, ``PULL_NODES``), the rest of the mesh keeps
the base's bits.
docs/live.md describes what a drag does with it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..eegt.engine_numpy import edge_lengths
from ..mesh.faces import FaceSet
from ..metrics.targets import Targets, corner_factors
from ..optimize.energy import FoldoverEnergy
from ..optimize.solver import ResumableLBFGS
from ..optimize.stages import EPS_MIN
from ..optimize.state import State
from ..optimize.submesh import Neighbourhood
from .repair import touching

__all__ = ["PULL_AFTER", "PULL_CHUNK", "PULL_GROWTH", "PULL_NODES",
           "PULL_REACH", "PULL_WEIGHT", "PULL_WEIGHT_MAX", "GrabPull", "PullEnergy", "PullStep"]

PULL_AFTER = 0.25  # seconds of rest with a fold the frames have not opened: then the pull
PULL_WEIGHT = 10.0  # the pull's first weight, per squared mean edge of the region
PULL_GROWTH = 1.5  # the weight grows by this factor after PULL_CHUNK iterations at it ...
PULL_WEIGHT_MAX = 1e6  # ... up to this (per squared mean edge)
PULL_CHUNK = 100  # L-BFGS iterations at one weight (and at most in one go)
PULL_REACH = 1.5  # the faces with a node within this x the way left (and 3 mean edges)
#                   of the grabbed nodes' way to the cursor move; the rest stays ...
PULL_NODES = 4000  # ... nearer when more nodes than this are that near (an iteration on a
#                    larger region does not fit a frame)
FIRST_ITERATIONS = 2  # a timed solve's iterations before its time per iteration is known
SNAP = 1e-3  # within this x the mean edge of the cursor, a grabbed node is put on it when
#              its corners stay positive there
STILL = 1e-3  # a solve at the top weight that gets the nodes less than this x the mean
#               edge nearer: the pull is done (the layout holds them there)


class PullEnergy:
    """``FoldoverEnergy`` plus ``weight`` sum |x_k - c_k|^2 over the packed variables ``k``
    (free-node positions in the state's ``fidx``), with the interface ``solver.lbfgs``
    uses; the dets, and so the guard and the step limit, are the energy's own."""

    def __init__(self, en: FoldoverEnergy, k: np.ndarray, c: np.ndarray, weight: float):
        self.en, self.k, self.c, self.weight = en, k, c, weight
        self.precond, self.h_mean, self.tick_every = en.precond, en.h_mean, en.tick_every
        self.step_limit = en.step_limit
        self._z: np.ndarray | None = None
        self._nf = 0

    def packed(self, st: State) -> tuple[tuple[np.ndarray, int], np.ndarray]:
        self._nf = st.nf
        return self.en.packed(st)

    def _xy(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return z[self.k] - self.c[:, 0], z[self._nf + self.k] - self.c[:, 1]

    def evaluate(self, z: np.ndarray, layout, eps: float) -> tuple[float, float, bool]:
        e, dmin, ok = self.en.evaluate(z, layout, eps)
        self._z = z  # the point `gradient` follows (lbfgs asks right after evaluating)
        dx, dy = self._xy(z)
        return e + self.weight * float(np.sum(dx * dx + dy * dy)), dmin, ok

    def gradient(self, layout) -> np.ndarray:
        g = self.en.gradient(layout).copy()
        dx, dy = self._xy(self._z)
        g[self.k] += 2.0 * self.weight * dx
        g[self._nf + self.k] += 2.0 * self.weight * dy
        return g


@dataclass(frozen=True)
class PullStep:
    """One frame's pull: where the moved nodes are and what it did."""

    positions: np.ndarray  # (len(GrabPull.moved), 2), normalised
    iterations: int
    distance: float  # the grabbed nodes' largest distance from the cursor (normalised)
    done: bool  # nothing more to gain (at the cursor, or held by the layout)
    snapped: bool  # the grabbed nodes are exactly at the cursor


class GrabPull:
    """The pull of one rest: ``base`` (N, 2; normalised, no corner a move can change
    inverted), ``fs`` and ``free`` (N,) bool the drag's faces and movable nodes (the grabbed
    ones not), ``grab`` their ids and ``target`` (k, 2) the cursor's places for them
    (normalised), ``targets`` the drag's target shapes. ValueError when the base has a
    non-positive corner in the pull's region (the guard would accept no step)."""

    def __init__(self, base: np.ndarray, fs: FaceSet, free: np.ndarray, grab: np.ndarray,
                 target: np.ndarray, targets: Targets | None = None):
        self.base = base
        self.grab, self.target = grab, np.asarray(target, dtype=np.float64).reshape(-1, 2)
        movable = free.copy()
        movable[grab] = True
        factors = None if targets is None else corner_factors(targets, fs)
        near = Neighbourhood(fs.by_arity(), movable, factors)
        seed = self._seed(base, fs)
        (groups, nodes, sub_free, sub_factors), _ = near.submesh(seed, 1)
        self.nodes, self.sub_free = nodes, sub_free
        self.moved = nodes[sub_free]  # the mesh's nodes the pull moves
        pts = base[nodes]
        self.en = FoldoverEnergy(pts, groups, sub_free, sub_factors)
        self.st = State(pts, sub_free)
        local = np.searchsorted(nodes, grab)
        self.k = np.searchsorted(self.st.fidx, local)
        if not self.en.i0.size or float(np.min(self.en.dets(self.st.x, self.st.y))) <= 0.0:
            raise ValueError("the pull's base has an inverted corner")
        self.h = float(self.en.h_mean)
        self.weight = PULL_WEIGHT / (self.h * self.h)
        self.v = self.st.pack(self.st.x, self.st.y)
        self.energy = PullEnergy(self.en, self.k, self.target, self.weight)
        self.solve = ResumableLBFGS(self.energy, self.st, self.v, EPS_MIN)
        self.per_iteration = 0.0
        self._at_weight = 0  # iterations at the current weight
        self.distance = self._distance(self.v)
        self.done = self.snapped = False

    def _seed(self, base: np.ndarray, fs: FaceSet) -> np.ndarray:
        """(E,) bool, ``Neighbourhood`` order: the elements with a node within reach of a
        grabbed node's way from the base to the cursor (``PULL_REACH``; the ``PULL_NODES``
        nearest nodes when more are that near)."""
        a, b = base[self.grab], self.target
        ab = b - a
        way = float(np.max(np.sqrt(ab[:, 0] * ab[:, 0] + ab[:, 1] * ab[:, 1])))
        mean, _ = edge_lengths(base[:, 0], base[:, 1], fs.groups)
        reach = max(PULL_REACH * way, 3.0 * mean)
        near = np.full(base.shape[0], np.inf)  # squared distance to the nearest way
        for i in range(a.shape[0]):
            ln = float(ab[i, 0] * ab[i, 0] + ab[i, 1] * ab[i, 1])
            r = base - a[i]
            t = np.zeros(base.shape[0]) if ln == 0.0 else \
                np.clip((r[:, 0] * ab[i, 0] + r[:, 1] * ab[i, 1]) / ln, 0.0, 1.0)
            d = r - t[:, None] * ab[i]
            np.minimum(near, d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1], out=near)
        top = reach * reach
        if near.size > PULL_NODES:
            top = min(top, float(np.partition(near, PULL_NODES)[PULL_NODES]))
        return touching(fs, near <= top)[fs.arity_order()]

    def _distance(self, v: np.ndarray) -> float:
        nf = self.st.nf
        dx, dy = v[self.k] - self.target[:, 0], v[nf + self.k] - self.target[:, 1]
        return float(np.max(np.sqrt(dx * dx + dy * dy)))

    def positions(self) -> np.ndarray:
        """(len(moved), 2) where the pull has the nodes ``moved`` (normalised)."""
        nf = self.st.nf
        return np.column_stack([self.v[:nf], self.v[nf:]])

    def advance(self, until: float | None) -> PullStep:
        """Iterations until the time ``until`` (a ``time.perf_counter`` value; None:
        ``PULL_CHUNK`` of them), one solve resumed from frame to frame (its L-BFGS memory
        too), the weight rising after every ``PULL_CHUNK`` iterations at it (or when the
        solve stops at one); the grabbed nodes go exactly to the cursor once near it with
        their corners positive there."""
        its = 0
        top = PULL_WEIGHT_MAX / (self.h * self.h)
        while not self.done:
            left = None if until is None else until - time.perf_counter()
            if left is not None and left <= 0.0 and its:
                break
            n = PULL_CHUNK
            if left is not None:
                n = FIRST_ITERATIONS if self.per_iteration <= 0.0 else \
                    int(np.clip(left / self.per_iteration, 1, PULL_CHUNK))
            t0 = time.perf_counter()
            done, stopped = self.solve.run(n)
            self.v = self.solve.v
            if done:
                self.per_iteration = (time.perf_counter() - t0) / done
            its += done
            before, self.distance = self.distance, self._distance(self.v)
            if self.distance <= SNAP * self.h and self._snap():
                self.done = self.snapped = True
            elif self.weight >= top and before - self.distance < STILL * self.h:
                self.done = True
            self._at_weight += max(done, 1)
            if (self._at_weight >= PULL_CHUNK or stopped) and self.weight < top:
                self.weight, self._at_weight = min(self.weight * PULL_GROWTH, top), 0
                self.energy.weight = self.weight  # the next weight (the memory stays)
                self.solve.energy_changed()
            if until is None:
                break
        return PullStep(self.positions(), its, self.distance, self.done, self.snapped)

    def _snap(self) -> bool:
        """Put the grabbed nodes exactly at the cursor when every corner stays positive."""
        v = self.v.copy()
        nf = self.st.nf
        v[self.k], v[nf + self.k] = self.target[:, 0], self.target[:, 1]
        x, y = self.st.unpack(v)
        if float(np.min(self.en.dets(x, y))) <= 0.0:
            return False
        self.v, self.distance = v, 0.0
        return True
