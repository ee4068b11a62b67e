"""Global untangling stage: the foldover-free energy of Garanzha et al. 2021, minimised by L-BFGS.

Used when local EEGT moves stall on a fold (a rotated hole, a large one-step deformation).
Pure NumPy (no SciPy, no bpy), vectorized over corners, deterministic.

Energy (Garanzha, Kaporin, Kudryavtseva, Protais, Ray, Sokolov, "Foldover-free maps in 50 lines
of code", ACM TOG 2021), written here from the paper's equations, for 2D:

    chi(D, eps) = (D + sqrt(eps^2 + D^2)) / 2
    f_eps(J)    = ||J||_F^2 / chi(det J, eps)          (shape, scale invariant)
    g_eps(J)    = (det(J)^2 + 1) / chi(det J, eps)     (area)
    F_eps(x)    = sum_t w_t [ (1 - theta) f_eps(J_t) + theta g_eps(J_t) ]

J_t maps a regular reference corner onto the current corner t. Each n-gon (n >= 4) contributes
its n corner triangles (p_{k-1}, p_k, p_{k+1}) with the regular n-gon corner as reference (so a
positive det on every corner is exactly SPEC section 3's validity, and f = 2 / q_k for eps -> 0);
a triangle contributes one corner (all three give the same J up to a rotation) with the
equilateral triangle as reference. Reference edge lengths follow the local mean edge length,
smoothed, and are scaled so the reference areas add up to the domain area.

eps continuation (the paper's rule): after each inner L-BFGS run,
sigma = max(1 - F_eps(x_new) / F_eps(x_old), 1/10), mu = (1 - sigma) chi(D_-, eps) with D_- the
smallest det, and the new eps solves chi(D_-, eps_new) = mu, i.e. eps_new = 2 sqrt(mu (mu - D_-))
(or the floor when D_- >= mu). Details and measurements: docs/global_untangle.md.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from . import fpmath

__all__ = ["lift_min_quality", "untangle_global"]

THETA = 1.0 / 16.0  # weight of the area term g against the shape term f
LBFGS_MEMORY = 4  # L-BFGS (s, y) pairs kept (8 was 15-20% slower, same iterations: docs)
INNER_ITER = 1000  # L-BFGS iterations between two eps updates (60 stalled on spun holes: docs)
SIZE_SMOOTHING = 2  # smoothing passes of the reference-size field
EPS_MIN = 1e-9  # floor of eps (J is dimensionless: dets are ~1 at the reference size)
SIGMA_MIN = 0.1  # the paper's lower bound on sigma
TICK_EVERY = 20  # progress is reported at most this many L-BFGS iterations apart ...
TICK_CORNERS = 500_000  # ... and every TICK_CORNERS / corners iterations (big meshes: often)
STOP_REL_DECREASE = 1e-3  # stop polishing when one round lowers F by less than this (relative)
# lift_min_quality (max mean quality subject to a rising quality floor; see the docs)
LIFT_FIRST_ITER = 150  # L-BFGS iterations of the first run (floor = the input's q_min)
LIFT_ITER = 200  # L-BFGS iterations per later round (100 stopped short on naca_deform: docs)
LIFT_GROW = 1.15  # floor of the next round: min(q_min * GROW, q_min + GAP * (q_avg - q_min))
LIFT_GAP = 0.15
LIFT_RATE = 3.0  # a round that lowers q_avg must raise q_min by at least RATE times as much
LIFT_PENALTY = 1000.0  # weight of the one-sided quadratic floor penalty
LIFT_BARRIER = 0.01  # weight of sum 1/q_corner (keeps every corner away from det = 0)
LIFT_RINGS = 6  # rounds after the first move only the nodes within this many rings of ...
LIFT_ACTIVE = 1.0  # ... the elements with q < LIFT_ACTIVE * floor (a small local problem)
LIFT_REL_TOL = 1e-5  # a lift run stops when 5 iterations lower F by less than this (relative)
LIFT_POOR = 0.5  # while q_min < this x q_avg, q_avg may fall below the input's (still capped)
LIFT_AVG_DROP = 0.03  # q_avg may not fall below (1 - this) x the best q_avg of the lift


# --------------------------------------------------------------------------- mesh tables


def _tables(
    groups: Mapping[int, np.ndarray],
) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
    """Stack polygons by arity: per-arity arrays, element arity, directed edges, edge element."""
    faces: list[np.ndarray] = []
    arity: list[np.ndarray] = []
    ea: list[np.ndarray] = []
    eb: list[np.ndarray] = []
    ee: list[np.ndarray] = []
    base = 0
    for n in sorted(groups):
        f = np.asarray(groups[n], dtype=np.int64).reshape(-1, int(n))
        if f.shape[0] == 0:
            continue
        if n < 3:
            raise ValueError("polygons need at least 3 nodes")
        m = f.shape[0]
        faces.append(f)
        arity.append(np.full(m, n, dtype=np.int64))
        ea.append(f.ravel())
        eb.append(np.roll(f, -1, axis=1).ravel())
        ee.append(np.repeat(base + np.arange(m, dtype=np.int64), n))
        base += m
    if not faces:
        z = np.zeros(0, dtype=np.int64)
        return [], z, np.stack([z, z]), z
    edges = np.stack([np.concatenate(ea), np.concatenate(eb)])
    return faces, np.concatenate(arity), edges, np.concatenate(ee)


def _corners(
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


def stops(answer: Any) -> bool:
    """A progress callback's answer cancels when it is falsy but not None (False, np.False_,
    0); None (a callback that returns nothing) and truthy values continue."""
    return answer is not None and not answer


def _per_arity(arity: np.ndarray, fn: Callable[[int], Any]) -> np.ndarray:
    """fn(n) (a float or a tuple of floats) for each entry of an integer arity array,
    evaluated once per distinct n; tuples give one column each."""
    top = int(arity.max()) if arity.size else 0
    if top <= 64:  # the usual case: a lookup table (no sort); rows below 3 are never read
        table = np.array([fn(max(n, 3)) for n in range(top + 1)], dtype=np.float64)
        return table[arity]
    values, inverse = np.unique(arity, return_inverse=True)
    return np.array([fn(int(n)) for n in values], dtype=np.float64)[inverse]


def _reference_sizes(
    points: np.ndarray, arity: np.ndarray, edges: np.ndarray, edge_elem: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Reference edge length per element and the smoothed node size.

    Node size = mean length of its incident edges; element size = geometric mean of its
    nodes' sizes, smoothed SIZE_SMOOTHING times through the nodes; then one global factor so
    the regular reference polygons add up to the domain area (which folds cannot change).
    """
    n_nodes = points.shape[0]
    n_elem = arity.shape[0]
    p0 = points.take(edges[0], axis=0)  # = points[edges[0]]
    p1 = points.take(edges[1], axis=0)
    d = p1 - p0
    dx, dy = d[:, 0], d[:, 1]
    elen = np.sqrt(dx * dx + dy * dy)
    positive = elen[elen > 0]
    floor = 1e-3 * (float(np.mean(positive)) if positive.size else 1.0)
    elen = np.maximum(elen, floor)
    cnt = np.bincount(edges[0], minlength=n_nodes).astype(np.float64)
    hn = np.bincount(edges[0], weights=elen, minlength=n_nodes)
    hn = hn + np.bincount(edges[1], weights=elen, minlength=n_nodes)
    hn = np.maximum(hn / np.maximum(2.0 * cnt, 1.0), floor)
    lh = fpmath.log(np.append(hn, floor))  # the floor's log in the same call
    lh, log_floor = lh[:-1], float(lh[-1])
    deg = arity.astype(np.float64)
    le = np.bincount(edge_elem, weights=lh[edges[0]], minlength=n_elem) / deg
    for _ in range(SIZE_SMOOTHING):
        lh = np.bincount(edges[0], weights=le[edge_elem], minlength=n_nodes)
        lh = np.where(cnt > 0, lh / np.maximum(cnt, 1.0), log_floor)
        le = np.bincount(edge_elem, weights=lh[edges[0]], minlength=n_elem) / deg
    size = fpmath.exp(le)
    ref_area = arity * size**2 / (4.0 * _per_arity(arity, fpmath.tan_pi_over))
    x0, y0 = p0.T
    x1, y1 = p1.T
    dom_area = 0.5 * float(np.sum(x0 * y1 - x1 * y0))
    total = float(np.sum(ref_area))
    if dom_area > 0.0 and total > 0.0:
        size = size * np.sqrt(dom_area / total)
    return size, fpmath.exp(lh)


# --------------------------------------------------------------------------- energy


def _chi(d: np.ndarray, eps: float, root: np.ndarray) -> np.ndarray:
    """chi(D, eps) = (D + sqrt(eps^2 + D^2)) / 2, without cancellation for D < 0."""
    return np.where(d >= 0.0, 0.5 * (d + root), (0.5 * eps * eps) / (root + np.abs(d)))


def _chi_scalar(d: float, eps: float) -> float:
    root = float(np.sqrt(eps * eps + d * d))
    return 0.5 * (d + root) if d >= 0.0 else 0.5 * eps * eps / (root - d)


class _Blocks:
    """Preallocated per-corner arrays of one energy, with views of their blocks made once.

    `_eval` fills them and `_grad` reads what the last `_eval` left, so one evaluation is in
    flight at a time (as in `_lbfgs`: the gradient right after the accepted trial point).
    Scratch that is dead by then shares memory: squares of J with dF/dJ, edges with dF/dE.
    Constants are full-length arrays: NumPy multiplies two arrays faster than an array and a
    Python float, with the same result.
    """

    def __init__(self, m: int, w00: np.ndarray, w01: np.ndarray, w11: np.ndarray):
        def blocks(k: int) -> tuple[np.ndarray, ...]:
            a = np.empty(k * m)
            return a, *(a[i * m : (i + 1) * m] for i in range(k))

        two = [np.concatenate([w, w]) for w in (w00, w01, w11)]
        self.w00, self.w01, self.w11 = two  # W^-1 entries for [x, y] pairs of blocks
        # z[gather] = [x1, y1, x2, y2, x0, y0]; e1 = [e1x, e1y], e2 = [e2x, e2y]
        self.c, *_ = blocks(6)
        self.c1, self.c2, self.c0 = self.c[: 2 * m], self.c[2 * m : 4 * m], self.c[4 * m :]
        self.j, self.j00, self.j10, self.j01, self.j11 = blocks(4)
        self.ja, self.jb = self.j[: 2 * m], self.j[2 * m :]  # [j00, j10], [j01, j11]
        self.g, self.g00, self.g10, self.g01, self.g11 = blocks(4)  # dF/dJ
        self.ga, self.gb = self.g[: 2 * m], self.g[2 * m :]
        self.sq, self.s00, self.s10, self.s01, self.s11 = self.g, *self.g.reshape(4, m)  # j^2
        # dF/dE per corner node: [ge1x, ge1y, ge2x, ge2y, -(ge1x + ge2x), -(ge1y + ge2y)]
        self.ge, *_ = blocks(6)
        self.ge1, self.ge2, self.ge0 = self.ge[: 2 * m], self.ge[2 * m : 4 * m], self.ge[4 * m :]
        self.e1, self.e2 = self.ge1, self.ge2  # edge vectors (only while J is computed)
        for name in ("d", "t", "dd", "root", "chi", "num", "inv_chi", "u", "a", "b", "tmp"):
            setattr(self, name, np.empty(m))
        for name, value in (("half", 0.5), ("one", 1.0), ("theta", THETA)):
            setattr(self, name, np.full(m, value))
        self.one_theta = np.full(m, 1.0 - THETA)
        self.two_one_theta = np.full(m, 2.0 * (1.0 - THETA))
        self.two_theta = np.full(m, 2.0 * THETA)


class _Energy:
    """F_eps over the corner triangles that touch a free node, with its gradient.

    The hot path works on one flat coordinate vector z and a layout (gather index, scatter
    index, length of z): `value_grad(x, y)` uses z = [x, y]; `_lbfgs` uses z = [v, fixed
    coordinates], so it never unpacks or packs. `_eval` gives F and min det J (all a line
    search needs), `_grad` the gradient of the point `_eval` saw last. Per-corner quantities
    live in `_Blocks` (one NumPy call per block of M, no temporaries); every value is the same
    float operation on the same operands as the per-entry formula beside it.
    """

    def __init__(self, points: np.ndarray, groups: Mapping[int, np.ndarray], free: np.ndarray):
        tabs = self._prepare(points, groups, free)
        if tabs is None:
            return
        arity, size = tabs
        i0, i1, i2, eid = self.v0, self.v1, self.v2, self.veid
        keep = free[i0] | free[i1] | free[i2]  # other corners have a constant energy
        self._set_corners(i0[keep], i1[keep], i2[keep], arity[eid[keep]], size[eid[keep]])

    def _prepare(
        self, points: np.ndarray, groups: Mapping[int, np.ndarray], free: np.ndarray
    ):
        """Tables, validity corners, reference sizes and preconditioner: (arity, size), or
        None (and no energy corners) when there are no elements."""
        self.n_nodes = points.shape[0]
        faces, arity, edges, edge_elem = _tables(groups)
        self.n_elem = arity.shape[0]
        # validity check: every corner of every element (triangles: one is enough), except
        # frozen ones: made of fixed nodes only and not positive, so no move can change them
        v0, v1, v2, veid = _corners(faces, all_corners=False)
        x, y = points[:, 0], points[:, 1]
        det = (x[v1] - x[v0]) * (y[v2] - y[v0]) - (y[v1] - y[v0]) * (x[v2] - x[v0])
        keep = free[v0] | free[v1] | free[v2] | (det > 0.0)
        self.v0, self.v1, self.v2, self.veid = v0[keep], v1[keep], v2[keep], veid[keep]
        self.power = 1.0
        self._full = None  # the layout of z = [x, y], built on first use
        self._pack = None  # (state, layout, fixed coordinates) of the last _lbfgs call
        if self.n_elem == 0:
            self.i0 = self.i1 = self.i2 = np.zeros(0, dtype=np.int64)
            return None
        size, hnode = _reference_sizes(points, arity, edges, edge_elem)
        # Diagonal L-BFGS preconditioner: with uniform weights the Hessian at a node scales
        # like 1 / size^2, so moves are scaled by size^2.
        self.precond = (hnode / float(np.mean(hnode))) ** 2
        self.h_mean = float(np.mean(size))
        return arity, size

    def _set_corners(
        self, i0: np.ndarray, i1: np.ndarray, i2: np.ndarray, arity: np.ndarray, s: np.ndarray
    ) -> None:
        """Energy corners (k, k+1, k-1) with their element's arity and reference size."""
        self.i0, self.i1, self.i2 = i0, i1, i2
        n = arity.astype(np.float64)
        cos_a, sin_a = _per_arity(arity, fpmath.regular_corner).T
        # W = s [[1, cos a], [0, sin a]]  ->  W^-1 = [[1, -cot a], [0, 1 / sin a]] / s
        self.w00 = 1.0 / s
        self.w01 = -cos_a / (sin_a * s)
        self.w11 = 1.0 / (sin_a * s)
        # One weight per element (spread over its corners): uniform, not the reference area;
        # area weights let small elements absorb all distortion (see the docs).
        self.weight = np.where(n == 3.0, 1.0, 1.0 / n)
        self.idx = np.concatenate([self.i1, self.i2, self.i0])
        self.tick_every = max(1, min(TICK_EVERY, TICK_CORNERS // max(i0.size, 1)))
        self._bk = _Blocks(i0.size, self.w00, self.w01, self.w11)

    # -- flat layouts ----------------------------------------------------------------------
    def _layout(self, pos: np.ndarray) -> tuple[np.ndarray, int]:
        """(index, length) for a flat z holding coordinate c of node i at pos[c, i].

        z[index] = [x1, y1, x2, y2, x0, y0] (blocks of M; corner nodes i1, i2, i0), and the
        same index bins the corner gradients [e1x, e1y, e2x, e2y, e0x, e0y]: each bin adds
        its terms in `idx` order (e1, e2, then -(e1 + e2)), as one bincount over idx per axis.
        """
        index = pos[:, np.stack([self.i1, self.i2, self.i0])]  # (axis, node, corner)
        return np.ascontiguousarray(index.transpose(1, 0, 2)).ravel(), pos.size

    def _full_layout(self) -> tuple[np.ndarray, int]:
        if self._full is None:
            self._full = self._layout(np.arange(2 * self.n_nodes).reshape(2, self.n_nodes))
        return self._full

    def _packed(self, st: _State) -> tuple[tuple[np.ndarray, int], np.ndarray]:
        """Layout of z = [v, x_fixed, y_fixed] for `st`, and the fixed part of z (cached)."""
        if self._pack is None or self._pack[0] is not st:
            fixed = np.ones(self.n_nodes, dtype=bool)
            fixed[st.fidx] = False
            fix = np.flatnonzero(fixed)
            nf, nx = st.nf, fix.size
            pos = np.empty((2, self.n_nodes), dtype=np.int64)
            pos[0, st.fidx] = np.arange(nf)
            pos[1, st.fidx] = np.arange(nf, 2 * nf)
            pos[0, fix] = np.arange(2 * nf, 2 * nf + nx)
            pos[1, fix] = np.arange(2 * nf + nx, 2 * nf + 2 * nx)
            self._pack = (st, self._layout(pos), np.concatenate([st.x[fix], st.y[fix]]))
        return self._pack[1], self._pack[2]

    # -- corner Jacobians ------------------------------------------------------------------
    def _jac(self, z: np.ndarray, index: np.ndarray) -> None:
        """J = [j00, j10, j01, j11] and d = det J of every corner into the blocks."""
        bk = self._bk
        z.take(index, None, bk.c, "clip")  # = z[index]
        np.subtract(bk.c1, bk.c0, bk.e1)  # e1x = x[i1] - x[i0], e1y = y[i1] - y[i0]
        np.subtract(bk.c2, bk.c0, bk.e2)  # e2x = x[i2] - x[i0], e2y
        np.multiply(bk.e1, bk.w00, bk.ja)  # j00 = e1x w00, j10 = e1y w00
        np.multiply(bk.e1, bk.w01, bk.jb)
        np.add(bk.jb, np.multiply(bk.e2, bk.w11, bk.e2), bk.jb)  # j01 = e1x w01 + e2x w11
        np.multiply(bk.j00, bk.j11, bk.d)  # d = j00 j11 - j01 j10
        np.subtract(bk.d, np.multiply(bk.j01, bk.j10, bk.tmp), bk.d)

    def _frob(self) -> np.ndarray:
        """t = j00^2 + j01^2 + j10^2 + j11^2 (in that order) of the blocks' J."""
        bk = self._bk
        np.multiply(bk.j, bk.j, bk.sq)
        np.add(bk.s00, bk.s01, bk.t)
        np.add(bk.t, bk.s10, bk.t)
        return np.add(bk.t, bk.s11, bk.t)

    def _scatter(self, a: np.ndarray, b: np.ndarray, n_bins: int, index: np.ndarray):
        """Node gradient (flat, layout order) of dF/dJ = a J + b cof(J), cof(J) = [[j11, -j10],
        [-j01, j00]], through dF/dE = dF/dJ W^-T with E = [e1, e2]."""
        bk = self._bk
        mul, tmp = np.multiply, bk.tmp
        np.add(mul(a, bk.j00, bk.g00), mul(b, bk.j11, tmp), bk.g00)  # g00 = a j00 + b j11
        np.subtract(mul(a, bk.j10, bk.g10), mul(b, bk.j01, tmp), bk.g10)  # g10 = a j10 - b j01
        np.subtract(mul(a, bk.j01, bk.g01), mul(b, bk.j10, tmp), bk.g01)  # g01 = a j01 - b j10
        np.add(mul(a, bk.j11, bk.g11), mul(b, bk.j00, tmp), bk.g11)  # g11 = a j11 + b j00
        mul(bk.ga, bk.w00, bk.ge1)
        np.add(bk.ge1, mul(bk.gb, bk.w01, bk.ga), bk.ge1)  # ge1x = g00 w00 + g01 w01, ge1y
        mul(bk.gb, bk.w11, bk.ge2)  # ge2x = g01 w11, ge2y = g11 w11
        np.negative(np.add(bk.ge1, bk.ge2, bk.ge0), bk.ge0)  # -(ge1 + ge2)
        return np.bincount(index, bk.ge, n_bins)

    def _xy(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(J, d) at the node positions x, y (copies)."""
        self._jac(np.concatenate([x, y]), self._full_layout()[0])
        return self._bk.j.copy(), self._bk.d.copy()

    def dets(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """det J of every energy corner."""
        return self._xy(x, y)[1]

    def value(self, x: np.ndarray, y: np.ndarray, eps: float) -> float:
        """F_eps."""
        self._jac(np.concatenate([x, y]), self._full_layout()[0])
        d = self._bk.d.copy()
        num = (1.0 - THETA) * self._frob()
        num += THETA * (d * d + 1.0)
        chi = _chi(d, eps, np.sqrt(eps * eps + d * d))
        u = num / chi
        if self.power != 1.0:
            u = fpmath.power(0.5 * u, self.power)
        return float(np.add.reduce(self.weight * u))

    def value_grad(
        self, x: np.ndarray, y: np.ndarray, eps: float
    ) -> tuple[float, np.ndarray, np.ndarray, float]:
        """F_eps, dF/dx, dF/dy over all nodes (non-free rows included), and min det J."""
        n = self.n_nodes
        layout = self._full_layout()
        e, dmin, ok = self._eval(np.concatenate([x, y]), layout, eps)
        g = self._grad(layout) if ok else np.zeros(layout[1])
        return e, g[:n], g[n:], dmin

    def _eval(self, z: np.ndarray, layout, eps: float) -> tuple[float, float, bool]:
        """(F_eps, min det J, whether `_grad` may follow) at the flat coordinates z."""
        bk = self._bk
        self._jac(z, layout[0])
        d, dd, root, chi, num, inv_chi = bk.d, bk.dd, bk.root, bk.chi, bk.num, bk.inv_chi
        dmin = float(np.minimum.reduce(d))
        np.multiply(d, d, dd)
        np.sqrt(np.add(dd, eps * eps, root), root)  # sqrt(eps^2 + d^2)
        if dmin >= 0.0:  # no D < 0: chi's first branch, 0.5 (d + root), everywhere
            np.multiply(bk.half, np.add(d, root, chi), chi)
        else:
            chi[:] = _chi(d, eps, root)
        np.multiply(bk.one_theta, self._frob(), num)  # (1 - theta) t + theta (d^2 + 1)
        np.add(num, np.multiply(bk.theta, np.add(dd, bk.one, bk.tmp), bk.tmp), num)
        np.divide(self.weight, chi, inv_chi)
        if self.power != 1.0:  # F = sum w (u / 2)^p with u = num / chi
            u = 0.5 * num / chi
            up = fpmath.power(u, self.power)
            energy = float(np.add.reduce(self.weight * up))
            np.multiply(inv_chi, 0.5 * self.power, inv_chi)  # inv_chi (p / 2) (up / u)
            np.multiply(inv_chi, up / u, inv_chi)
        else:
            energy = float(np.add.reduce(np.multiply(num, inv_chi, bk.tmp)))
        return energy, dmin, True

    def _grad(self, layout) -> np.ndarray:
        """dF/dz at the point `_eval` saw last."""
        bk = self._bk
        # dF/dJ = a J + b cof(J); dchi/dD = chi / root
        a = np.multiply(bk.two_one_theta, bk.inv_chi, bk.a)  # 2 (1 - theta) inv_chi
        b = np.multiply(bk.two_theta, bk.d, bk.b)  # inv_chi (2 theta d - num / root)
        np.multiply(bk.inv_chi, np.subtract(b, np.divide(bk.num, bk.root, bk.tmp), b), b)
        return self._scatter(a, b, layout[1], layout[0])

    def n_inverted(self, x: np.ndarray, y: np.ndarray) -> int:
        """Elements with a corner det <= 0 (SPEC section 3)."""
        x0 = x[self.v0]
        y0 = y[self.v0]
        det = (x[self.v1] - x0) * (y[self.v2] - y0) - (y[self.v1] - y0) * (x[self.v2] - x0)
        bad = det <= 0.0
        if not bad.any():
            return 0
        return int(np.count_nonzero(np.bincount(self.veid[bad], minlength=self.n_elem)))


class _LiftEnergy(_Energy):
    """F = sum_e [ -q_e + PENALTY ((qc - q_e)_+ / qc)^2 ] + BARRIER sum_corners w / q_k.

    q_k = 2 det / |J|_F^2 is the corner's mean ratio (theta = 0, eps -> 0) and q_e the mean
    over the element's corners (SPEC section 3). The first term maximises q_avg itself, the
    second is a soft floor qc on every element's quality, the third a barrier per corner (the
    mean alone lets one corner of a polygon collapse). Every corner of every element is kept,
    so element means are complete; only valid (guarded) iterates are evaluated.
    """

    def __init__(self, points: np.ndarray, groups: Mapping[int, np.ndarray], free: np.ndarray):
        tabs = self._prepare(points, groups, free)
        self.qc = 0.0
        if tabs is None:
            return
        arity, size = tabs
        self.eid = self.veid
        self._set_corners(self.v0, self.v1, self.v2, arity[self.eid], size[self.eid])
        self.n_corners = np.bincount(self.eid, minlength=self.n_elem).astype(np.float64)
        self._neg_inv_nc = -1.0 / self.n_corners[self.eid]  # dq_e / du_k = this / u_k^2
        self._barrier_w = LIFT_BARRIER * self.weight
        self._gap = np.empty(0)  # the last `_eval`'s (qc - q_e)_+ / qc
        ne = self.n_elem  # per-element constants (array operands: faster than floats)
        self._zero_e, self._pen_e, self._m1_e = (np.full(ne, c) for c in (0.0, LIFT_PENALTY, -1.0))
        self._qc_e = np.empty(ne)  # filled with qc, then with 2 PENALTY / qc

    def element_quality(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(E,) mean ratio of each element (0 where a corner is not positive)."""
        self._jac(np.concatenate([x, y]), self._full_layout()[0])
        d = self._bk.d
        u = 0.5 * self._frob() / np.where(d > 0.0, d, np.inf)  # 1 / q_k; inf: q_k = 0
        with np.errstate(divide="ignore"):  # a degenerate corner (u = 0): its element is bad
            q = np.bincount(self.eid, 1.0 / u, minlength=self.n_elem) / self.n_corners
        bad = np.bincount(self.eid, d <= 0.0, minlength=self.n_elem) > 0
        return np.where(bad, 0.0, q)

    def value(self, x: np.ndarray, y: np.ndarray, eps: float) -> float:
        return self.value_grad(x, y, eps)[0]

    def _eval(self, z: np.ndarray, layout, eps: float) -> tuple[float, float, bool]:
        bk = self._bk
        self._jac(z, layout[0])
        d, u = bk.d, bk.u
        dmin = float(np.minimum.reduce(d))
        if not dmin > 0.0:  # only reached by rejected trial steps: infinite energy
            return float("inf"), dmin, False
        np.divide(np.multiply(bk.half, self._frob(), u), d, u)  # 1 / q_k = 0.5 t / d
        q = np.bincount(self.eid, np.divide(bk.one, u, bk.tmp), self.n_elem) / self.n_corners
        qc = self._qc_e
        qc.fill(self.qc)
        gap = np.subtract(qc, q)  # (qc - q)_+ / qc
        np.divide(np.maximum(gap, self._zero_e, gap), qc, gap)
        w = np.multiply(self._pen_e, gap)  # PENALTY gap gap - q
        energy = float(np.add.reduce(np.subtract(np.multiply(w, gap, w), q, w)))
        energy += LIFT_BARRIER * float(np.add.reduce(np.multiply(self.weight, u, bk.tmp)))
        self._gap = gap
        return energy, dmin, True

    def _grad(self, layout) -> np.ndarray:
        bk = self._bk
        d, u, tmp = bk.d, bk.u, bk.tmp
        k = self._qc_e
        k.fill(2.0 * LIFT_PENALTY / self.qc)
        de_dq = np.subtract(self._m1_e, np.multiply(k, self._gap, k), k)  # -1 - k gap = dF/dq_e
        # dq_e / du_k = -1 / (n_e u_k^2); u_k = t / (2 d): du/dJ = J / d - u cof(J) / d
        de_du = np.multiply(de_dq[self.eid], self._neg_inv_nc, bk.a)
        np.divide(de_du, np.multiply(u, u, tmp), de_du)
        np.add(de_du, self._barrier_w, de_du)
        b = np.divide(np.multiply(np.negative(de_du, bk.b), u, bk.b), d, bk.b)  # -de_du u / d
        a = np.divide(de_du, d, bk.a)
        return self._scatter(a, b, layout[1], layout[0])


def _active_submesh(
    groups: Mapping[int, np.ndarray], free: np.ndarray, seed: np.ndarray, rings: int
) -> tuple[dict[int, np.ndarray], np.ndarray, np.ndarray]:
    """The elements that touch a free node within `rings` rings of the seed elements.

    seed: (E,) bool over the elements in `_tables` order (arities sorted). Returns the
    sub-mesh's groups with local node numbers, the global id of each local node, and the
    local free mask (the free nodes within reach; the rest of the sub-mesh is fixed).
    """
    faces = [np.asarray(groups[n], dtype=np.int64).reshape(-1, int(n)) for n in sorted(groups)]
    faces = [f for f in faces if f.shape[0]]
    near = np.zeros(free.shape[0], dtype=bool)
    base = 0
    for f in faces:
        near[f[seed[base : base + f.shape[0]]]] = True
        base += f.shape[0]
    for _ in range(rings):
        grow = near.copy()
        for f in faces:
            grow[f[near[f].any(axis=1)]] = True
        near = grow
    move = near & free
    sub = [f[move[f].any(axis=1)] for f in faces]
    nodes = np.unique(np.concatenate([f.ravel() for f in sub])) if sub else np.zeros(0, int)
    local = np.full(free.shape[0], -1, dtype=np.int64)
    local[nodes] = np.arange(nodes.size)
    out = {f.shape[1]: local[f] for f in sub if f.shape[0]}
    return out, nodes, move[nodes]


# --------------------------------------------------------------------------- L-BFGS


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """Dot product by NumPy's pairwise sum: unlike `a @ b` (BLAS, whose result depends on its
    thread count), bit-identical on every run and thread setting (`np.add.reduce` is
    `np.sum` without its Python wrapper: half the cost on small meshes)."""
    return float(np.add.reduce(a * b))


class _State:
    """Free coordinates packed as v = [x_free, y_free]; fixed nodes never written."""

    def __init__(self, points: np.ndarray, free: np.ndarray):
        self.x = np.ascontiguousarray(points[:, 0])
        self.y = np.ascontiguousarray(points[:, 1])
        self.fidx = np.flatnonzero(free)
        self.nf = self.fidx.size

    def unpack(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = self.x.copy()
        y = self.y.copy()
        x[self.fidx] = v[: self.nf]
        y[self.fidx] = v[self.nf :]
        return x, y

    def pack(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.concatenate([x[self.fidx], y[self.fidx]])


def _lbfgs(
    en: _Energy,
    st: _State,
    v0: np.ndarray,
    eps: float,
    *,
    max_it: int,
    guard: bool,
    rel_tol: float = 1e-7,
    tick: Callable[[int], bool] | None = None,
) -> tuple[np.ndarray, int]:
    """L-BFGS with a diagonal preconditioner and Armijo backtracking from v0.

    guard: reject trial points with a corner det <= 0 (used once the mesh is valid); without
    it, stop as soon as every corner is positive.
    Stops after max_it iterations, when 5 iterations lower F by less than rel_tol (relative),
    or when tick(iterations so far), called every `en.tick_every` iterations, cancels.
    Returns the last accepted point and the number of iterations done.

    Written for few NumPy calls per iteration, same arithmetic as the plain formulas in the
    comments: the energy sees z = [v, fixed coordinates] (`_Energy._packed`), whose first
    2 nf gradient entries are the packed gradient, and only accepted points get a gradient;
    dot products are `_dot`'s pairwise sums (one scratch buffer; the four of a new pair as
    the rows of one reduce, each row summed exactly as alone); a scalar factor is filled into
    an array first (a cheaper NumPy operand than a float or a 0-d array).
    """
    layout, fixed = en._packed(st)
    evaluate, gradient = en._eval, en._grad
    mul, red, amax = np.multiply, np.add.reduce, np.maximum.reduce
    n2 = 2 * st.nf
    z = np.concatenate([v0, fixed])  # the energy's input: trial points go into z[:n2]
    zv = z[:n2]
    tmp = np.empty(n2)  # scratch: a product before its sum, a scaled vector
    c0 = np.empty(n2)  # scratch: a scalar factor, filled in (faster operand than a float)
    prods = np.empty((4, n2))  # s y, s s, y y, y (dpre y) of a new pair
    sy_, ss_, yy_, ydy_ = prods
    v = v0
    e, _, ok = evaluate(z, layout, eps)
    g = gradient(layout)[:n2] if ok else np.zeros(n2)
    dpre = np.tile(en.precond[st.fidx], 2)
    # memory: (s, y, rho = 1 / s.y, s.y, y.(dpre y)) per pair, oldest first
    mem: list[tuple[np.ndarray, np.ndarray, float, float, float]] = []
    e_hist = [e]
    h0 = 0.1 * en.h_mean  # first step: the fastest node moves a tenth of a typical edge
    it = 0
    while it < max_it:
        it += 1
        q = -g
        alphas = []
        for s, yv, rho, _, _ in reversed(mem):
            al = rho * red(mul(s, q, tmp))  # rho _dot(s, q)
            alphas.append(al)
            c0.fill(al)
            q -= mul(yv, c0, tmp)  # q -= al yv
        if mem:
            c0.fill(mem[-1][3] / mem[-1][4])
            q *= mul(dpre, c0, tmp)  # q *= dpre (_dot(s, y) / _dot(y, dpre y)) of the last pair
            for (s, yv, rho, _, _), al in zip(mem, reversed(alphas), strict=True):
                c0.fill(al - rho * red(mul(yv, q, tmp)))
                q += mul(s, c0, tmp)  # q += (al - rho _dot(yv, q)) s
            step = 1.0
        else:
            q *= dpre
            qmax = float(amax(np.abs(q, out=tmp)))
            step = h0 / qmax if qmax > 0.0 else 0.0
        slope = float(red(mul(g, q, tmp)))
        if not slope < 0.0:  # not a descent direction: restart from preconditioned descent
            mem = []
            q = -dpre * g
            slope = float(red(mul(g, q, tmp)))
            qmax = float(amax(np.abs(q, out=tmp)))
            step = h0 / qmax if qmax > 0.0 else 0.0
            if not slope < 0.0:
                break
        accepted = False
        for _ in range(40):
            c0.fill(step)
            np.add(v, mul(q, c0, tmp), zv)  # vt = v + step q
            et, dmin_t, ok = evaluate(z, layout, eps)
            if (
                math.isfinite(et)
                and et <= e + 1e-4 * step * slope
                and not (guard and dmin_t <= 0.0)
            ):
                accepted = True
                break
            step *= 0.5
        if not accepted:
            if mem:  # drop the memory and retry once from plain descent
                mem = []
                continue
            break
        gt = gradient(layout)[:n2]
        vt = zv.copy()
        s = vt - v
        yv = gt - g
        mul(s, yv, sy_)
        mul(s, s, ss_)
        mul(yv, yv, yy_)
        mul(yv, mul(dpre, yv, tmp), ydy_)
        sy, ss, yy, ydy = red(prods, 1).tolist()  # _dot(s, y), _dot(s, s), ...
        if sy > 1e-12 * math.sqrt(ss * yy):
            mem.append((s, yv, 1.0 / sy, sy, ydy))
            if len(mem) > LBFGS_MEMORY:
                del mem[0]
        v, e, g = vt, et, gt
        if not guard and dmin_t > 0.0:  # just became valid: hand over to the guarded polish
            break
        e_hist.append(e)
        if len(e_hist) > 5 and e_hist[-6] - e <= rel_tol * abs(e_hist[-6]):
            break
        if tick is not None and it % en.tick_every == 0 and stops(tick(it)):
            break
    return v, it


# --------------------------------------------------------------------------- driver


def _checked_input(points, free) -> tuple[np.ndarray, np.ndarray]:
    """A float64 copy of the (N, 2) points and the (N,) bool free mask; ValueError else."""
    P = np.array(points, dtype=np.float64, copy=True)
    free = np.asarray(free, dtype=bool).reshape(-1)
    if P.ndim != 2 or P.shape[1] != 2 or free.shape[0] != P.shape[0]:
        raise ValueError("points must be (N, 2) and free (N,)")
    return P, free


def untangle_global(
    points: np.ndarray,
    groups: Mapping[int, np.ndarray],
    free: np.ndarray,
    *,
    max_iter: int = 3000,
    polish_iter: int = 300,
    polish_power: float = 1.0,
    time_limit: float | None = None,
    progress: Callable[[int, int, int], Any] | None = None,
    lbfgs: Callable[..., tuple[np.ndarray, int]] | None = None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Untangle a planar polygon mesh by minimising the foldover-free energy (eps continuation).

    points: (N, 2) float64; groups: arity -> (F_n, n) int node arrays, counterclockwise = valid;
    free: (N,) bool mask of the nodes that may move. max_iter bounds all L-BFGS iterations;
    polish_iter bounds those spent improving quality once no element is inverted (0: stop at
    the first valid iterate); polish_power p > 0 polishes sum (f / 2)^p instead of the
    paper's sum f (f / 2 = 1 / mean ratio for eps -> 0): p > 1 raises q_min and lowers q_avg,
    p < 1 the opposite (see the docs); time_limit (s) stops early.
    progress(iterations, max_iter, n_inverted) is called after each round and every
    `tick_every` L-BFGS iterations inside it (a few tenths of a second of work on any mesh
    size); a falsy answer other than None cancels (`stops`).
    lbfgs: a drop-in for `_lbfgs` (same arguments and result), e.g. the OpenCL solver.

    Returns (new points, info); non-free rows are bit-identical to the input. Once valid, steps
    that would invert a corner are rejected, so a valid iterate stays valid; when no valid one
    was reached, the iterate with the fewest inverted elements is returned.
    info: iterations, rounds, n_inverted_in, n_inverted_out, min_det (smallest normalised corner
    det), eps_history, seconds, seconds_per_iter, status ("untangled" / "failed" / "cancelled" /
    "nothing to do").
    """
    t_start = time.perf_counter()
    P, free = _checked_input(points, free)
    if not np.all(np.isfinite(P)):
        raise ValueError("points contain NaN or inf")
    if not polish_power > 0.0:
        raise ValueError("polish_power must be > 0")
    run_lbfgs = lbfgs or _lbfgs
    en = _Energy(P, groups, free)
    st = _State(P, free)
    n_inv = en.n_inverted(st.x, st.y)
    info: dict[str, Any] = {
        "iterations": 0,
        "rounds": 0,
        "n_inverted_in": n_inv,
        "n_inverted_out": n_inv,
        "min_det": float(np.min(en.dets(st.x, st.y))) if en.i0.size else 0.0,
        "eps_history": [],
        "seconds": 0.0,
        "seconds_per_iter": 0.0,
        "status": "nothing to do",
    }
    if en.i0.size == 0 or st.nf == 0:
        info["seconds"] = time.perf_counter() - t_start
        return P, info

    v = st.pack(st.x, st.y)
    dmin = info["min_det"]
    eps = max(0.1 * abs(dmin), 1e-3) if dmin <= 0.0 else EPS_MIN
    best_v, best_inv = v, n_inv
    valid = dmin > 0.0  # every corner that can move is positive (others are constant)
    total = 0
    polish_used = 0
    status = ""
    eps_hist: list[float] = []
    rounds = 0
    cancel = False
    while total < max_iter:
        rounds += 1
        eps_hist.append(eps)
        guard = valid  # valid: polish the quality, never invert a corner again
        en.power = float(polish_power) if guard else 1.0
        e_start = en.value(*st.unpack(v), eps)
        if guard:  # eps is at its floor: one long L-BFGS run, no memory restarts
            cap = min(max_iter - total, polish_iter - polish_used)
            if cap <= 0:
                break
        else:
            cap = min(max_iter - total, INNER_ITER)
        tick = None
        if progress is not None:  # long runs report (and cancel) from inside

            def tick(it: int, done: int = total, n_now: int = best_inv) -> bool:
                nonlocal cancel
                cancel = cancel or stops(progress(done + it, max_iter, n_now))
                return not cancel

        v, its = run_lbfgs(en, st, v, eps, max_it=cap, guard=guard, tick=tick)
        total += its
        if guard:
            polish_used += its
        x, y = st.unpack(v)
        e_end = en.value(x, y, eps)
        dmin = float(np.min(en.dets(x, y)))
        valid = dmin > 0.0
        n_inv = en.n_inverted(x, y)
        if n_inv <= best_inv:
            best_v, best_inv = v, n_inv
        if cancel or (progress is not None and stops(progress(total, max_iter, n_inv))):
            status = "cancelled"
            break
        decrease = (e_start - e_end) / abs(e_start) if e_start != 0.0 else 0.0
        if guard and (decrease < STOP_REL_DECREASE or its == 0):
            break
        if valid and polish_iter <= 0:
            break
        if time_limit is not None and time.perf_counter() - t_start > time_limit:
            break
        sigma = max(decrease, SIGMA_MIN)
        mu = (1.0 - sigma) * _chi_scalar(dmin, eps)
        eps = max(2.0 * float(np.sqrt(mu * (mu - dmin))) if dmin < mu else EPS_MIN, EPS_MIN)
        if valid:  # the guard now keeps dets > 0: use the exact barrier (see the docs)
            eps = EPS_MIN

    x, y = st.unpack(best_v)
    out = P.copy()
    out[st.fidx, 0] = x[st.fidx]
    out[st.fidx, 1] = y[st.fidx]
    n_out = en.n_inverted(x, y)
    if not status:
        status = "untangled" if n_out == 0 else "failed"
    secs = time.perf_counter() - t_start
    info.update(
        iterations=total,
        rounds=rounds,
        n_inverted_out=n_out,
        min_det=float(np.min(en.dets(x, y))),
        eps_history=eps_hist,
        seconds=secs,
        seconds_per_iter=secs / max(total, 1),
        status=status,
    )
    return out, info


def lift_min_quality(
    points: np.ndarray,
    groups: Mapping[int, np.ndarray],
    free: np.ndarray,
    *,
    rounds: int = 6,
    progress: Callable[[int, int, float, float], Any] | None = None,
    lbfgs: Callable[..., tuple[np.ndarray, int]] | None = None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Raise the worst element quality of a valid mesh without lowering its mean quality.

    Maximises the mean quality q_avg subject to a soft floor q_e >= qc on every element
    (`_LiftEnergy`, guarded L-BFGS: the mesh stays valid), first with qc = the input's q_min,
    then for up to `rounds` rounds with a rising floor, each over only the free nodes within
    LIFT_RINGS rings of the elements under the new floor. A round is kept only when q_min
    rises, q_avg stays within LIFT_AVG_DROP (relative) of the best q_avg seen and, once q_min
    >= LIFT_POOR q_avg, at least the input's, and any q_avg it costs buys at least LIFT_RATE
    times as much q_min.
    Returns (points, info) with the kept iterate: the input itself (bit-identical) when
    nothing qualifies or the input has an inverted element. info: iterations, rounds (kept),
    q_min_in, q_avg_in, q_min_out, q_avg_out, trail ((q_min, q_avg) after each run), seconds,
    status ("lifted", "unchanged", "cancelled").
    progress(iterations, rounds_done, q_min, q_avg) after each run and every few tenths of a
    second inside one, with the kept iterate's qualities; a falsy answer other than None
    cancels (`stops`) and the input is returned.
    lbfgs: a drop-in for `_lbfgs` (same arguments and result), e.g. the OpenCL solver.
    """
    t_start = time.perf_counter()
    P, free = _checked_input(points, free)
    run_lbfgs = lbfgs or _lbfgs
    en = _LiftEnergy(P, groups, free)
    st = _State(P, free)
    info: dict[str, Any] = {"iterations": 0, "rounds": 0, "status": "unchanged"}
    q = en.element_quality(st.x, st.y) if en.n_elem else np.zeros(0)
    m0 = float(q.min()) if q.size else 0.0
    a0 = float(q.mean()) if q.size else 0.0
    info.update(q_min_in=m0, q_avg_in=a0, q_min_out=m0, q_avg_out=a0)
    if q.size == 0 or st.nf == 0 or not m0 > 0.0 or not np.all(np.isfinite(P)):
        info["seconds"] = time.perf_counter() - t_start
        return P, info

    best_v, best_m, best_a = None, m0, a0
    v = st.pack(st.x, st.y)
    cur_m, cur_a = m0, a0
    peak = a0  # the best q_avg seen: q_avg may fall at most LIFT_AVG_DROP below it
    total = 0
    trail: list[tuple[float, float]] = []  # (q_min, q_avg) after each run, kept or not
    info["trail"] = trail
    cancel = False
    for r in range(rounds + 1):
        en.qc = m0 if r == 0 else min(cur_m * LIFT_GROW, cur_m + LIFT_GAP * (cur_a - cur_m))
        tick = None
        if progress is not None:

            def tick(
                it: int, done: int = total, r: int = r, m: float = cur_m, a: float = cur_a
            ) -> bool:
                nonlocal cancel
                cancel = cancel or stops(progress(done + it, r, m, a))
                return not cancel

        if r == 0:  # the whole mesh: maximise q_avg at the input's floor
            vt, its = run_lbfgs(
                en, st, v, EPS_MIN, max_it=LIFT_FIRST_ITER, guard=True, rel_tol=LIFT_REL_TOL,
                tick=tick,
            )
            xt, yt = st.unpack(vt)
        else:  # only near the elements under the new floor: the rest is at its optimum
            x, y = st.unpack(v)
            sub, nodes, sfree = _active_submesh(groups, free, q < LIFT_ACTIVE * en.qc, LIFT_RINGS)
            if not sfree.any():
                break
            sp = np.stack([x[nodes], y[nodes]], axis=1)
            sen = _LiftEnergy(sp, sub, sfree)
            sen.qc = en.qc
            sst = _State(sp, sfree)
            sv, its = run_lbfgs(
                sen, sst, sst.pack(sst.x, sst.y), EPS_MIN, max_it=LIFT_ITER, guard=True,
                rel_tol=LIFT_REL_TOL, tick=tick,
            )
            sx, sy = sst.unpack(sv)
            xt, yt = x.copy(), y.copy()
            xt[nodes], yt[nodes] = sx, sy
            vt = st.pack(xt, yt)
        total += its
        qt = en.element_quality(xt, yt)
        qm, qa = float(qt.min()), float(qt.mean())
        trail.append((qm, qa))
        if cancel or (progress is not None and stops(progress(total, r, cur_m, cur_a))):
            info.update(iterations=total, status="cancelled", seconds=time.perf_counter() - t_start)
            return P, info
        if r == 0:  # the first run maximises q_avg at the input's floor: the start of the climb
            v, q, cur_m, cur_a = vt, qt, qm, qa
            peak = max(peak, qa)
        else:
            floor = (1.0 - LIFT_AVG_DROP) * peak
            if cur_m >= LIFT_POOR * cur_a:
                floor = max(floor, a0)
            if qa < floor or qm <= cur_m or (qa < cur_a and qm - cur_m < LIFT_RATE * (cur_a - qa)):
                break
            v, q, cur_m, cur_a = vt, qt, qm, qa
            peak = max(peak, qa)
            info["rounds"] = r
        if (cur_a >= a0 or info["rounds"]) and cur_m > best_m:
            best_v, best_m, best_a = v, cur_m, cur_a

    info.update(iterations=total, seconds=time.perf_counter() - t_start)
    if best_v is None:
        return P, info
    x, y = st.unpack(best_v)
    P[st.fidx, 0] = x[st.fidx]
    P[st.fidx, 1] = y[st.fidx]
    info.update(q_min_out=best_m, q_avg_out=best_a, status="lifted")
    return P, info
