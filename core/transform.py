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
    n = X.shape[0]
    NX = np.zeros_like(X)
    NY = np.zeros_like(Y)
    for r in range(1, stretch_radius(n) + 1):
        NX += np.roll(Y, -r, axis=0) - np.roll(Y, r, axis=0)
        NY += np.roll(X, r, axis=0) - np.roll(X, -r, axis=0)
    return NX, NY


def _mean_edge(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    return np.hypot(np.roll(X, -1, axis=0) - X, np.roll(Y, -1, axis=0) - Y).mean(axis=0)


def _abs_area(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    return 0.5 * np.abs((X * np.roll(Y, -1, axis=0) - np.roll(X, -1, axis=0) * Y).sum(axis=0))


def group_transform_delta(
    X: np.ndarray, Y: np.ndarray, lam: np.ndarray, scaling: str = "edge"
) -> tuple[np.ndarray, np.ndarray]:
    """(DX, DY) = p^s - p for every corner of an (n, F) group, lam an (F,) array."""
    NX, NY = _stretch(X, Y)
    SX = X + lam * NX
    SY = Y + lam * NY
    if scaling == "edge":
        before, after = _mean_edge(X, Y), _mean_edge(SX, SY)
    elif scaling == "area":
        before, after = np.sqrt(_abs_area(X, Y)), np.sqrt(_abs_area(SX, SY))
    else:
        raise ValueError(f"unknown scaling {scaling!r} (use 'edge' or 'area')")
    s = np.ones_like(before)
    np.divide(before, after, out=s, where=after > 0)
    CX = X.mean(axis=0)
    CY = Y.mean(axis=0)
    # p^s - p = (1 - s)(c - p) + s lambda n
    DX = (1.0 - s) * (CX - X) + (s * lam) * NX
    DY = (1.0 - s) * (CY - Y) + (s * lam) * NY
    return DX, DY


def transform_polygon(points, lam: float, scaling: str = "edge") -> np.ndarray:
    """One transform of a single polygon given as (n, 2) points; returns the new (n, 2)."""
    p = np.asarray(points, dtype=np.float64)
    X, Y = p[:, 0:1].copy(), p[:, 1:2].copy()
    DX, DY = group_transform_delta(X, Y, np.array([lam], dtype=np.float64), scaling)
    return np.column_stack([X[:, 0] + DX[:, 0], Y[:, 0] + DY[:, 0]])
