"""A harmonic start for the global stage: every interior free node at the mean of its edge
neighbours, the boundary and held nodes where they are.

A fold made by moving an inner boundary far (a ring turned half a turn) sends the
optimization from the tangled input through a long, nearly symmetric detour; the harmonic
map of the same boundary spreads the turn over the whole interior and leaves the optimizer
a short way (docs/global_untangle.md, "Harmonic start"). It is the uniform-weight
convex-combination map (Tutte's embedding when the held nodes are one convex boundary),
solved by Jacobi-preconditioned conjugate gradients. NumPy only; its sums are
`fpmath.add_reduce` and `np.bincount`, so the result has the same bits on every CPU.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..fpmath import add_reduce
from ..mesh.faces import FaceSet
from ..mesh.topology import boundary_nodes

__all__ = ["HARMONIC_MAX_ITER", "HARMONIC_TICK", "HARMONIC_TOL", "harmonic_positions"]

HARMONIC_TOL = 1e-9  # conjugate gradients stop at this residual, relative to the first one
HARMONIC_MAX_ITER = 5000  # ... or after this many iterations per coordinate
HARMONIC_TICK = 50  # `tick` is called every this many iterations


def harmonic_positions(points: np.ndarray, faces: FaceSet, movable: np.ndarray,
                       tick: Callable[[], object] | None = None) -> np.ndarray:
    """`points` (N, 2) with the movable interior nodes moved to the harmonic map of the rest.

    Interior: every edge at the node is shared by exactly two faces (boundary and
    non-manifold nodes stay), so every movable node of a planar mesh is tied to held ones.
    Returns a new array; the held rows are bit-identical (all rows are when the solve does
    not end finite). `tick()` is called every HARMONIC_TICK iterations (a progress report
    that may raise to cancel: a million nodes take thousands of iterations)."""
    n = points.shape[0]
    a, b = _edges(faces, n)
    deg = np.bincount(a, minlength=n) + np.bincount(b, minlength=n)
    held = ~movable | boundary_nodes(n, faces) | (deg == 0)
    out = np.array(points, dtype=np.float64, copy=True)
    if held.all():
        return out
    free = ~held
    degf = deg.astype(np.float64)
    moved = [_solve(out[:, c], a, b, degf, free, tick)[free] for c in range(2)]
    if all(np.isfinite(m).all() for m in moved):
        out[free, 0], out[free, 1] = moved
    return out


def _edges(faces: FaceSet, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The faces' distinct undirected edges (a < b)."""
    keys = []
    for g in faces.groups:
        nodes = g.nodes  # (arity, F)
        nxt = np.roll(nodes, -1, axis=0)
        lo, hi = np.minimum(nodes, nxt).ravel(), np.maximum(nodes, nxt).ravel()
        keys.append(lo * n + hi)
    key = np.unique(np.concatenate(keys))
    return key // n, key % n


def _laplace(v: np.ndarray, a: np.ndarray, b: np.ndarray, deg: np.ndarray) -> np.ndarray:
    """(D - W) v for the uniform weights: deg v minus the sum over neighbours."""
    n = v.shape[0]
    return deg * v - (np.bincount(a, v[b], n) + np.bincount(b, v[a], n))


def _solve(v: np.ndarray, a: np.ndarray, b: np.ndarray, deg: np.ndarray,
           free: np.ndarray, tick: Callable[[], object] | None) -> np.ndarray:
    """v with its free entries solving (D - W) v = 0 there (the held ones fixed)."""
    v = v.copy()
    r = -_laplace(v, a, b, deg)
    r[~free] = 0.0
    inv_d = np.where(free, 1.0 / np.maximum(deg, 1.0), 0.0)
    z = r * inv_d
    p = z.copy()
    rz = add_reduce(r * z)
    stop = HARMONIC_TOL * HARMONIC_TOL * rz
    for it in range(HARMONIC_MAX_ITER):
        if not rz > stop:  # converged (or nothing to do)
            break
        if tick is not None and it % HARMONIC_TICK == HARMONIC_TICK - 1:
            tick()
        ap = _laplace(p, a, b, deg)
        ap[~free] = 0.0
        pap = add_reduce(p * ap)
        if not pap > 0.0:
            break
        alpha = rz / pap
        v += alpha * p
        r -= alpha * ap
        z = r * inv_d
        rz_new = add_reduce(r * z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return v
