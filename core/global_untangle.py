"""Global untangling stage: the foldover-free energy of Garanzha et al. 2021, minimised by L-BFGS.

Used when local EEGT moves stall on a fold (a rotated hole, a large one-step deformation).
Pure NumPy (no SciPy, no bpy), vectorized over corners, deterministic.

Energy (Garanzha, Kaporin, Kudryavtseva, Protais, Ray, Sokolov, "Foldover-free maps in 50 lines
of code", ACM TOG 2021), written here from the paper's equations, for 2D:

    chi(D, eps) = (D + sqrt(eps^2 + D^2)) / 2
    f_eps(J)    = ||J||_F^2 / chi(det J, eps)          (shape, scale invariant)
    g_eps(J)    = (det(J)^2 + 1) / chi(det J, eps)     (area)
    F_eps(x)    = sum_t w_t [ (1 - theta) f_eps(J_t) + theta g_eps(J_t) ]

J_t maps a regular reference corner (size from a smoothed local edge length, normalised so the
reference areas add up to the domain area) onto the current corner; w_t is the reference area.
Each n-gon contributes its n corner triangles (p_{k-1}, p_k, p_{k+1}); a triangle contributes one
(all its corners give the same J up to a rotation). For eps -> 0, f is 2 / (corner mean ratio).
eps follows the paper's continuation: after each inner minimisation,
sigma = max(1 - F_eps(x_new) / F_eps(x_old), 1/10) and eps <- (1 - sigma) chi(D_-, eps) with
D_- = min(min_t det J_t, 0). See docs/global_untangle.md.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

__all__ = ["untangle_global"]

_THETA = 1.0 / 16.0  # weight of the area term g against the shape term f
_LBFGS_M = 8  # L-BFGS memory
_EPS_MIN = 1e-9  # floor of eps (J is dimensionless: dets are ~1 for the reference size)
_DEBUG = bool(os.environ.get("GU_DEBUG"))
_BETA = float(os.environ.get("GU_BETA", "0"))
_INNER = int(os.environ.get("GU_INNER", "100"))
_THETA = float(os.environ.get("GU_THETA", str(_THETA)))


def _corner_tables(
    points: np.ndarray, groups: Mapping[int, np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Corner triangles of all polygons: node indices (k, k+1, k-1), arity, element id, corner id."""
    i0s, i1s, i2s, ns, eids, cids = [], [], [], [], [], []
    base = 0
    for n in sorted(groups):
        f = np.asarray(groups[n], dtype=np.int64).reshape(-1, int(n))
        m = f.shape[0]
        if m == 0:
            continue
        ks = [0] if n == 3 else list(range(n))
        for k in ks:
            i0s.append(f[:, k])
            i1s.append(f[:, (k + 1) % n])
            i2s.append(f[:, (k - 1) % n])
            ns.append(np.full(m, n, dtype=np.int64))
            eids.append(base + np.arange(m, dtype=np.int64))
            cids.append(np.full(m, k, dtype=np.int64))
        base += m
    if not i0s:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty, empty, empty, empty, np.zeros(0)
    del points
    return (
        np.concatenate(i0s),
        np.concatenate(i1s),
        np.concatenate(i2s),
        np.concatenate(ns),
        np.concatenate(eids),
        np.concatenate(cids),
        np.zeros(0),
    )


def _element_tables(groups: Mapping[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """All polygon edges (a, b) with their element id, ordered by arity then element."""
    ea, eb, ee = [], [], []
    base = 0
    for n in sorted(groups):
        f = np.asarray(groups[n], dtype=np.int64).reshape(-1, int(n))
        m = f.shape[0]
        if m == 0:
            continue
        ea.append(f.ravel())
        eb.append(np.roll(f, -1, axis=1).ravel())
        ee.append(np.repeat(base + np.arange(m, dtype=np.int64), n))
        base += m
    if not ea:
        z = np.zeros(0, dtype=np.int64)
        return np.stack([z, z]), z
    return np.stack([np.concatenate(ea), np.concatenate(eb)]), np.concatenate(ee)


class _Energy:
    """Regularised foldover-free energy over corner triangles, with its gradient."""

    def __init__(self, points: np.ndarray, groups: Mapping[int, np.ndarray], free: np.ndarray):
        n_nodes = points.shape[0]
        i0, i1, i2, ns, eids, _, _ = _corner_tables(points, groups)
        edges, edge_elem = _element_tables(groups)
        n_elem = int(eids.max()) + 1 if eids.size else 0
        self.n_nodes = n_nodes
        self.n_elem = n_elem
        self.all_i0, self.all_i1, self.all_i2, self.all_eid = i0, i1, i2, eids

        # Per-element target edge length. Folds stretch edges (a sheared layer keeps its short
        # edges, its long ones grow), so a node's size is its shortest incident edge; elements
        # take the geometric mean of their nodes, smoothed twice in log space through the nodes.
        # The global scale is fixed below by the domain area, so only relative sizes matter here.
        elen = np.hypot(*(points[edges[1]] - points[edges[0]]).T)
        pos_len = elen[elen > 0]
        floor = 1e-3 * (float(np.mean(pos_len)) if pos_len.size else 1.0)
        elen = np.maximum(elen, floor)
        hn = np.full(n_nodes, np.inf)
        np.minimum.at(hn, edges[0], elen)
        np.minimum.at(hn, edges[1], elen)
        hn = np.where(np.isfinite(hn), hn, floor)
        deg_e = np.bincount(edge_elem, minlength=n_elem).astype(np.float64)
        node_cnt = np.bincount(edges[0], minlength=n_nodes).astype(np.float64)
        lh = np.log(hn)
        for it in range(3):
            le = np.bincount(edge_elem, weights=lh[edges[0]], minlength=n_elem)
            le = le / np.maximum(deg_e, 1.0)
            if it == 2:
                break
            lh = np.bincount(edges[0], weights=le[edge_elem], minlength=n_nodes)
            lh = lh / np.maximum(node_cnt, 1.0)
        size = np.exp(le)

        # Regular n-gon with edge s: area n s^2 / (4 tan(pi/n)); normalise to the domain area.
        n_of_elem = np.zeros(n_elem, dtype=np.int64)
        n_of_elem[eids] = ns
        ref_area = n_of_elem * size**2 / (4.0 * np.tan(np.pi / np.maximum(n_of_elem, 3)))
        x, y = points[edges[0]].T
        xb, yb = points[edges[1]].T
        dom_area = 0.5 * float(np.sum(x * yb - xb * y))
        tot = float(np.sum(ref_area))
        if dom_area > 0.0 and tot > 0.0:
            scale = dom_area / tot
            ref_area = ref_area * scale
            size = size * np.sqrt(scale)

        # Keep only corners that touch a free node (others have a constant energy).
        keep = free[i0] | free[i1] | free[i2]
        self.i0, self.i1, self.i2 = i0[keep], i1[keep], i2[keep]
        nk = ns[keep].astype(np.float64)
        s = size[eids[keep]]
        a = (nk - 2.0) * np.pi / nk
        # W = s [[1, cos a], [0, sin a]]; Winv = [[1, -cot a], [0, 1/sin a]] / s
        self.w00 = 1.0 / s
        self.w01 = -np.cos(a) / (np.sin(a) * s)
        self.w10 = np.zeros_like(s)
        self.w11 = 1.0 / (np.sin(a) * s)
        self.weight = ref_area[eids[keep]] ** _BETA / np.where(nk == 3, 1.0, nk)
        self.weight = self.weight / float(np.mean(self.weight)) if self.weight.size else self.weight
        self.idx = np.concatenate([self.i1, self.i2, self.i0])
        self.free = free
        self.theta = _THETA
        # Diagonal preconditioner for L-BFGS: the energy Hessian at a node scales like
        # weight / size^2 = size^(2 beta - 2), so scale moves by size^(2 - 2 beta).
        hnode = np.exp(lh)
        self.precond = (hnode / float(np.mean(hnode))) ** (2.0 - 2.0 * _BETA)

    def jac(self, X: np.ndarray) -> tuple[np.ndarray, ...]:
        """Corner Jacobians J = [p1 - p0, p2 - p0] W^-1 as four component arrays."""
        p0 = X[self.i0]
        e1 = X[self.i1] - p0
        e2 = X[self.i2] - p0
        j00 = e1[:, 0] * self.w00 + e2[:, 0] * self.w10
        j01 = e1[:, 0] * self.w01 + e2[:, 0] * self.w11
        j10 = e1[:, 1] * self.w00 + e2[:, 1] * self.w10
        j11 = e1[:, 1] * self.w01 + e2[:, 1] * self.w11
        return j00, j01, j10, j11

    def dets(self, X: np.ndarray) -> np.ndarray:
        """det J of every kept corner."""
        j00, j01, j10, j11 = self.jac(X)
        return j00 * j11 - j01 * j10

    def value(self, X: np.ndarray, eps: float) -> float:
        """F_eps(X)."""
        j00, j01, j10, j11 = self.jac(X)
        d = j00 * j11 - j01 * j10
        t = j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11
        chi = _chi(d, eps)
        th = self.theta
        return float(np.sum(self.weight * ((1.0 - th) * t + th * (d * d + 1.0)) / chi))

    def value_grad(self, X: np.ndarray, eps: float) -> tuple[float, np.ndarray, np.ndarray]:
        """F_eps(X), its gradient (N, 2) (zero on non-free rows), and the corner dets."""
        j00, j01, j10, j11 = self.jac(X)
        d = j00 * j11 - j01 * j10
        t = j00 * j00 + j01 * j01 + j10 * j10 + j11 * j11
        root = np.sqrt(eps * eps + d * d)
        chi = _chi(d, eps, root)
        dchi = chi / root  # = (1 + d / root) / 2
        th = self.theta
        num = (1.0 - th) * t + th * (d * d + 1.0)
        w = self.weight
        energy = float(np.sum(w * num / chi))
        a = w * (2.0 * (1.0 - th)) / chi
        b = w * (2.0 * th * d / chi - num * dchi / (chi * chi))
        # dF/dJ = a J + b cof(J), cof(J) = [[j11, -j10], [-j01, j00]]
        g00 = a * j00 + b * j11
        g01 = a * j01 - b * j10
        g10 = a * j10 - b * j01
        g11 = a * j11 + b * j00
        # dF/dE = dF/dJ W^-T, E = [e1, e2]
        ge1x = g00 * self.w00 + g01 * self.w01
        ge1y = g10 * self.w00 + g11 * self.w01
        ge2x = g00 * self.w10 + g01 * self.w11
        ge2y = g10 * self.w10 + g11 * self.w11
        n = self.n_nodes
        gx = np.bincount(
            self.idx, weights=np.concatenate([ge1x, ge2x, -(ge1x + ge2x)]), minlength=n
        )
        gy = np.bincount(
            self.idx, weights=np.concatenate([ge1y, ge2y, -(ge1y + ge2y)]), minlength=n
        )
        grad = np.stack([gx, gy], axis=1)
        grad[~self.free] = 0.0
        return energy, grad, d


def _chi(d: np.ndarray, eps: float, root: np.ndarray | None = None) -> np.ndarray:
    """chi(D, eps) = (D + sqrt(eps^2 + D^2)) / 2, evaluated without cancellation for D < 0."""
    if root is None:
        root = np.sqrt(eps * eps + d * d)
    pos = 0.5 * (d + root)
    neg = (0.5 * eps * eps) / (root + np.abs(d))  # = chi for d < 0; unused for d >= 0
    return np.where(d >= 0.0, pos, neg)


def _chi_scalar(d: float, eps: float) -> float:
    root = float(np.sqrt(eps * eps + d * d))
    return 0.5 * (d + root) if d >= 0.0 else 0.5 * eps * eps / (root - d)


def _all_corner_dets(X: np.ndarray, i0: np.ndarray, i1: np.ndarray, i2: np.ndarray) -> np.ndarray:
    """Raw corner determinants det[p_{k+1} - p_k, p_{k-1} - p_k] (SPEC section 3 sign)."""
    e1 = X[i1] - X[i0]
    e2 = X[i2] - X[i0]
    return e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]


def _inverted_count(
    X: np.ndarray, i0: np.ndarray, i1: np.ndarray, i2: np.ndarray, eid: np.ndarray, n_elem: int
) -> int:
    """Number of elements with a corner det <= 0 (triangles: the signed area)."""
    bad = _all_corner_dets(X, i0, i1, i2) <= 0.0
    if not bad.any():
        return 0
    return int(np.count_nonzero(np.bincount(eid[bad], minlength=n_elem)))


def untangle_global(
    points: np.ndarray,
    groups: Mapping[int, np.ndarray],
    free: np.ndarray,
    *,
    max_iter: int = 3000,
    max_outer: int = 500,
    time_limit: float | None = None,
    progress: Callable[[int, int, int], Any] | None = None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Untangle a planar polygon mesh by minimising the foldover-free energy with eps continuation.

    points: (N, 2) float64; groups: arity -> (F_n, n) int node arrays, counterclockwise = valid;
    free: (N,) bool mask of movable nodes. max_iter bounds the total L-BFGS iterations,
    max_outer the eps updates; time_limit (s) stops early. progress(it, max_iter, n_inverted)
    is called once per outer step; returning False cancels (the best iterate is returned).

    Returns (new points, info). Non-free rows are bit-identical to the input. The returned
    iterate is the best seen (fewest inverted elements, then lowest energy at the final eps).
    info: iterations, outer, n_inverted_in/out, min_det (min corner det of J), eps_history,
    seconds, seconds_per_iter, status ("untangled" / "failed" / "cancelled" / "nothing to do").
    """
    t_start = time.perf_counter()
    P = np.array(points, dtype=np.float64, copy=True)
    free = np.asarray(free, dtype=bool).reshape(-1)
    if P.ndim != 2 or P.shape[1] != 2 or free.shape[0] != P.shape[0]:
        raise ValueError("points must be (N, 2) and free (N,)")
    if not np.all(np.isfinite(P)):
        raise ValueError("points contain NaN or inf")
    en = _Energy(P, groups, free)
    n_inv0 = _inverted_count(P, en.all_i0, en.all_i1, en.all_i2, en.all_eid, en.n_elem)
    info: dict[str, Any] = {
        "iterations": 0,
        "outer": 0,
        "n_inverted_in": n_inv0,
        "n_inverted_out": n_inv0,
        "eps_history": [],
        "seconds": 0.0,
        "seconds_per_iter": 0.0,
        "status": "nothing to do",
    }
    if en.i0.size == 0 or not free.any():
        info["min_det"] = float(np.min(en.dets(P))) if en.i0.size else 0.0
        info["seconds"] = time.perf_counter() - t_start
        return P, info

    fmask = free
    X = P.copy()

    def count_inv(Y: np.ndarray) -> int:
        return _inverted_count(Y, en.all_i0, en.all_i1, en.all_i2, en.all_eid, en.n_elem)

    d = en.dets(X)
    dmin = float(np.min(d))
    # Initial eps: a fraction of the worst inversion, never below the floor.
    eps = max(0.1 * abs(min(dmin, 0.0)), 1e-3 if dmin <= 0.0 else _EPS_MIN)
    best_X, best_key = X.copy(), (count_inv(X), np.inf)
    total_it = 0
    status = "failed"
    eps_hist: list[float] = []
    for outer in range(max_outer):
        eps_hist.append(eps)
        n_inv_now = count_inv(X)
        guard = n_inv_now == 0  # once valid, never accept a step that inverts a corner
        e_start = en.value(X, eps)
        budget = max_iter - total_it
        if budget <= 0:
            break
        X, its = _lbfgs(en, X, eps, fmask, max_it=min(budget, _INNER), guard=guard)
        total_it += its
        e_end = en.value(X, eps)
        d = en.dets(X)
        dmin = float(np.min(d))
        n_inv = count_inv(X)
        key = (n_inv, e_end if n_inv == 0 else np.inf)
        if key[0] < best_key[0] or (key[0] == best_key[0] and key[1] <= best_key[1]):
            best_X, best_key = X.copy(), key
        info["outer"] = outer + 1
        if _DEBUG:
            print(
                f"outer {outer} eps {eps:.2e} its {its} tot {total_it} inv {n_inv} "
                f"dmin {dmin:.3e} E {e_start:.6e}->{e_end:.6e} t {time.perf_counter() - t_start:.2f}"
            )
        if progress is not None and progress(total_it, max_iter, n_inv) is False:
            status = "cancelled"
            break
        sigma = max(1.0 - e_end / e_start, 0.1) if e_start > 0 else 0.1
        if n_inv == 0 and (1.0 - e_end / e_start) < 1e-3 and guard:
            status = "untangled"
            break
        if time_limit is not None and time.perf_counter() - t_start > time_limit:
            break
        # Paper's rule: the new eps makes chi(D_-, eps) shrink by the factor (1 - sigma).
        mu = (1.0 - sigma) * _chi_scalar(dmin, eps)
        eps = 2.0 * float(np.sqrt(mu * (mu - dmin))) if dmin < mu else _EPS_MIN
        eps = max(eps, _EPS_MIN)
    X = best_X
    X[~fmask] = P[~fmask]
    n_out = count_inv(X)
    if status != "cancelled":
        status = "untangled" if n_out == 0 else "failed"
    secs = time.perf_counter() - t_start
    info.update(
        iterations=total_it,
        n_inverted_out=n_out,
        min_det=float(np.min(en.dets(X))),
        eps_history=eps_hist,
        seconds=secs,
        seconds_per_iter=secs / max(total_it, 1),
        status=status,
    )
    return X, info


def _lbfgs(
    en: _Energy, X0: np.ndarray, eps: float, fmask: np.ndarray, *, max_it: int, guard: bool
) -> tuple[np.ndarray, int]:
    """L-BFGS (two-loop recursion, Armijo backtracking) on the free coordinates of X0.

    guard: reject trial points with any corner det <= 0 (used once the mesh is valid).
    Stops on a relative energy decrease below 1e-6 over 5 iterations, or max_it.
    """
    X = X0.copy()
    fidx = np.flatnonzero(fmask)
    e, G, _ = en.value_grad(X, eps)
    g = G[fidx].ravel()
    dpre = np.repeat(en.precond[fidx], 2)
    s_list: list[np.ndarray] = []
    y_list: list[np.ndarray] = []
    rho_list: list[float] = []
    hist: list[float] = [e]
    # First step length: move the fastest node by ~ 1/10 of a typical reference edge.
    h0 = 0.1 / float(np.mean(en.w00))
    it = 0
    for it in range(1, max_it + 1):  # noqa: B007
        # two-loop recursion
        q = -g
        alphas = []
        for s, y, rho in zip(reversed(s_list), reversed(y_list), reversed(rho_list), strict=True):
            al = rho * float(s @ q)
            alphas.append(al)
            q = q - al * y
        if s_list:
            sy = float(s_list[-1] @ y_list[-1])
            ydy = float(y_list[-1] @ (dpre * y_list[-1]))
            q = q * dpre * (sy / ydy)
            step0 = 1.0
        else:
            q = q * dpre
            gmax = float(np.max(np.abs(q))) if q.size else 0.0
            step0 = h0 / gmax if gmax > 0 else 0.0
        for s, y, rho, al in zip(s_list, y_list, rho_list, reversed(alphas), strict=True):
            be = rho * float(y @ q)
            q = q + (al - be) * s
        p = q
        slope = float(g @ p)
        if not slope < 0.0:
            s_list, y_list, rho_list = [], [], []
            p = -g * dpre
            slope = float(g @ p)
            gmax = float(np.max(np.abs(p))) if p.size else 0.0
            step0 = h0 / gmax if gmax > 0 else 0.0
            if slope == 0.0:
                break
        t = step0
        accepted = False
        xf = X[fidx].ravel()
        for _ in range(40):
            Xt = X.copy()
            Xt[fidx] = (xf + t * p).reshape(-1, 2)
            et, Gt, dt = en.value_grad(Xt, eps)
            ok = np.isfinite(et) and et <= e + 1e-4 * t * slope
            if ok and guard and float(np.min(dt)) <= 0.0:
                ok = False
            if ok:
                accepted = True
                break
            t *= 0.5
        if not accepted:
            if s_list:  # retry from steepest descent with a fresh memory
                s_list, y_list, rho_list = [], [], []
                continue
            break
        gt = Gt[fidx].ravel()
        s = t * p
        y = gt - g
        sy = float(s @ y)
        if sy > 1e-12 * float(np.sqrt(float(s @ s) * float(y @ y))):
            s_list.append(s)
            y_list.append(y)
            rho_list.append(1.0 / sy)
            if len(s_list) > _LBFGS_M:
                s_list.pop(0)
                y_list.pop(0)
                rho_list.pop(0)
        X, e, g = Xt, et, gt
        hist.append(e)
        if len(hist) > 5 and hist[-6] - e <= 1e-6 * abs(hist[-6]):
            break
    return X, it
