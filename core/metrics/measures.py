"""Element quality measures engineers check, for polygons of any arity (docs/measures.md).

Every measure is computed per arity group on (n, F) corner coordinates, like the mean ratio
of `core.metrics.face_quality` (reused here, docs/method.md 3). Notation for corner k of an
n-gon with nodes p_0..p_{n-1} counterclockwise: e1 = p_{k+1} - p_k, e2 = p_{k-1} - p_k; its interior
angle is the counterclockwise turn from e1 to e2, so a corner of a valid convex polygon has
0 < angle < 180 deg, a reflex corner more than 180 and a corner of an inverted element too.
theta_e = 180 (n - 2) / n is the regular polygon's interior angle.

- ``min_angle`` (deg, higher is better): the smallest corner angle, taken in (-180, 180]:
  a reflex or inverted corner reads as a negative angle.
- ``max_angle`` (deg, lower is better): the largest corner angle, taken in [0, 360): a
  reflex or inverted corner reads above 180.
- ``aspect_ratio`` (>= 1, lower is better): the longest edge over the polygon's smallest
  width perpendicular to one of its edges (for a triangle: the shortest altitude), divided
  by the same ratio of the regular polygon. Orientation-blind: it measures elongation only.
- ``scaled_jacobian`` (<= 1, higher is better): min over corners of det[e1, e2] / (|e1| |e2|)
  (the corner's sine), divided by sin(theta_e); negative at a reflex or inverted corner.
- ``skewness`` (>= 0, lower is better): equiangle skewness
  max((max_angle - theta_e) / (180 - theta_e), (theta_e - min_angle) / theta_e); 1 for a
  degenerate element, above 1 only with a reflex or inverted corner.

Degenerate input never gives NaN: a corner next to a zero-length edge has no angle and
counts as collapsed (0 deg for the minimum, 180 deg for the maximum, sine 0); an element of
zero width has the aspect ratio ``ASPECT_MAX`` (1 / machine epsilon). Every measure reads
the same at any finite scale: faces are brought to unit size by a power of two (exact).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from ..fpmath import add_reduce, atan2, regular_corner, tan_pi_over
from ..mesh.faces import FaceSet, as_faceset
from ..mesh.points import check_points
from .mean_ratio import scaled_group_quality, unit_scaled

__all__ = [
    "ASPECT_MAX",
    "MEASURES",
    "MEASURE_NAMES",
    "Measure",
    "MeasureSummary",
    "face_values",
    "get_measure",
    "goodness",
    "summaries",
    "summarize",
]

ASPECT_MAX = 1.0 / np.finfo(np.float64).eps  # a zero-width element: 2^52, finite


def regular_angle(n: int) -> float:
    """Interior angle of the regular n-gon in degrees."""
    return 180.0 * (n - 2) / n


def regular_width(n: int) -> float:
    """Width of the regular n-gon with unit edges perpendicular to an edge: twice the
    apothem for even n, apothem + circumradius for odd n."""
    t = tan_pi_over(n)
    apothem = 0.5 / t
    if n % 2 == 0:
        return 2.0 * apothem
    return apothem + 0.5 * float(np.sqrt(1.0 + t * t)) / t  # R = 1 / (2 sin(pi / n))


# -- per-group geometry ------------------------------------------------------------------


def _edges(X: np.ndarray, Y: np.ndarray):
    """Edge k = p_{k+1} - p_k of each face (coordinates from ``unit_scaled``): unit vectors
    (0 for a zero-length edge) and lengths, all (n, F)."""
    EX = np.roll(X, -1, axis=0) - X
    EY = np.roll(Y, -1, axis=0) - Y
    L = np.sqrt(EX * EX + EY * EY)
    pos = L > 0.0
    UX = np.divide(EX, L, out=np.zeros_like(EX), where=pos)
    UY = np.divide(EY, L, out=np.zeros_like(EY), where=pos)
    return UX, UY, L, pos


def _corners(X: np.ndarray, Y: np.ndarray):
    """(sin, cos, defined) of every corner's angle from e1 = p_{k+1} - p_k to
    e2 = p_{k-1} - p_k, (n, F); ``defined`` is False next to a zero-length edge."""
    UX, UY, _, pos = _edges(*unit_scaled(X, Y))
    PX = np.roll(UX, 1, axis=0)  # edge k-1, e2 = -edge k-1
    PY = np.roll(UY, 1, axis=0)
    sin = PX * UY - PY * UX  # det[e1, e2], the same sign as core.metrics.face_quality's corner det
    cos = -(UX * PX + UY * PY)
    return sin, cos, pos & np.roll(pos, 1, axis=0)


def _signed_angles(X: np.ndarray, Y: np.ndarray):
    """Corner angles in degrees, (-180, 180], and whether each is defined."""
    sin, cos, ok = _corners(X, Y)
    # fpmath.atan2 reads a zero sine as positive: a straight corner is +180, never -180
    return atan2(sin, cos) * (180.0 / np.pi), ok


def min_angle(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Smallest corner angle (deg) per face; negative for a reflex or inverted corner."""
    phi, ok = _signed_angles(X, Y)
    return np.where(ok, phi, 0.0).min(axis=0)


def max_angle(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Largest corner angle (deg, in [0, 360)) per face; above 180 for a reflex or
    inverted corner."""
    phi, ok = _signed_angles(X, Y)
    theta = np.where(phi < 0.0, phi + 360.0, phi)
    return np.where(ok, theta, 180.0).max(axis=0)


def scaled_jacobian(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """min over corners of det[e1, e2] / (|e1| |e2|), over the regular polygon's value."""
    sin, _, ok = _corners(X, Y)
    _, sin_e = regular_corner(X.shape[0])
    return np.where(ok, sin, 0.0).min(axis=0) / sin_e


def skewness(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Equiangle skewness per face (0 for the regular polygon, 1 degenerate)."""
    te = regular_angle(X.shape[0])
    over = (max_angle(X, Y) - te) / (180.0 - te)
    under = (te - min_angle(X, Y)) / te
    return np.maximum(np.maximum(over, under), 0.0)  # >= 0; round-off only could go below


def aspect_ratio(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Longest edge over the smallest width perpendicular to an edge, over the regular
    polygon's ratio; ``ASPECT_MAX`` for a zero-width (collapsed) face."""
    n = X.shape[0]
    X, Y = unit_scaled(X, Y)
    UX, UY, L, pos = _edges(X, Y)
    width = np.full(X.shape[1], np.inf)
    for k in range(n):  # over the n edges of the arity: each step is vectorized over faces
        d = UX[k] * (Y - Y[k]) - UY[k] * (X - X[k])  # signed distances to edge k's line
        extent = np.where(pos[k], d.max(axis=0) - d.min(axis=0), np.inf)
        np.minimum(width, extent, out=width)
    longest = L.max(axis=0) * regular_width(n)
    out = np.full(X.shape[1], ASPECT_MAX)
    np.divide(longest, width, out=out, where=(longest > 0.0) & (width * ASPECT_MAX > longest))
    return out


# -- the measures' table -----------------------------------------------------------------


def _per_arity(tri: float, other: Callable[[int], float]) -> Callable[[int], float]:
    return lambda n: tri if n == 3 else other(n)


@dataclass(frozen=True)
class Measure:
    """One quality measure: how to compute it and how to read it.

    ``threshold(n)``: values beyond it (below for higher-is-better measures, above
    otherwise) are counted as poor; ``ideal(n)`` is the regular polygon's value and
    ``worst(n)`` where the heat map reaches pure red.
    """

    name: str
    label: str
    unit: str
    higher_is_better: bool
    description: str
    group: Callable[[np.ndarray, np.ndarray], np.ndarray]
    ideal: Callable[[int], float]
    threshold: Callable[[int], float]
    worst: Callable[[int], float]

    def beyond(self, values: np.ndarray, n: int | np.ndarray) -> np.ndarray:
        """Which values are beyond the threshold of arity ``n`` (an int or per face)."""
        thr = self._per_face(self.threshold, n, np.shape(values))
        return values < thr if self.higher_is_better else values > thr

    def _per_face(self, fn: Callable[[int], float], n, shape) -> np.ndarray:
        if np.ndim(n) == 0:
            return np.full(shape, fn(int(n)))
        n = np.asarray(n)
        out = np.empty(shape)
        for a in np.unique(n):  # one step per arity present
            out[n == a] = fn(int(a))
        return out


MEASURES: dict[str, Measure] = {m.name: m for m in (
    Measure("mean_ratio", "Mean Ratio", "", True,
            "Mean ratio shape quality (1 = regular polygon, 0 = inverted or degenerate)",
            scaled_group_quality, lambda n: 1.0, lambda n: 0.5, lambda n: 0.0),
    Measure("min_angle", "Minimum Angle", "deg", True,
            "Smallest corner angle in degrees (negative = reflex or inverted corner)",
            min_angle, regular_angle, _per_arity(20.0, lambda n: regular_angle(n) / 2),
            lambda n: 0.0),
    Measure("max_angle", "Maximum Angle", "deg", False,
            "Largest corner angle in degrees (over 180 = reflex or inverted corner)",
            max_angle, regular_angle,
            _per_arity(120.0, lambda n: (regular_angle(n) + 180.0) / 2), lambda n: 180.0),
    Measure("aspect_ratio", "Aspect Ratio", "", False,
            "Longest edge over smallest width, 1 for the regular polygon (elongation only)",
            aspect_ratio, lambda n: 1.0, lambda n: 5.0, lambda n: 25.0),
    Measure("scaled_jacobian", "Scaled Jacobian", "", True,
            "Smallest corner sine over the regular polygon's (1 best, negative = inverted)",
            scaled_jacobian, lambda n: 1.0, lambda n: 0.2, lambda n: 0.0),
    Measure("skewness", "Skewness", "", False,
            "Equiangle skewness (0 = regular, 1 = degenerate, over 1 = reflex or inverted)",
            skewness, lambda n: 0.0, lambda n: 0.85, lambda n: 1.0),
)}

MEASURE_NAMES: tuple[str, ...] = tuple(MEASURES)


def get_measure(name: str) -> Measure:
    """The measure called ``name``; ValueError listing the valid names otherwise."""
    m = MEASURES.get(name) if isinstance(name, str) else None
    if m is None:
        raise ValueError(f"unknown measure {name!r} (valid: {', '.join(MEASURE_NAMES)})")
    return m


def _group_values(p: np.ndarray, fs: FaceSet, m: Measure) -> np.ndarray:
    out = np.empty(fs.n_faces)
    for g in fs.groups:
        out[g.ids] = m.group(p[g.nodes, 0], p[g.nodes, 1])
    return out


def face_values(points, faces, measure: str = "mean_ratio") -> np.ndarray:
    """(F,) values of ``measure`` per face in the given face order."""
    m = get_measure(measure)
    p = check_points(points)
    return _group_values(p, as_faceset(faces, p.shape[0]), m)


# -- summaries and the heat map ----------------------------------------------------------


@dataclass(frozen=True)
class MeasureSummary:
    """min / mean / max of one measure over a mesh and how many faces are beyond its
    threshold (``thresholds``: arity -> threshold, for the arities present)."""

    measure: str
    n_faces: int
    min: float
    mean: float
    max: float
    n_beyond: int
    thresholds: dict[int, float]
    higher_is_better: bool

    def as_dict(self) -> dict:
        """JSON-ready dict (threshold keys as strings)."""
        return {"min": self.min, "mean": self.mean, "max": self.max,
                "n_beyond": self.n_beyond, "n_faces": self.n_faces,
                "beyond": "below" if self.higher_is_better else "above",
                "thresholds": {str(n): t for n, t in self.thresholds.items()}}

    def line(self) -> str:
        """'Minimum Angle (deg): min 12.3, mean 45.6, max 89.9; 7 of 140 faces below 20
        (triangles), 45 (quads)'."""
        m = MEASURES[self.measure]
        unit = f" ({m.unit})" if m.unit else ""
        word = "below" if self.higher_is_better else "above"
        thr = ", ".join(f"{t:.4g} ({_arity_name(n)})" for n, t in self.thresholds.items())
        return (f"{m.label}{unit}: min {self.min:.4g}, mean {self.mean:.4g}, max "
                f"{self.max:.4g}; {self.n_beyond} of {self.n_faces} faces {word} {thr}")


def _arity_name(n: int) -> str:
    return {3: "triangles", 4: "quads"}.get(n, f"{n}-gons")


def summarize(measure: str, values: np.ndarray, arity: np.ndarray) -> MeasureSummary:
    """Summary of per-face ``values`` of ``measure``; ``arity`` is each face's corner
    count (same length)."""
    m = get_measure(measure)
    values = np.asarray(values, dtype=np.float64)
    arity = np.asarray(arity)
    if values.shape != arity.shape or values.ndim != 1:
        raise ValueError("values and arity must be 1D arrays of the same length")
    if values.size == 0:
        raise ValueError("mesh has no faces")
    present = [int(a) for a in np.unique(arity)]
    return MeasureSummary(
        measure=m.name, n_faces=int(values.size), min=float(values.min()),
        mean=add_reduce(values) / values.size, max=float(values.max()),
        n_beyond=int(np.count_nonzero(m.beyond(values, arity))),
        thresholds={n: float(m.threshold(n)) for n in present},
        higher_is_better=m.higher_is_better)


def summaries(points, faces, measures: Iterable[str] = MEASURE_NAMES
              ) -> dict[str, MeasureSummary]:
    """measure name -> MeasureSummary of a mesh, for each of ``measures``."""
    chosen = [get_measure(name) for name in measures]
    p = check_points(points)
    fs = as_faceset(faces, p.shape[0])
    return {m.name: summarize(m.name, _group_values(p, fs, m), fs.counts) for m in chosen}


def goodness(measure: str, values: np.ndarray, arity: np.ndarray | int) -> np.ndarray:
    """Heat-map position of each value in [0, 1]: 1 at the ideal, 0.5 at the threshold,
    0 at (and past) the worst value, linear in between, in the measure's own direction.
    For the mean ratio this is the quality itself, clipped to [0, 1]."""
    m = get_measure(measure)
    v = np.asarray(values, dtype=np.float64)
    ideal = m._per_face(m.ideal, arity, v.shape)
    thr = m._per_face(m.threshold, arity, v.shape)
    worst = m._per_face(m.worst, arity, v.shape)
    good = 0.5 + 0.5 * np.clip((v - thr) / (ideal - thr), 0.0, 1.0)
    bad = 0.5 * np.clip((v - worst) / (thr - worst), 0.0, 1.0)
    return np.where(m.beyond(v, arity), bad, good)
