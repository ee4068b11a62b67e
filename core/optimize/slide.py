"""Boundary sliding in the global stage: a sliding node's variable is its parameter on its
boundary curve (core.eegt.boundary), not its two coordinates.

The L-BFGS then runs on v = [x_free, y_free, tau_sliding]; the energy sees every node's
position, the sliding ones at point(tau) (piecewise linear: the gradient in tau is the
position gradient along the segment the parameter lies on). A trial point where a sliding
node is not strictly between its neighbours on the loop, or a periodic curve is wound more
than once, has an infinite energy, so the line search never takes it: order is kept by
construction, not only by the mesh staying valid. Runs with sliding nodes use the host
solver (`solver.lbfgs`): the device solvers take the plain layout.
"""

from __future__ import annotations

import numpy as np

from ..eegt.boundary import SlideView
from .state import State

__all__ = ["SlideProblem", "SlideState", "make_state"]


def make_state(points: np.ndarray, free: np.ndarray, slide: SlideView | None) -> State:
    """The L-BFGS state of a problem: plain, or with the sliding nodes of `slide`."""
    if slide is None:
        return State(points, free)
    st = SlideState(points, free, slide)
    return st if st.ns else State(points, free)


class SlideState(State):
    """v = [x of free nodes, y of free nodes, tau of sliding nodes]; `fidx` are the nodes
    free in 2D, `sidx` the sliding ones (local ids) with their slots `var_slots`."""

    def __init__(self, points: np.ndarray, free: np.ndarray, view: SlideView):
        self.slide = s = view.slide
        slots, local = view.here(points.shape[0])
        self.tau0 = view.tau_all(points)  # every slot's parameter: constants for the others
        var = free[local]
        self.var_slots, self.sidx = slots[var], local[var]
        sliding = np.zeros(points.shape[0], dtype=bool)
        sliding[local] = True
        super().__init__(points, free & ~sliding)
        self.ns = int(self.sidx.size)
        dx, dy = s.direction(self.var_slots, self.tau0[self.var_slots])
        len2 = dx * dx + dy * dy  # the tau preconditioner: d(position) = |d| d(tau)
        self._len2 = np.where(len2 > 0.0, len2, 1.0)  # 0: a node stacked inside a stack
        self._views: dict[int, SlideProblem] = {}

    @property
    def size(self) -> int:
        return 2 * self.nf + self.ns

    @property
    def written(self) -> np.ndarray:
        return np.concatenate([self.fidx, self.sidx])

    def preconditioner(self, precond: np.ndarray) -> np.ndarray:
        return np.concatenate([np.tile(precond[self.fidx], 2), precond[self.sidx] / self._len2])

    def view(self, en):
        key = id(en)
        if key not in self._views:
            self._views[key] = SlideProblem(en, self)
        return self._views[key]

    def tau_of(self, v: np.ndarray) -> np.ndarray:
        """The sliding nodes' parameters in v, periodic ones wrapped."""
        return self.slide.wrap(self.var_slots, v[2 * self.nf:])

    def unpack(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x, y = super().unpack(v[: 2 * self.nf])
        x[self.sidx], y[self.sidx] = self.slide.point(self.var_slots, self.tau_of(v))
        return x, y

    def pack(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        tau = self.slide.locate(self.var_slots, x[self.sidx], y[self.sidx])
        return np.concatenate([x[self.fidx], y[self.fidx], tau])


class SlideProblem:
    """An energy seen through `SlideState`'s variables, with the interface `solver.lbfgs`
    uses (`packed`, `evaluate`, `gradient`, `precond`, `h_mean`, `tick_every`)."""

    def __init__(self, en, st: SlideState):
        self.en, self.st = en, st
        self.precond, self.h_mean, self.tick_every = en.precond, en.h_mean, en.tick_every
        n, nf, ns = en.n_nodes, st.nf, st.ns
        fixed = np.ones(n, dtype=bool)
        fixed[st.fidx] = False
        fixed[st.sidx] = False
        fix = np.flatnonzero(fixed)
        pos = np.empty((2, n), dtype=np.int64)  # z_in = [xf, yf, xs, ys, x_fixed, y_fixed]
        pos[0, st.fidx] = np.arange(nf)
        pos[1, st.fidx] = nf + np.arange(nf)
        pos[0, st.sidx] = 2 * nf + np.arange(ns)
        pos[1, st.sidx] = 2 * nf + ns + np.arange(ns)
        base = 2 * (nf + ns)
        pos[0, fix] = base + np.arange(fix.size)
        pos[1, fix] = base + fix.size + np.arange(fix.size)
        self.inner = en.flat_layout(pos)
        self.z_in = np.concatenate([np.zeros(base), st.x[fix], st.y[fix]])
        self._dir = (np.zeros(ns), np.zeros(ns))

    def packed(self, st: SlideState):
        return (self.inner, self.st.size), np.zeros(0)

    def evaluate(self, z: np.ndarray, layout, eps: float) -> tuple[float, float, bool]:
        st, s = self.st, self.st.slide
        n2, ns = 2 * st.nf, st.ns
        tau = st.tau_of(z)
        tau_all = st.tau0.copy()
        tau_all[st.var_slots] = tau
        if not s.order_kept(tau_all, st.var_slots):
            return float("inf"), -float("inf"), False
        zi = self.z_in
        zi[:n2] = z[:n2]
        zi[n2 : n2 + ns], zi[n2 + ns : n2 + 2 * ns] = s.point(st.var_slots, tau)
        self._dir = s.direction(st.var_slots, tau)
        return self.en.evaluate(zi, self.inner, eps)

    def gradient(self, layout) -> np.ndarray:
        st = self.st
        n2, ns = 2 * st.nf, st.ns
        g = self.en.gradient(self.inner)
        out = np.empty(n2 + ns)
        out[:n2] = g[:n2]
        dx, dy = self._dir
        out[n2:] = g[n2 : n2 + ns] * dx + g[n2 + ns : n2 + 2 * ns] * dy
        return out
