"""The global stage's energies: foldover-free (Garanzha et al. 2021) and the lift (mean ratio).

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
positive det on every corner is exactly the mean ratio's validity (docs/method.md 3), and
f = 2 / q_k for eps -> 0);
a triangle contributes one corner (all three give the same J up to a rotation) with the
equilateral triangle as reference. Reference edge lengths follow the local mean edge length,
smoothed, and are scaled so the reference areas add up to the domain area.

eps continuation (the paper's rule): after each inner L-BFGS run,
sigma = max(1 - F_eps(x_new) / F_eps(x_old), 1/10), mu = (1 - sigma) chi(D_-, eps) with D_- the
smallest det, and the new eps solves chi(D_-, eps_new) = mu, i.e. eps_new = 2 sqrt(mu (mu - D_-))
(or the floor when D_- >= mu). Details and measurements: docs/global_untangle.md.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping

import numpy as np

from .. import fpmath
from ..mesh.csr import bincount_csr, ragged_arange
from .mesh_tables import (
    Factors,
    corner_factor_values,
    corner_triangles,
    mesh_tables,
    per_arity,
    reference_sizes,
)
from .state import LIMIT_MARGIN, TICK_CORNERS, TICK_EVERY, State

__all__ = ["FoldoverEnergy", "LiftEnergy", "chi_array", "chi_scalar", "energy_defines"]

THETA = 1.0 / 16.0  # weight of the area term g against the shape term f
LIFT_PENALTY = 1000.0  # weight of the one-sided quadratic floor penalty
LIFT_BARRIER = 0.01  # weight of sum 1/q_corner (keeps every corner away from det = 0)


def energy_defines() -> dict[str, float]:
    """The energies' constants under their kernel names (build defines of both solvers)."""
    return {"THETA": THETA, "PENALTY": LIFT_PENALTY, "BARRIER": LIFT_BARRIER}


def chi_array(d: np.ndarray, eps: float, root: np.ndarray) -> np.ndarray:
    """chi(D, eps) = (D + sqrt(eps^2 + D^2)) / 2, without cancellation for D < 0."""
    return np.where(d >= 0.0, 0.5 * (d + root), (0.5 * eps * eps) / (root + np.abs(d)))


def chi_scalar(d: float, eps: float) -> float:
    root = float(np.sqrt(eps * eps + d * d))
    return 0.5 * (d + root) if d >= 0.0 else 0.5 * eps * eps / (root - d)


LIMIT_PIECE = 16384  # corners per piece of `step_limit` (its arrays stay in cache)
PIECE = 65536  # corners per piece of `_jac` and of the scratch-free measures (in cache)


def _corner_limit(j: np.ndarray, cc: np.ndarray, f: np.ndarray, w00: np.ndarray,
                  w01: np.ndarray, w11: np.ndarray, s0: float) -> float:
    """`FoldoverEnergy.step_limit` of some corners: j the (4, m) rows [j00, j10, j01, j11]
    of J at the point and cc = det J (as `_jac` computes them), f the (6, m) corner
    coordinates (x1, y1, x2, y2, x0, y0) of the direction."""
    j00, j10, j01, j11 = j
    f1x, f1y, f2x, f2y = f[0] - f[4], f[1] - f[5], f[2] - f[4], f[3] - f[5]
    k00, k10 = f1x * w00, f1y * w00
    k01, k11 = f1x * w01 + f2x * w11, f1y * w01 + f2y * w11
    # det(J + t K) = cc + bb t + aa t^2
    bb = (j00 * k11 + k00 * j11) - (j01 * k10 + k01 * j10)
    aa = k00 * k11 - k01 * k10
    # A corner whose det stays positive on [0, 2 s0] (its lower bound there is) cannot
    # change which trial steps are skipped: its limit is above s0. Most corners are such.
    s1 = 2.0 * s0
    risky = np.flatnonzero(~(cc + np.minimum(bb, 0.0) * s1 + np.minimum(aa, 0.0) * (s1 * s1) > 0.0))
    if risky.size == 0:
        return np.inf
    if risky.size < cc.size:
        cc, bb, aa = cc[risky], bb[risky], aa[risky]
    with np.errstate(all="ignore"):
        pos = cc > 0.0
        t1 = np.where(pos & (aa == 0.0) & (bb < 0.0), -cc / bb, np.inf)
        disc = bb * bb - (4.0 * aa) * cc
        ok = pos & (aa != 0.0) & (disc >= 0.0)
        sq = np.sqrt(np.where(ok, disc, 0.0))
        qq = -0.5 * (bb + np.where(bb >= 0.0, sq, -sq))
        r1, r2 = qq / aa, cc / qq
        lo, hi = np.where(r1 < r2, r1, r2), np.where(r1 < r2, r2, r1)
        # aa < 0: one positive root, negative beyond it; aa > 0, bb < 0: negative between
        t1 = np.where(ok & (aa < 0.0), hi, t1)
        inside = ok & (aa > 0.0) & (bb < 0.0) & (hi * (1.0 - LIMIT_MARGIN) >= s0)
        t1 = np.where(inside, lo, t1)
    return float(np.minimum.reduce(t1)) if t1.size else np.inf


class _Blocks:
    """Preallocated per-corner arrays of one energy, with views of their blocks made once.

    `evaluate` fills them and `gradient` reads what the last `evaluate` left, so one
    evaluation is in flight at a time (as in `lbfgs`: the gradient right after the accepted
    trial point).
    Scratch that is dead by then shares memory: squares of J with dF/dJ, edges with dF/dE.
    Constants are full-length arrays: NumPy multiplies two arrays faster than an array and a
    Python float, with the same result.
    """

    def __init__(self, m: int, w00: np.ndarray, w01: np.ndarray, w11: np.ndarray):
        self.m = m
        two = [np.concatenate([w, w]) for w in (w00, w01, w11)]
        self.w00, self.w01, self.w11 = two  # W^-1 entries for [x, y] pairs of blocks
        # z[gather] = [x1, y1, x2, y2, x0, y0]; e1 = [e1x, e1y], e2 = [e2x, e2y]
        self.c = np.empty(6 * m)
        self.j = np.empty(4 * m)  # [j00, j10, j01, j11]
        self.g = np.empty(4 * m)  # dF/dJ, the same order
        self.sq = self.g  # J squared, entry by entry
        # dF/dE per corner node: [ge1x, ge1y, ge2x, ge2y, -(ge1x + ge2x), -(ge1y + ge2y)]
        self.ge = np.empty(6 * m)
        self.e1, self.e2 = self.ge[: 2 * m], self.ge[2 * m : 4 * m]  # edges (while J is made)
        for name in ("d", "t", "dd", "root", "chi", "num", "inv_chi", "u", "a", "b", "tmp"):
            setattr(self, name, np.empty(m))
        for name, value in (("half", 0.5), ("one", 1.0), ("theta", THETA)):
            setattr(self, name, np.full(m, value))
        self.one_theta = np.full(m, 1.0 - THETA)
        self.two_one_theta = np.full(m, 2.0 * (1.0 - THETA))
        self.two_theta = np.full(m, 2.0 * THETA)
        self.pieces = [self._piece(slice(lo, min(m, lo + PIECE)), m)
                       for lo in range(0, m, PIECE)]
        self.scatter_pieces = [self._scatter_piece(slice(lo, min(m, lo + PIECE)), m)
                               for lo in range(0, m, PIECE)]

    def _piece(self, k: slice, m: int) -> tuple[np.ndarray, ...]:
        """Views of one piece of corners k: its rows of c (6), e1, e2 (2 each), J (4), J
        squared (4), d, t, tmp, and its W^-1 entries (two equal rows, for x and y: NumPy
        multiplies two arrays of one shape faster than it broadcasts a row)."""
        c, j = self.c.reshape(6, m)[:, k], self.j.reshape(4, m)[:, k]
        sq = self.sq.reshape(4, m)[:, k]
        e1, e2 = self.e1.reshape(2, m)[:, k], self.e2.reshape(2, m)[:, k]
        w00, w01, w11 = (w.reshape(2, m)[:, k] for w in (self.w00, self.w01, self.w11))
        return (k, c, c[0:2], c[2:4], c[4:6], e1, e2, j, j[0:2], j[2:4], sq, self.d[k], self.t[k],
                self.tmp[k], w00, w01, w11)

    def _scatter_piece(self, k: slice, m: int) -> tuple[np.ndarray, ...]:
        """Views of one piece of corners k for `_scatter`: a, b, J (4 rows), dF/dJ (4 rows),
        dF/dE (6 rows), tmp and the W^-1 entries (two rows each, for x and y)."""
        g, ge = self.g.reshape(4, m)[:, k], self.ge.reshape(6, m)[:, k]
        w00, w01, w11 = (w.reshape(2, m)[:, k] for w in (self.w00, self.w01, self.w11))
        return (self.a[k], self.b[k], self.j.reshape(4, m)[:, k], g, g[0:2], g[2:4],
                ge[0:2], ge[2:4], ge[4:6], self.tmp[k], w00, w01, w11)


class FoldoverEnergy:
    """F_eps over the corner triangles that touch a free node, with its gradient.

    The hot path works on one flat coordinate vector z and a layout (gather index, scatter
    index, length of z): the whole-mesh measures use z = [x, y]; `lbfgs` uses z = [v, fixed
    coordinates], so it never unpacks or packs. `evaluate` gives F and min det J (all a line
    search needs), `gradient` the gradient of the point `evaluate` saw last. Per-corner quantities
    live in `_Blocks` (one NumPy call per block of M, no temporaries); every value is the same
    float operation on the same operands as the per-entry formula beside it.
    """

    def __init__(
        self, points: np.ndarray, groups: Mapping[int, np.ndarray], free: np.ndarray,
        factors: Factors | None = None,
    ):
        tabs = self._prepare(points, groups, free, factors)
        if tabs is None:
            return
        arity, size = tabs
        i0, i1, i2, eid = self.v0, self.v1, self.v2, self.veid
        keep = free[i0] | free[i1] | free[i2]  # other corners have a constant energy
        u = None if self.vu is None else tuple(a[keep] for a in self.vu)
        self._set_corners(i0[keep], i1[keep], i2[keep], arity[eid[keep]], size[eid[keep]], u)

    def _prepare(
        self, points: np.ndarray, groups: Mapping[int, np.ndarray], free: np.ndarray,
        factors: Factors | None,
    ):
        """Tables, validity corners (with their target factors), reference sizes and
        preconditioner: (arity, size), or None (and no energy corners) without elements."""
        self.n_nodes = points.shape[0]
        faces, arity, edges, edge_elem = mesh_tables(groups)
        self.n_elem = arity.shape[0]
        # validity check: every corner of every element (triangles: one is enough), except
        # frozen ones: made of fixed nodes only and not positive, so no move can change them
        v0, v1, v2, veid = corner_triangles(faces, all_corners=False)
        keep = free[v0] | free[v1] | free[v2]
        fixed = np.flatnonzero(~keep)  # corners of fixed nodes only: kept when positive
        if fixed.size:
            x, y = points[:, 0], points[:, 1]
            a, b, c = v0[fixed], v1[fixed], v2[fixed]
            keep[fixed] = (x[b] - x[a]) * (y[c] - y[a]) - (y[b] - y[a]) * (x[c] - x[a]) > 0.0
        every = bool(keep.all())  # the usual case: no copies
        self.v0, self.v1, self.v2, self.veid = (
            (v0, v1, v2, veid) if every else (v0[keep], v1[keep], v2[keep], veid[keep]))
        self.vu = None  # per validity corner (u00, u01, u11) of its target; None: regular
        if factors is not None:
            self.vu = tuple(a if every else a[keep]
                            for a in corner_factor_values(groups, factors, False))
        self.power = 1.0
        self._full = None  # the layout of z = [x, y], built on first use
        self._pack = None  # (state, layout, fixed coordinates, free nodes) of the last
        # lbfgs call
        if self.n_elem == 0:
            self.i0 = self.i1 = self.i2 = np.zeros(0, dtype=np.int64)
            return None
        size, hnode = reference_sizes(points, arity, edges, edge_elem)
        # Diagonal L-BFGS preconditioner: with uniform weights the Hessian at a node scales
        # like 1 / size^2, so moves are scaled by size^2.
        self.precond = (hnode / (fpmath.add_reduce(hnode) / hnode.size)) ** 2
        self.h_mean = fpmath.add_reduce(size) / size.size
        return arity, size

    def _set_corners(
        self, i0: np.ndarray, i1: np.ndarray, i2: np.ndarray, arity: np.ndarray, s: np.ndarray,
        u: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """Energy corners (k, k+1, k-1) with their element's arity, reference size and
        target factors u = (u00, u01, u11) (None: the regular polygon's corner)."""
        self.i0, self.i1, self.i2 = i0, i1, i2
        n = arity.astype(np.float64)
        if u is None:
            cos_a, sin_a = per_arity(arity, fpmath.regular_corner).T
            # W = s [[1, cos a], [0, sin a]]  ->  W^-1 = [[1, -cot a], [0, 1 / sin a]] / s
            self.w00 = 1.0 / s
            self.w01 = -cos_a / (sin_a * s)
            self.w11 = 1.0 / (sin_a * s)
        else:  # W = s [[u00, u01], [0, u11]] (regular: u00 = 1, the same bits as above)
            u00, u01, u11 = u
            self.w00 = 1.0 / (u00 * s)
            self.w01 = -u01 / (u00 * u11 * s)
            self.w11 = 1.0 / (u11 * s)
        # One weight per element (spread over its corners): uniform, not the reference area;
        # area weights let small elements absorb all distortion (see the docs).
        self.weight = np.where(n == 3.0, 1.0, 1.0 / n)
        self.idx = np.concatenate([self.i1, self.i2, self.i0])
        self.tick_every = max(1, min(TICK_EVERY, TICK_CORNERS // max(i0.size, 1)))
        self._blocks: _Blocks | None = None  # made on the first host evaluation

    def stiffness_precond(self) -> np.ndarray:
        """A per-node preconditioner that sees the targets' anisotropy: 1 / sqrt of the
        Jacobi diagonal of sum w |J|_F^2 (J = E W^-1, so a node's entry adds w |its row of
        W^-1|^2 over its corners), scaled to mean 1 over the nodes with corners (1 elsewhere).
        `precond`, the squared smoothed edge length, is blind to a boundary layer's aspect
        ratio: it scales a thin cell's nodes by its long edges (docs/global_untangle.md,
        "Settle")."""
        n, w, w00, w01, w11 = self.n_nodes, self.weight, self.w00, self.w01, self.w11
        d = np.bincount(self.i1, w * (w00 * w00 + w01 * w01), n)  # e1 = x1 - x0: W^-1 row 0
        d += np.bincount(self.i2, w * (w11 * w11), n)  # e2 = x2 - x0: row 1
        a = w01 + w11
        d += np.bincount(self.i0, w * (w00 * w00 + a * a), n)  # x0: minus both rows
        pos = np.flatnonzero(d > 0.0)
        pre = np.ones(n)
        if pos.size:
            inv = 1.0 / np.sqrt(d[pos])
            pre[pos] = inv / (fpmath.add_reduce(inv) / pos.size)
        return pre

    def with_precond(self, precond: np.ndarray) -> FoldoverEnergy:
        """This energy with another per-node preconditioner: a shallow copy (the corner
        tables shared, its own scratch), so a device solver, which keeps the tables of the
        energy it last solved, uploads this one's."""
        other = copy.copy(self)
        other.precond = precond
        other._blocks = None
        return other

    @property
    def _bk(self) -> _Blocks:
        """The host's per-corner scratch, made when a host evaluation first needs it: a
        device solve never does, so the run does not hold it (about 43 doubles per corner)."""
        if self._blocks is None:
            self._blocks = _Blocks(self.i0.size, self.w00, self.w01, self.w11)
        return self._blocks

    def _corner_du(self, k, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(det J, u = |J|_F^2 / (2 det J), 0 where det <= 0) of the corners k (a slice or
        ids), with temporaries of k's size: the operations of `_jac` in order (the same
        bits)."""
        i0, i1, i2 = self.i0[k], self.i1[k], self.i2[k]
        x0, y0 = x.take(i0), y.take(i0)
        e1x, e1y = x.take(i1) - x0, y.take(i1) - y0
        e2x, e2y = x.take(i2) - x0, y.take(i2) - y0
        w00, w01, w11 = self.w00[k], self.w01[k], self.w11[k]
        j00, j10 = e1x * w00, e1y * w00
        j01, j11 = e1x * w01 + e2x * w11, e1y * w01 + e2y * w11
        d = j00 * j11 - j01 * j10
        t = j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11
        return d, 0.5 * t / np.where(d > 0.0, d, np.inf)

    def _corner_u(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """(u of every corner (`_corner_du`), whether its det is <= 0, the smallest det), in
        pieces of PIECE corners, without the corner scratch of `_Blocks`."""
        m = self.i0.size
        u = np.empty(m)
        bad = np.empty(m, dtype=bool)
        dmin = np.inf
        for lo in range(0, m, PIECE):
            k = slice(lo, min(m, lo + PIECE))
            d, u[k] = self._corner_du(k, x, y)
            dmin = np.minimum(dmin, np.minimum.reduce(d))  # NaN, as np.minimum over all
            np.less_equal(d, 0.0, out=bad[k])
        return u, bad, float(dmin)

    # -- flat layouts ----------------------------------------------------------------------
    def flat_layout(self, pos: np.ndarray) -> tuple[np.ndarray, int]:
        """(index, length) for a flat z holding coordinate c of node i at pos[c, i].

        z[index] = [x1, y1, x2, y2, x0, y0] (blocks of M; corner nodes i1, i2, i0), and the
        same index bins the corner gradients [e1x, e1y, e2x, e2y, e0x, e0y]: each bin adds
        its terms in `idx` order (e1, e2, then -(e1 + e2)), as one bincount over idx per axis.
        """
        index = pos[:, np.stack([self.i1, self.i2, self.i0])]  # (axis, node, corner)
        return np.ascontiguousarray(index.transpose(1, 0, 2)).ravel(), pos.size

    def _full_layout(self) -> tuple[np.ndarray, int]:
        if self._full is None:
            self._full = self.flat_layout(np.arange(2 * self.n_nodes).reshape(2, self.n_nodes))
        return self._full

    def packed(self, st: State) -> tuple[tuple[np.ndarray, int], np.ndarray]:
        """Layout of z = [v, x_fixed, y_fixed] for `st`, and the fixed part of z (cached)."""
        if self._pack is None or self._pack[0] is not st:
            fixed = np.ones(self.n_nodes, dtype=bool)
            fixed[st.fidx] = False
            fix = np.flatnonzero(fixed)
            # the layout depends on the free nodes only: another state of the same free
            # nodes (a resumed solve's next call) keeps it
            if self._pack is not None and np.array_equal(self._pack[3], st.fidx):
                layout = self._pack[1]
            else:
                nf, nx = st.nf, fix.size
                pos = np.empty((2, self.n_nodes), dtype=np.int64)
                pos[0, st.fidx] = np.arange(nf)
                pos[1, st.fidx] = np.arange(nf, 2 * nf)
                pos[0, fix] = np.arange(2 * nf, 2 * nf + nx)
                pos[1, fix] = np.arange(2 * nf + nx, 2 * nf + 2 * nx)
                layout = self.flat_layout(pos)
            self._pack = (st, layout, np.concatenate([st.x[fix], st.y[fix]]), st.fidx)
        return self._pack[1], self._pack[2]

    # -- corner Jacobians ------------------------------------------------------------------
    def step_limit(self, z: np.ndarray, dz: np.ndarray, index: np.ndarray, s0: float,
                   at_point: bool = False) -> float:
        """The smallest step t at which some energy corner's det, a quadratic in t along
        z + t dz, turns non-positive and stays so up to s0 (inf: none, or every det stays
        positive up to 2 s0, which skips no trial either). The line search
        skips the trial steps above it: they would be rejected for a det <= 0 (see
        `solver.skipped_trials`). opencl/lbfgs_parallel.cl `limit_corner` is its twin, operation
        for operation. at_point: the last `evaluate` was at z, so J and det J there are
        still in the blocks (`gradient` leaves them) and are not computed again. The rest
        works in cache-sized pieces."""
        m, bk = self.i0.size, self._bk
        if not at_point:
            self._jac(z, index)
        j, f = bk.j.reshape(4, m), bk.ge.reshape(6, m)  # f: scratch until the next `evaluate`
        dz.take(index, None, bk.ge, "wrap")  # = dz[index]
        out = np.inf
        for lo in range(0, m, LIMIT_PIECE):
            hi = min(m, lo + LIMIT_PIECE)
            out = min(out, _corner_limit(j[:, lo:hi], bk.d[lo:hi], f[:, lo:hi], self.w00[lo:hi],
                                         self.w01[lo:hi], self.w11[lo:hi], s0))
        return out

    def _jac(self, z: np.ndarray, index: np.ndarray) -> None:
        """J = [j00, j10, j01, j11], d = det J and t = |J|_F^2 of every corner into the
        blocks, in pieces of PIECE corners (their temporaries stay in cache: about a
        third of the time of whole-array passes at 1M corners); each value is the same
        operation on the same operands as on whole arrays."""
        bk = self._bk
        mul, sub, add = np.multiply, np.subtract, np.add
        rows = index.reshape(6, bk.m)
        for k, c, c1, c2, c0, e1, e2, j, ja, jb, sq, d, t, tmp, w00, w01, w11 in bk.pieces:
            z.take(rows[:, k], None, c, "wrap")  # = z[index] (in range: wrap checks least)
            sub(c1, c0, e1)  # e1x = x[i1] - x[i0], e1y = y[i1] - y[i0]
            sub(c2, c0, e2)  # e2x = x[i2] - x[i0], e2y
            mul(e1, w00, ja)  # j00 = e1x w00, j10 = e1y w00
            mul(e1, w01, jb)
            add(jb, mul(e2, w11, e2), jb)  # j01 = e1x w01 + e2x w11
            mul(j[0], j[3], d)  # d = j00 j11 - j01 j10
            sub(d, mul(j[2], j[1], tmp), d)
            mul(j, j, sq)  # t = j00^2 + j01^2 + j10^2 + j11^2 (in that order)
            add(sq[0], sq[2], t)
            add(t, sq[1], t)
            add(t, sq[3], t)

    def _scatter(self, n_bins: int, index: np.ndarray):
        """Node gradient (flat, layout order) of dF/dJ = a J + b cof(J), cof(J) = [[j11, -j10],
        [-j01, j00]] (a, b: the blocks' `a` and `b`), through dF/dE = dF/dJ W^-T with
        E = [e1, e2]; the per-corner part runs in pieces like `_jac`."""
        bk = self._bk
        mul, add, sub = np.multiply, np.add, np.subtract
        for pa, pb, j, g, ga, gb, ge1, ge2, ge0, tmp, w00, w01, w11 in bk.scatter_pieces:
            add(mul(pa, j[0], g[0]), mul(pb, j[3], tmp), g[0])  # g00 = a j00 + b j11
            sub(mul(pa, j[1], g[1]), mul(pb, j[2], tmp), g[1])  # g10 = a j10 - b j01
            sub(mul(pa, j[2], g[2]), mul(pb, j[1], tmp), g[2])  # g01 = a j01 - b j10
            add(mul(pa, j[3], g[3]), mul(pb, j[0], tmp), g[3])  # g11 = a j11 + b j00
            mul(ga, w00, ge1)
            add(ge1, mul(gb, w01, ga), ge1)  # ge1x = g00 w00 + g01 w01, ge1y
            mul(gb, w11, ge2)  # ge2x = g01 w11, ge2y = g11 w11
            np.negative(add(ge1, ge2, ge0), ge0)  # -(ge1 + ge2)
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
        num = (1.0 - THETA) * self._bk.t
        num += THETA * (d * d + 1.0)
        ch = chi_array(d, eps, np.sqrt(eps * eps + d * d))
        u = num / ch
        if self.power != 1.0:
            u = fpmath.power(0.5 * u, self.power)
        return fpmath.add_reduce(self.weight * u)

    def evaluate(self, z: np.ndarray, layout, eps: float) -> tuple[float, float, bool]:
        """(F_eps, min det J, whether `gradient` may follow) at the flat coordinates z."""
        bk = self._bk
        self._jac(z, layout[0])
        d, dd, root, chi, num, inv_chi = bk.d, bk.dd, bk.root, bk.chi, bk.num, bk.inv_chi
        dmin = float(np.minimum.reduce(d))
        np.multiply(d, d, dd)
        np.sqrt(np.add(dd, eps * eps, root), root)  # sqrt(eps^2 + d^2)
        if dmin >= 0.0:  # no D < 0: chi's first branch, 0.5 (d + root), everywhere
            np.multiply(bk.half, np.add(d, root, chi), chi)
        else:
            chi[:] = chi_array(d, eps, root)
        np.multiply(bk.one_theta, bk.t, num)  # (1 - theta) t + theta (d^2 + 1)
        np.add(num, np.multiply(bk.theta, np.add(dd, bk.one, bk.tmp), bk.tmp), num)
        np.divide(self.weight, chi, inv_chi)
        if self.power != 1.0:  # F = sum w (u / 2)^p with u = num / chi
            u = 0.5 * num / chi
            up = fpmath.power(u, self.power)
            energy = fpmath.add_reduce(self.weight * up)
            np.multiply(inv_chi, 0.5 * self.power, inv_chi)  # inv_chi (p / 2) (up / u)
            np.multiply(inv_chi, up / u, inv_chi)
        else:
            energy = fpmath.add_reduce(np.multiply(num, inv_chi, bk.tmp))
        return energy, dmin, True

    def gradient(self, layout) -> np.ndarray:
        """dF/dz at the point `evaluate` saw last."""
        bk = self._bk
        # dF/dJ = a J + b cof(J); dchi/dD = chi / root
        np.multiply(bk.two_one_theta, bk.inv_chi, bk.a)  # a = 2 (1 - theta) inv_chi
        b = np.multiply(bk.two_theta, bk.d, bk.b)  # inv_chi (2 theta d - num / root)
        np.multiply(bk.inv_chi, np.subtract(b, np.divide(bk.num, bk.root, bk.tmp), b), b)
        return self._scatter(layout[1], layout[0])

    def n_inverted(self, x: np.ndarray, y: np.ndarray) -> int:
        """Elements with a corner det <= 0 (docs/method.md 3)."""
        x0 = x[self.v0]
        y0 = y[self.v0]
        det = (x[self.v1] - x0) * (y[self.v2] - y0) - (y[self.v1] - y0) * (x[self.v2] - x0)
        bad = det <= 0.0
        if not bad.any():
            return 0
        return int(np.count_nonzero(np.bincount(self.veid[bad], minlength=self.n_elem)))


class LiftEnergy(FoldoverEnergy):
    """F = sum_e [ -q_e + PENALTY ((qc - q_e)_+ / qc)^2 ] + BARRIER sum_corners w / q_k.

    q_k = 2 det / |J|_F^2 is the corner's mean ratio (theta = 0, eps -> 0) and q_e the mean
    over the element's corners (docs/method.md 3). The first term maximises q_avg itself, the
    second is a soft floor qc on every element's quality, the third a barrier per corner (the
    mean alone lets one corner of a polygon collapse). Every corner of every element is kept,
    so element means are complete; only valid (guarded) iterates are evaluated.
    """

    def __init__(
        self, points: np.ndarray, groups: Mapping[int, np.ndarray], free: np.ndarray,
        factors: Factors | None = None,
    ):
        tabs = self._prepare(points, groups, free, factors)
        self.qc = 0.0
        if tabs is None:
            return
        arity, size = tabs
        self.eid = self.veid
        self._set_corners(self.v0, self.v1, self.v2, arity[self.eid], size[self.eid], self.vu)
        self.n_corners = np.bincount(self.eid, minlength=self.n_elem).astype(np.float64)
        # triangles only: corner k is element k, so per-element sums and gathers are copies
        self._one_each = self.eid.size == self.n_elem and bool(
            np.array_equal(self.eid, np.arange(self.n_elem)))
        self._neg_inv_nc = -1.0 / self.n_corners[self.eid]  # dq_e / du_k = this / u_k^2
        self._barrier_w = LIFT_BARRIER * self.weight
        self._gap = np.empty(0)  # the last `evaluate`'s (qc - q_e)_+ / qc
        ne = self.n_elem  # per-element constants (array operands: faster than floats)
        self._zero_e, self._pen_e, self._m1_e = (np.full(ne, c) for c in (0.0, LIFT_PENALTY, -1.0))
        self._qc_e = np.empty(ne)  # filled with qc, then with 2 PENALTY / qc
        self._by_elem: tuple[np.ndarray, np.ndarray] | None = None  # corners per element

    def element_quality(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(E,) mean ratio of each element (0 where a corner is not positive)."""
        u, bad_corner, _ = self._corner_u(x, y)
        return self._quality_of(self._element_mean(u, np.empty_like(u)), bad_corner)

    def value_and_quality(self, x: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray]:
        """(`value`, `element_quality`) at x, y from one pass over the corners."""
        u, bad_corner, dmin = self._corner_u(x, y)
        tmp = np.empty_like(u)
        q = self._element_mean(u, tmp)
        energy = self._energy_of(u, q, np.empty(self.n_elem), tmp)[0] if dmin > 0.0 else np.inf
        return float(energy), self._quality_of(q, bad_corner)

    def _element_mean(self, u: np.ndarray, tmp: np.ndarray) -> np.ndarray:
        """(E,) mean over each element's corners of q_k = 1 / u_k (u_k = 0: inf)."""
        with np.errstate(divide="ignore"):  # a degenerate corner (u = 0): its element is bad
            return self._positive_mean(u, tmp)

    def _positive_mean(self, u: np.ndarray, tmp: np.ndarray) -> np.ndarray:
        """`_element_mean` where every u_k is positive (no division by zero to silence)."""
        if self._one_each:  # the same bits: 0 + q and q / 1 are q (q >= 0, never -0)
            return np.divide(1.0, u)
        return np.bincount(self.eid, np.divide(1.0, u, tmp), self.n_elem) / self.n_corners

    def _quality_of(self, q: np.ndarray, bad_corner: np.ndarray) -> np.ndarray:
        """The element means q, 0 for an element with a corner whose det is <= 0."""
        bad = np.zeros(self.n_elem, dtype=bool)
        bad[self.eid[bad_corner]] = True
        return np.where(bad, 0.0, q)

    def _energy_of(self, u: np.ndarray, q: np.ndarray, qc: np.ndarray,
                   tmp: np.ndarray) -> tuple[float, np.ndarray]:
        """(F, (qc - q_e)_+ / qc) from the corners' u and the element means q of a point
        whose dets are all positive; qc (E,) and tmp (corners) are scratch."""
        qc.fill(self.qc)
        gap = np.subtract(qc, q)  # (qc - q)_+ / qc
        np.divide(np.maximum(gap, self._zero_e, out=gap), qc, gap)
        w = np.multiply(self._pen_e, gap)  # PENALTY gap gap - q
        energy = fpmath.add_reduce(np.subtract(np.multiply(w, gap, w), q, w))
        energy += LIFT_BARRIER * fpmath.add_reduce(np.multiply(self.weight, u, tmp))
        return energy, gap

    def element_quality_of(self, elems: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """`element_quality(x, y)[elems]` bit for bit (ascending element ids), from those
        elements' corners only: a lift round on a large mesh changes a few of them."""
        if self._by_elem is None:  # corners by element, in corner order
            self._by_elem = bincount_csr(self.eid, self.n_elem)
        ptr, order = self._by_elem
        cnt = ptr[elems + 1] - ptr[elems]
        d, u = self._corner_du(order[ragged_arange(ptr[elems], cnt)], x, y)
        local = np.repeat(np.arange(elems.size), cnt)
        with np.errstate(divide="ignore"):
            q = np.bincount(local, 1.0 / u, minlength=elems.size) / self.n_corners[elems]
        bad = np.bincount(local, d <= 0.0, minlength=elems.size) > 0
        return np.where(bad, 0.0, q)

    def value(self, x: np.ndarray, y: np.ndarray, eps: float) -> float:
        """F (inf where a corner det is not positive), without the gradient: `evaluate`'s
        operations in order (the same bits), without its corner scratch and its state."""
        u, _, dmin = self._corner_u(x, y)
        if not dmin > 0.0:
            return float("inf")
        q = self._element_mean(u, np.empty_like(u))
        return float(self._energy_of(u, q, np.empty(self.n_elem), np.empty_like(u))[0])

    def evaluate(self, z: np.ndarray, layout, eps: float) -> tuple[float, float, bool]:
        bk = self._bk
        self._jac(z, layout[0])
        d, u = bk.d, bk.u
        dmin = float(np.minimum.reduce(d))
        if not dmin > 0.0:  # only reached by rejected trial steps: infinite energy
            return float("inf"), dmin, False
        np.divide(np.multiply(bk.half, bk.t, u), d, u)  # 1 / q_k = 0.5 t / d, > 0 (d > 0)
        q = self._positive_mean(u, bk.tmp)
        energy, self._gap = self._energy_of(u, q, self._qc_e, bk.tmp)
        return energy, dmin, True

    def gradient(self, layout) -> np.ndarray:
        bk = self._bk
        d, u, tmp = bk.d, bk.u, bk.tmp
        k = self._qc_e
        k.fill(2.0 * LIFT_PENALTY / self.qc)
        de_dq = np.subtract(self._m1_e, np.multiply(k, self._gap, k), k)  # -1 - k gap = dF/dq_e
        # dq_e / du_k = -1 / (n_e u_k^2); u_k = t / (2 d): du/dJ = J / d - u cof(J) / d
        per_corner = de_dq if self._one_each else de_dq.take(self.eid, out=bk.a)
        de_du = np.multiply(per_corner, self._neg_inv_nc, bk.a)
        np.divide(de_du, np.multiply(u, u, tmp), de_du)
        np.add(de_du, self._barrier_w, de_du)
        np.divide(np.multiply(np.negative(de_du, bk.b), u, bk.b), d, bk.b)  # b = -de_du u / d
        np.divide(de_du, d, bk.a)  # a = de_du / d
        return self._scatter(layout[1], layout[0])
