"""The explicit element geometric transformation (paper eq. 1-4) on whole arity groups.

Stretch: p'_k = p_k + lambda n_k with n_k = sum_{r=1..R} rot(p_{k+r} - p_{k-r}),
R = ceil((n - 1) / 4), rot(x, y) = (y, -x). Shrink: scale p' about the (preserved) vertex
centroid so the mean edge length (default) or the absolute area is that of the input.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["group_transform_delta", "stretch_radius", "transform_polygon"]


def stretch_radius(n: int) -> int:
    """R = ceil((n - 1) / 4): how many opposite node pairs build each stretch vector."""
    return math.ceil((n - 1) / 4.0)


def _stretch(X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stretch vectors n_k of every corner, as (n, F) arrays."""
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


def _edge_sum(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
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
    X: np.ndarray, Y: np.ndarray, lam: np.ndarray, scaling: str = "edge"
) -> tuple[np.ndarray, np.ndarray]:
    """(DX, DY) = p^s - p for every corner of an (n, F) group, lam an (F,) array."""
    NX, NY = _stretch(X, Y)
    NX *= lam
    NY *= lam  # now lambda n_k
    SX = X + NX
    SY = Y + NY
    if scaling == "edge":
        before, after = _edge_sum(X, Y), _edge_sum(SX, SY)
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


def transform_polygon(points, lam: float, scaling: str = "edge") -> np.ndarray:
    """One transform of a single polygon given as (n, 2) points; returns the new (n, 2)."""
    p = np.asarray(points, dtype=np.float64)
    X, Y = p[:, 0:1].copy(), p[:, 1:2].copy()
    DX, DY = group_transform_delta(X, Y, np.array([lam], dtype=np.float64), scaling)
    return np.column_stack([X[:, 0] + DX[:, 0], Y[:, 0] + DY[:, 0]])
