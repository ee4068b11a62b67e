"""The acceptance rule: whether a run's result is kept over its input ("no worse than the
input"), judged on the values as they are stored.

Every path that returns or writes a result asks `accept`: the 2D and 3D runs, the UV run
per island, live frames and the Blender operators. Results are compared as
``Stats.better_than`` orders them (docs/method.md 2): fewer inverted faces first, then a
higher q_min, then a higher q_avg. How close two qualities may be and still tie depends on
the type the positions are stored in (`tie_tolerance`):

- float64 (the core's own arrays): exact comparison, and a tie keeps the result (it is no
  worse than the input);
- float32 (Blender's vertex positions and UV values): qualities at most ``1e-6`` apart tie,
  and a tie keeps the input (a rewrite would only move vertices by float32 round-off for a
  gain of ~1e-13).
"""

from __future__ import annotations

import numpy as np

from ..metrics.face_quality import Stats

__all__ = ["FLOAT32_TIE", "accept", "tie_tolerance"]

FLOAT32_TIE = 1e-6  # quality changes up to this are float32 round-off, not a gain


def tie_tolerance(stored: np.dtype | type = np.float64) -> float:
    """How far apart two qualities may be and still tie, for positions stored as ``stored``:
    0 for float64 (exact), ``FLOAT32_TIE`` for float32. ValueError for other types."""
    kind = np.dtype(stored)
    if kind == np.float64:
        return 0.0
    if kind == np.float32:
        return FLOAT32_TIE
    raise ValueError(f"stored positions must be float64 or float32, got {kind}")


def accept(before: Stats, after: Stats, stored: np.dtype | type = np.float64) -> bool:
    """Whether ``after`` (the result's stats, measured on its stored values) is kept over
    ``before`` (the input's): fewer inverted faces wins; with as many, a q_min higher by
    more than the tie tolerance of ``stored`` (`tie_tolerance`) wins and a lower one loses;
    then likewise q_avg. A full tie keeps the result in float64 (no worse than the input)
    and the input in float32 (nothing worth a rewrite)."""
    eps = tie_tolerance(stored)
    if after.n_inverted != before.n_inverted:
        return after.n_inverted < before.n_inverted
    if abs(after.q_min - before.q_min) > eps:
        return after.q_min > before.q_min
    if abs(after.q_avg - before.q_avg) > eps:
        return after.q_avg > before.q_avg
    return eps == 0.0
