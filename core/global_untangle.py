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

import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

__all__ = ["lift_min_quality", "untangle_global"]

THETA = 1.0 / 16.0  # weight of the area term g against the shape term f
LBFGS_MEMORY = 8  # L-BFGS (s, y) pairs kept
INNER_ITER = 60  # L-BFGS iterations between two eps updates
SIZE_SMOOTHING = 2  # smoothing passes of the reference-size field
EPS_MIN = 1e-9  # floor of eps (J is dimensionless: dets are ~1 at the reference size)
SIGMA_MIN = 0.1  # the paper's lower bound on sigma
TICK_EVERY = 20  # progress is reported this often inside a long polish run
STOP_REL_DECREASE = 1e-3  # stop polishing when one round lowers F by less than this (relative)
# lift_min_quality (max mean quality subject to a rising quality floor; see the docs)
LIFT_FIRST_ITER = 150  # L-BFGS iterations of the first run (floor = the input's q_min)
LIFT_ITER = 100  # L-BFGS iterations per later round
LIFT_GROW = 1.15  # floor of the next round: min(q_min * GROW, q_min + GAP * (q_avg - q_min))
LIFT_GAP = 0.15
LIFT_RATE = 3.0  # a round that lowers q_avg must raise q_min by at least RATE times as much
LIFT_PENALTY = 1000.0  # weight of the one-sided quadratic floor penalty
LIFT_BARRIER = 0.01  # weight of sum 1/q_corner (keeps every corner away from det = 0)
LIFT_RINGS = 6  # rounds after the first move only the nodes within this many rings of ...
LIFT_ACTIVE = 1.0  # ... the elements with q < LIFT_ACTIVE * floor (a small local problem)
LIFT_REL_TOL = 1e-6  # a lift run stops when 5 iterations lower F by less than this (relative)
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
    d = points[edges[1]] - points[edges[0]]
    elen = np.hypot(d[:, 0], d[:, 1])
    positive = elen[elen > 0]
    floor = 1e-3 * (float(np.mean(positive)) if positive.size else 1.0)
    elen = np.maximum(elen, floor)
    cnt = np.bincount(edges[0], minlength=n_nodes).astype(np.float64)
    hn = np.bincount(edges[0], weights=elen, minlength=n_nodes)
    hn = hn + np.bincount(edges[1], weights=elen, minlength=n_nodes)
    hn = np.maximum(hn / np.maximum(2.0 * cnt, 1.0), floor)
    lh = np.log(hn)
    deg = arity.astype(np.float64)
    le = np.bincount(edge_elem, weights=lh[edges[0]], minlength=n_elem) / deg
    for _ in range(SIZE_SMOOTHING):
        lh = np.bincount(edges[0], weights=le[edge_elem], minlength=n_nodes)
        lh = np.where(cnt > 0, lh / np.maximum(cnt, 1.0), np.log(floor))
        le = np.bincount(edge_elem, weights=lh[edges[0]], minlength=n_elem) / deg
    size = np.exp(le)
    ref_area = arity * size**2 / (4.0 * np.tan(np.pi / arity))
    x0, y0 = points[edges[0]].T
    x1, y1 = points[edges[1]].T
    dom_area = 0.5 * float(np.sum(x0 * y1 - x1 * y0))
    total = float(np.sum(ref_area))
    if dom_area > 0.0 and total > 0.0:
        size = size * np.sqrt(dom_area / total)
    return size, np.exp(lh)


# --------------------------------------------------------------------------- energy


def _chi(d: np.ndarray, eps: float, root: np.ndarray) -> np.ndarray:
    """chi(D, eps) = (D + sqrt(eps^2 + D^2)) / 2, without cancellation for D < 0."""
    return np.where(d >= 0.0, 0.5 * (d + root), (0.5 * eps * eps) / (root + np.abs(d)))


def _chi_scalar(d: float, eps: float) -> float:
    root = float(np.sqrt(eps * eps + d * d))
    return 0.5 * (d + root) if d >= 0.0 else 0.5 * eps * eps / (root - d)


class _Energy:
    """F_eps over the corner triangles that touch a free node, with its gradient."""

    def __init__(self, points: np.ndarray, groups: Mapping[int, np.ndarray], free: np.ndarray):
        self.n_nodes = points.shape[0]
        faces, arity, edges, edge_elem = _tables(groups)
        self.n_elem = arity.shape[0]
        # validity check: every corner of every element (triangles: one is enough)
        self.v0, self.v1, self.v2, self.veid = _corners(faces, all_corners=False)
        if self.n_elem == 0:
            self.i0 = self.i1 = self.i2 = np.zeros(0, dtype=np.int64)
            return
        size, hnode = _reference_sizes(points, arity, edges, edge_elem)
        i0, i1, i2, eid = self.v0, self.v1, self.v2, self.veid
        keep = free[i0] | free[i1] | free[i2]  # other corners have a constant energy
        self.i0, self.i1, self.i2 = i0[keep], i1[keep], i2[keep]
        n = arity[eid[keep]].astype(np.float64)
        s = size[eid[keep]]
        a = (n - 2.0) * np.pi / n
        # W = s [[1, cos a], [0, sin a]]  ->  W^-1 = [[1, -cot a], [0, 1 / sin a]] / s
        self.w00 = 1.0 / s
        self.w01 = -np.cos(a) / (np.sin(a) * s)
        self.w11 = 1.0 / (np.sin(a) * s)
        # One weight per element (spread over its corners): uniform, not the reference area;
        # area weights let small elements absorb all distortion (see the docs).
        self.weight = np.where(n == 3.0, 1.0, 1.0 / n)
        self.idx = np.concatenate([self.i1, self.i2, self.i0])
        # Diagonal L-BFGS preconditioner: with uniform weights the Hessian at a node scales
        # like 1 / size^2, so moves are scaled by size^2.
        self.precond = (hnode / float(np.mean(hnode))) ** 2
        self.h_mean = float(np.mean(size))
        self.power = 1.0

    def _jac(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
        x0 = x[self.i0]
        y0 = y[self.i0]
        e1x = x[self.i1] - x0
        e1y = y[self.i1] - y0
        e2x = x[self.i2] - x0
        e2y = y[self.i2] - y0
        j00 = e1x * self.w00
        j10 = e1y * self.w00
        j01 = e1x * self.w01 + e2x * self.w11
        j11 = e1y * self.w01 + e2y * self.w11
        return j00, j01, j10, j11

    def dets(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """det J of every energy corner."""
        j00, j01, j10, j11 = self._jac(x, y)
        return j00 * j11 - j01 * j10

    def value(self, x: np.ndarray, y: np.ndarray, eps: float) -> float:
        """F_eps."""
        j00, j01, j10, j11 = self._jac(x, y)
        d = j00 * j11 - j01 * j10
        num = (1.0 - THETA) * (j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11)
        num += THETA * (d * d + 1.0)
        chi = _chi(d, eps, np.sqrt(eps * eps + d * d))
        u = num / chi
        if self.power != 1.0:
            u = (0.5 * u) ** self.power
        return float(np.sum(self.weight * u))

    def value_grad(
        self, x: np.ndarray, y: np.ndarray, eps: float
    ) -> tuple[float, np.ndarray, np.ndarray, float]:
        """F_eps, dF/dx, dF/dy over all nodes (non-free rows included), and min det J."""
        j00, j01, j10, j11 = self._jac(x, y)
        d = j00 * j11 - j01 * j10
        t = j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11
        root = np.sqrt(eps * eps + d * d)
        chi = _chi(d, eps, root)
        num = (1.0 - THETA) * t + THETA * (d * d + 1.0)
        inv_chi = self.weight / chi
        if self.power != 1.0:  # F = sum w (u / 2)^p with u = num / chi
            u = 0.5 * num / chi
            up = u**self.power
            energy = float(np.sum(self.weight * up))
            inv_chi = inv_chi * (0.5 * self.power) * (up / u)
        else:
            energy = float(np.sum(num * inv_chi))
        # dF/dJ = a J + b cof(J); cof(J) = [[j11, -j10], [-j01, j00]]; dchi/dD = chi / root
        a = (2.0 * (1.0 - THETA)) * inv_chi
        b = inv_chi * (2.0 * THETA * d - num / root)
        g00 = a * j00 + b * j11
        g01 = a * j01 - b * j10
        g10 = a * j10 - b * j01
        g11 = a * j11 + b * j00
        # dF/dE = dF/dJ W^-T with E = [e1, e2]
        ge1x = g00 * self.w00 + g01 * self.w01
        ge1y = g10 * self.w00 + g11 * self.w01
        ge2x = g01 * self.w11
        ge2y = g11 * self.w11
        n = self.n_nodes
        gx = np.bincount(self.idx, np.concatenate([ge1x, ge2x, -(ge1x + ge2x)]), minlength=n)
        gy = np.bincount(self.idx, np.concatenate([ge1y, ge2y, -(ge1y + ge2y)]), minlength=n)
        return energy, gx, gy, float(np.min(d))

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
        super().__init__(points, groups, free)
        self.qc = 0.0
        if self.n_elem == 0:
            return
        _faces, arity, edges, edge_elem = _tables(groups)
        size, _ = _reference_sizes(points, arity, edges, edge_elem)
        self.i0, self.i1, self.i2, self.eid = self.v0, self.v1, self.v2, self.veid
        n = arity[self.eid].astype(np.float64)
        s = size[self.eid]
        a = (n - 2.0) * np.pi / n
        self.w00 = 1.0 / s
        self.w01 = -np.cos(a) / (np.sin(a) * s)
        self.w11 = 1.0 / (np.sin(a) * s)
        self.weight = np.where(n == 3.0, 1.0, 1.0 / n)
        self.n_corners = np.bincount(self.eid, minlength=self.n_elem).astype(np.float64)
        self.idx = np.concatenate([self.i1, self.i2, self.i0])

    def _corner_u(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
        j00, j01, j10, j11 = self._jac(x, y)
        d = j00 * j11 - j01 * j10
        t = j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11
        u = 0.5 * t / np.where(d > 0.0, d, np.inf)  # 1 / q_k; inf (q_k = 0) when not positive
        return j00, j01, j10, j11, d, t, u

    def element_quality(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(E,) mean ratio of each element (0 where a corner is not positive)."""
        *_, d, _t, u = self._corner_u(x, y)
        q = np.bincount(self.eid, 1.0 / u, minlength=self.n_elem) / self.n_corners
        bad = np.bincount(self.eid, d <= 0.0, minlength=self.n_elem) > 0
        return np.where(bad, 0.0, q)

    def value(self, x: np.ndarray, y: np.ndarray, eps: float) -> float:
        return self.value_grad(x, y, eps)[0]

    def value_grad(
        self, x: np.ndarray, y: np.ndarray, eps: float
    ) -> tuple[float, np.ndarray, np.ndarray, float]:
        j00, j01, j10, j11, d, _t, u = self._corner_u(x, y)
        dmin = float(np.min(d))
        n = self.n_nodes
        if not dmin > 0.0:  # only reached by rejected trial steps: infinite energy
            z = np.zeros(n)
            return float("inf"), z, z, dmin
        q = np.bincount(self.eid, 1.0 / u, minlength=self.n_elem) / self.n_corners
        gap = np.maximum(self.qc - q, 0.0) / self.qc
        energy = float(np.sum(LIFT_PENALTY * gap * gap - q))
        energy += LIFT_BARRIER * float(np.sum(self.weight * u))
        de_dq = -1.0 - (2.0 * LIFT_PENALTY / self.qc) * gap  # dF / dq_e
        # dq_e / du_k = -1 / (n_e u_k^2); u_k = t / (2 d): du/dJ = J / d - u cof(J) / d
        de_du = de_dq[self.eid] * (-1.0 / self.n_corners[self.eid]) / (u * u)
        de_du = de_du + LIFT_BARRIER * self.weight
        a = de_du / d
        b = -de_du * u / d
        g00 = a * j00 + b * j11
        g01 = a * j01 - b * j10
        g10 = a * j10 - b * j01
        g11 = a * j11 + b * j00
        ge1x = g00 * self.w00 + g01 * self.w01
        ge1y = g10 * self.w00 + g11 * self.w01
        ge2x = g01 * self.w11
        ge2y = g11 * self.w11
        gx = np.bincount(self.idx, np.concatenate([ge1x, ge2x, -(ge1x + ge2x)]), minlength=n)
        gy = np.bincount(self.idx, np.concatenate([ge1y, ge2y, -(ge1y + ge2y)]), minlength=n)
        return energy, gx, gy, dmin


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
    or when tick(iterations so far), called every TICK_EVERY iterations, returns False.
    Returns the last accepted point and the number of iterations done.
    """
    v = v0
    e, gx, gy, _ = en.value_grad(*st.unpack(v), eps)
    g = st.pack(gx, gy)
    dpre = np.tile(en.precond[st.fidx], 2)
    s_hist: list[np.ndarray] = []
    y_hist: list[np.ndarray] = []
    rho_hist: list[float] = []
    e_hist = [e]
    h0 = 0.1 * en.h_mean  # first step: the fastest node moves a tenth of a typical edge
    it = 0
    while it < max_it:
        it += 1
        q = -g
        alphas = []
        for s, yv, rho in zip(reversed(s_hist), reversed(y_hist), reversed(rho_hist), strict=True):
            al = rho * _dot(s, q)
            alphas.append(al)
            q -= al * yv
        if s_hist:
            q *= dpre * (_dot(s_hist[-1], y_hist[-1]) / _dot(y_hist[-1], dpre * y_hist[-1]))
            for s, yv, rho, al in zip(s_hist, y_hist, rho_hist, reversed(alphas), strict=True):
                q += (al - rho * _dot(yv, q)) * s
            step = 1.0
        else:
            q *= dpre
            qmax = float(np.max(np.abs(q)))
            step = h0 / qmax if qmax > 0.0 else 0.0
        slope = _dot(g, q)
        if not slope < 0.0:  # not a descent direction: restart from preconditioned descent
            s_hist, y_hist, rho_hist = [], [], []
            q = -dpre * g
            slope = _dot(g, q)
            qmax = float(np.max(np.abs(q)))
            step = h0 / qmax if qmax > 0.0 else 0.0
            if not slope < 0.0:
                break
        accepted = False
        for _ in range(40):
            vt = v + step * q
            xt, yt = st.unpack(vt)
            et, gxt, gyt, dmin_t = en.value_grad(xt, yt, eps)
            if (
                np.isfinite(et)
                and et <= e + 1e-4 * step * slope
                and not (guard and dmin_t <= 0.0)
            ):
                accepted = True
                break
            step *= 0.5
        if not accepted:
            if s_hist:  # drop the memory and retry once from plain descent
                s_hist, y_hist, rho_hist = [], [], []
                continue
            break
        gt = st.pack(gxt, gyt)
        s = vt - v
        yv = gt - g
        sy = _dot(s, yv)
        if sy > 1e-12 * float(np.sqrt(_dot(s, s) * _dot(yv, yv))):
            s_hist.append(s)
            y_hist.append(yv)
            rho_hist.append(1.0 / sy)
            if len(s_hist) > LBFGS_MEMORY:
                del s_hist[0], y_hist[0], rho_hist[0]
        v, e, g = vt, et, gt
        if not guard and dmin_t > 0.0:  # just became valid: hand over to the guarded polish
            break
        e_hist.append(e)
        if len(e_hist) > 5 and e_hist[-6] - e <= rel_tol * abs(e_hist[-6]):
            break
        if tick is not None and it % TICK_EVERY == 0 and tick(it) is False:
            break
    return v, it


# --------------------------------------------------------------------------- driver


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
    progress(iterations, max_iter, n_inverted) is called after each round; False cancels.
    lbfgs: a drop-in for `_lbfgs` (same arguments and result), e.g. the OpenCL solver.

    Returns (new points, info); non-free rows are bit-identical to the input. Once valid, steps
    that would invert a corner are rejected, so a valid iterate stays valid; when no valid one
    was reached, the iterate with the fewest inverted elements is returned.
    info: iterations, rounds, n_inverted_in, n_inverted_out, min_det (smallest normalised corner
    det), eps_history, seconds, seconds_per_iter, status ("untangled" / "failed" / "cancelled" /
    "nothing to do").
    """
    t_start = time.perf_counter()
    P = np.array(points, dtype=np.float64, copy=True)
    free = np.asarray(free, dtype=bool).reshape(-1)
    if P.ndim != 2 or P.shape[1] != 2 or free.shape[0] != P.shape[0]:
        raise ValueError("points must be (N, 2) and free (N,)")
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
        if progress is not None and guard:  # long polish runs report (and cancel) from inside

            def tick(it: int, done: int = total, n_now: int = best_inv) -> bool:
                nonlocal cancel
                cancel = cancel or progress(done + it, max_iter, n_now) is False
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
        if cancel or (progress is not None and progress(total, max_iter, n_inv) is False):
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
    progress: Callable[[int, int], Any] | None = None,
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
    progress(iterations, rounds_done) after each run; False cancels (the input is returned).
    lbfgs: a drop-in for `_lbfgs` (same arguments and result), e.g. the OpenCL solver.
    """
    t_start = time.perf_counter()
    P = np.array(points, dtype=np.float64, copy=True)
    free = np.asarray(free, dtype=bool).reshape(-1)
    if P.ndim != 2 or P.shape[1] != 2 or free.shape[0] != P.shape[0]:
        raise ValueError("points must be (N, 2) and free (N,)")
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
    for r in range(rounds + 1):
        en.qc = m0 if r == 0 else min(cur_m * LIFT_GROW, cur_m + LIFT_GAP * (cur_a - cur_m))
        if r == 0:  # the whole mesh: maximise q_avg at the input's floor
            vt, its = run_lbfgs(
                en, st, v, EPS_MIN, max_it=LIFT_FIRST_ITER, guard=True, rel_tol=LIFT_REL_TOL
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
                rel_tol=LIFT_REL_TOL,
            )
            sx, sy = sst.unpack(sv)
            xt, yt = x.copy(), y.copy()
            xt[nodes], yt[nodes] = sx, sy
            vt = st.pack(xt, yt)
        total += its
        qt = en.element_quality(xt, yt)
        qm, qa = float(qt.min()), float(qt.mean())
        trail.append((qm, qa))
        if progress is not None and progress(total, r) is False:
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
