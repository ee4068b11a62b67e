"""Mean-ratio quality of a mesh (docs/method.md 3): per face (`quality`, or another measure
of core.metrics.measures by name) and the paper's table columns (`Stats`, `mesh_stats`). The formula
itself, per arity group, is core.metrics.mean_ratio's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fpmath import add_reduce
from ..mesh.faces import FaceSet, as_faceset
from ..mesh.points import check_points
from .kept import Kept
from .mean_ratio import scaled_group_quality
from .measures import face_values
from .targets import Targets, corner_vectors, prepare_targets

__all__ = [
    "Stats",
    "folded_area",
    "inverted_corners",
    "mesh_stats",
    "quality",
    "signed_face_areas",
    "stats_of",
]

@dataclass(frozen=True)
class Stats:
    """The paper's table columns for one mesh state."""

    n_inverted: int
    q_min: float
    q_avg: float

    def better_than(self, other: Stats) -> bool:
        """Fewer inverted, then higher q_min, then higher q_avg (docs/method.md 2)."""
        return (-self.n_inverted, self.q_min, self.q_avg) > (
            -other.n_inverted,
            other.q_min,
            other.q_avg,
        )

    def as_dict(self) -> dict:
        return {"n_inverted": self.n_inverted, "q_min": self.q_min, "q_avg": self.q_avg}


def stats_of(qs: list[np.ndarray]) -> Stats:
    """Stats over the per-group quality arrays (inverted faces count as 0)."""
    total = sum(q.size for q in qs)
    n_inv = sum(int(np.count_nonzero(q == 0.0)) for q in qs)
    q_min = min(float(q.min()) for q in qs if q.size)
    q_avg = sum(add_reduce(q) for q in qs) / total
    return Stats(n_inv, q_min, q_avg)


def quality(points, faces, targets=None, measure: str = "mean_ratio",
            kept: Kept | None = None) -> np.ndarray:
    """(F,) mean ratio per face in the given face order, 0 for inverted faces; or another
    measure of `core.metrics.measures` (ValueError for an unknown name).

    `targets`: None (against the regular polygon), or an (n_corners, 2) array of per-corner
    target points in the faces' corner order (or a prepared core.metrics.targets.Targets): the mean
    ratio against each face's target shape (1 = similar to it); the mean ratio only.
    Every measure is scale-safe: a mesh times 2^k reads the same bits at any finite scale.

    `kept`: the corners kept as given (core.metrics.kept.kept_corners of these faces): the
    faces are measured without them (targets in either faces' corner order); None:
    every corner counts (the paper's rule, and every mesh without such corners)."""
    if kept is not None:
        if (targets is not None and not isinstance(targets, Targets)
                and len(targets) == kept.faces.n_corners):  # the caller's corner order
            targets = np.asarray(targets, dtype=np.float64)[~kept.corner]
        return kept.check(points, quality(points, kept.measured, targets, measure))
    if measure != "mean_ratio":
        if targets is not None:
            raise ValueError(f"targets apply to the mean ratio only, not to {measure!r}")
        return face_values(points, faces, measure)
    p = check_points(points)
    fs = as_faceset(faces, p.shape[0])
    tg = prepare_targets(targets, fs)
    out = np.empty(fs.n_faces)
    for i, g in enumerate(fs.groups):
        corners = None if tg is None else tg.groups[i].corners
        out[g.ids] = scaled_group_quality(p[g.nodes, 0], p[g.nodes, 1], corners)
    return out


def mesh_stats(points, faces, targets=None, kept: Kept | None = None) -> Stats:
    """n_inverted, q_min, q_avg of a mesh (quality against `targets`, with the corners
    `kept` as given left out, as in `quality`)."""
    q = quality(points, faces, targets=targets, kept=kept)
    return stats_of([q])


def folded_area(points: np.ndarray, faces) -> np.ndarray:
    """(F,) how far each face is folded over: half the sum of its corners' negative
    determinants (a corner's det: the cross product of its two edges, > 0 when the face turns
    counterclockwise there); 0 for a face with no inverted corner, three times its area for
    an inverted triangle. A measure of how much fold a start leaves to undo, which
    a count of inverted faces is not: a sliver barely turned counts as much as a face turned
    over (docs/global_untangle.md, "Which start first")."""
    p = check_points(points)
    fs = as_faceset(faces, p.shape[0])
    out = np.zeros(fs.n_faces)
    for g in fs.groups:
        ax, ay, bx, by = corner_vectors(p[g.nodes, 0], p[g.nodes, 1])
        det = ax * by - ay * bx
        out[g.ids] = 0.5 * np.maximum(-det, 0.0).sum(axis=0)
    return out


def signed_face_areas(points: np.ndarray, fs: FaceSet) -> np.ndarray:
    """(F,) signed area of every face (shoelace; positive = counterclockwise)."""
    out = np.empty(fs.n_faces)
    for g in fs.groups:
        x, y = points[g.nodes, 0], points[g.nodes, 1]
        out[g.ids] = 0.5 * np.sum(x * np.roll(y, -1, axis=0) - np.roll(x, -1, axis=0) * y, axis=0)
    return out


def inverted_corners(p: np.ndarray, fs: FaceSet) -> np.ndarray:
    """(F,) bool: faces with a corner that does not turn left."""
    out = np.zeros(fs.n_faces, dtype=bool)
    for g in fs.groups:
        xr, yr = p[g.nodes, 0], p[g.nodes, 1]
        bad = np.zeros(g.size, dtype=bool)
        for k in range(g.n):
            a, b = (k + 1) % g.n, k - 1
            det = (xr[a] - xr[k]) * (yr[b] - yr[k]) - (yr[a] - yr[k]) * (xr[b] - xr[k])
            bad |= ~(det > 0.0)
        out[g.ids] = bad
    return out
