"""The explicit element geometric transformation (paper eq. 1-4) on whole arity groups.

Stretch: p'_k = p_k + lambda n_k with n_k = sum_{r=1..R} rot(p_{k+r} - p_{k-r}),
R = ceil((n - 1) / 4), rot(x, y) = (y, -x). Shrink: scale p' about the (preserved) vertex
centroid so the mean edge length (default) or the absolute area is that of the input.

Towards a target shape (core.metrics.targets): with T the face's centred target nodes (2 x n), P its
centred nodes and M = P T^T (T T^T)^-1 the least-squares affine map target -> face, split M
into its conformal part S and anti-conformal part A = M - S; the stretch is
n_k = c_n (S - A) t_k = c_n cof(M) t_k, c_n = sum_{r=1..R} 2 sin(2 pi r / n). For the regular
target it is the paper's stretch of triangles and quads exactly; for n >= 5 it keeps the
paper's action on the affine modes only (the others are not stretched: the shrink damps
them). docs/targets.md derives it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["edge_sum", "group_transform_delta", "stretch_radius", "transform_polygon"]


def stretch_radius(n: int) -> int:
    """R = ceil((n - 1) / 4): how many opposite node pairs build each stretch vector."""
    return math.ceil((n - 1) / 4.0)


def _stretch(X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The paper's stretch vectors n_k of every corner, as (n, F) arrays (OpenCL:
    stretch_vector, TRI_PAPER_STRETCH)."""
    n = X.shape[0]
    NX = np.empty_like(X)
    NY = np.empty_like(Y)
    R = stretch_radius(n)
    for k in range(n):
        nx = Y[(k + 1) % n] - Y[(k - 1) % n]
        ny = X[(k - 1) % n] - X[(k + 1) % n]
        for r in range(2, R + 1):
            nx += Y[(k + r) % n] - Y[(k - r) % n]
            ny += X[(k - r) % n] - X[(k + r) % n]
        NX[k] = nx
        NY[k] = ny
    return NX, NY


def _target_stretch(X: np.ndarray, Y: np.ndarray, target) -> tuple[np.ndarray, np.ndarray]:
    """Generalised stretch vectors c_n cof(M) t_k of every corner towards the group's targets
    (`target`: a core.metrics.targets.GroupTargets), as (n, F) arrays."""
    n = X.shape[0]
    CX = X.sum(axis=0)
    CX /= n
    CY = Y.sum(axis=0)
    CY /= n
    m00, m01 = np.zeros_like(CX), np.zeros_like(CX)
    m10, m11 = np.zeros_like(CX), np.zeros_like(CX)
    for k in range(n):  # c_n M = P_centred (c_n K), corner by corner
        xh = X[k] - CX
        yh = Y[k] - CY
        m00 += xh * target.kx[k]
        m01 += xh * target.ky[k]
        m10 += yh * target.kx[k]
        m11 += yh * target.ky[k]
    # cof(M) = 2 S - M = [[m11, -m10], [-m01, m00]]
    NX = m11 * target.x - m10 * target.y
    NY = m00 * target.y - m01 * target.x
    return NX, NY


def edge_sum(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Sum of the edge lengths of every face (n times the mean edge length)."""
    n = X.shape[0]
    total = np.zeros(X.shape[1])
    for k in range(n):
        ex = X[(k + 1) % n] - X[k]
        ey = Y[(k + 1) % n] - Y[k]
        ex *= ex
        ey *= ey
        ex += ey
        total += np.sqrt(ex, out=ex)
    return total


def _abs_area(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    return 0.5 * np.abs((X * np.roll(Y, -1, axis=0) - np.roll(X, -1, axis=0) * Y).sum(axis=0))


def group_transform_delta(
    X: np.ndarray, Y: np.ndarray, lam: np.ndarray, scaling: str = "edge", target=None
) -> tuple[np.ndarray, np.ndarray]:
    """(DX, DY) = p^s - p for every corner of an (n, F) group, lam an (F,) array: the stretch
    p' = p + lambda n_k, then the shrink about the centroid (OpenCL: transform_moves). `target`
    (a core.metrics.targets.GroupTargets) stretches towards per-face targets, None as the paper."""
    NX, NY = _stretch(X, Y) if target is None else _target_stretch(X, Y, target)
    NX *= lam
    NY *= lam  # now lambda n_k
    SX = X + NX
    SY = Y + NY
    # the shrink: s = size before / size after
    if scaling == "edge":
        before, after = edge_sum(X, Y), edge_sum(SX, SY)
    elif scaling == "area":
        before, after = np.sqrt(_abs_area(X, Y)), np.sqrt(_abs_area(SX, SY))
    else:
        raise ValueError(f"unknown scaling {scaling!r} (use 'edge' or 'area')")
    s = np.ones_like(before)
    np.divide(before, after, out=s, where=after > 0)
    n = X.shape[0]
    one_minus_s = 1.0 - s
    CX = X.sum(axis=0)
    CX /= n
    CY = Y.sum(axis=0)
    CY /= n
    # p^s - p = (1 - s)(c - p) + s lambda n
    DX, DY = SX, SY  # reuse the buffers
    for k in range(n):
        np.subtract(CX, X[k], out=DX[k])
        DX[k] *= one_minus_s
        NX[k] *= s
        DX[k] += NX[k]
        np.subtract(CY, Y[k], out=DY[k])
        DY[k] *= one_minus_s
        NY[k] *= s
        DY[k] += NY[k]
    return DX, DY


def transform_polygon(points, lam: float, scaling: str = "edge", target=None) -> np.ndarray:
    """One transform of a single polygon given as (n, 2) points; returns the new (n, 2).
    `target`: None (the paper's transform) or the polygon's (n, 2) target shape."""
    p = np.asarray(points, dtype=np.float64)
    X, Y = p[:, 0:1].copy(), p[:, 1:2].copy()
    gt = None
    if target is not None:
        from ..mesh.faces import as_faceset
        from ..metrics.targets import prepare_targets

        gt = prepare_targets(target, as_faceset([list(range(len(p)))], len(p))).groups[0]
    DX, DY = group_transform_delta(X, Y, np.array([lam], dtype=np.float64), scaling, gt)
    return np.column_stack([X[:, 0] + DX[:, 0], Y[:, 0] + DY[:, 0]])
