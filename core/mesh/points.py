"""The points a caller hands to core: checked and copied once, with a one-line error."""

from __future__ import annotations

import numpy as np

from ..fpmath import float64_copy

__all__ = ["check_points"]


def check_points(points, dim: int = 2) -> np.ndarray:
    """A float64 (N, dim) copy of the points; ValueError naming the problem (non-numbers,
    complex numbers, wrong shape, the first non-finite node)."""
    try:  # always a copy: callers' arrays stay untouched
        p = float64_copy(points)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"points must be an (N, {dim}) array of numbers ({exc})") from None
    if p.ndim != 2 or p.shape[1] != dim:
        raise ValueError(f"points must be an (N, {dim}) array, got shape {p.shape}")
    bad = ~np.isfinite(p).all(axis=1)
    if bad.any():
        raise ValueError(f"node {int(np.flatnonzero(bad)[0])} has a NaN or infinite coordinate")
    return p
