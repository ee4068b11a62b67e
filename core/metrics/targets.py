"""Per-face target shapes: the mean ratio and the EEGT transform measured against a target
element (Knupp's target matrices) instead of the regular polygon.

Targets come as an (n_corners, 2) array, one 2D point per face corner in the faces' corner
order (`FaceSet.indices`). Only a face's shape counts (translation, rotation and uniform
scale are free). `prepare_targets` validates them once per run and derives what every
consumer needs, per arity group as (n, F_n) arrays aligned with `ArityGroup.nodes`:

- corner k's target matrix W_k = [t_{k+1} - t_k, t_{k-1} - t_k] = Q_k U_k (Q_k a rotation,
  U_k upper triangular). The mean ratio needs U_k only up to scale: (cos_a, inv_sin) =
  (u01 / u00, u00 / u11), which are (cos a, 1 / sin a) for the regular n-gon;
- the centred, normalised target nodes T (2 x n) and c_n K, K = T^T (T T^T)^-1, for the
  generalised stretch (core.eegt.transform).

A face whose target has a non-finite value, a corner with det(W_k) <= FLAT_TOL |w1| |w2|
(concave, straight, degenerate or clockwise) or a width below THIN_TOL of its length falls
back to the regular polygon.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .. import fpmath
from ..mesh.faces import FaceSet, as_faceset

__all__ = [
    "FLAT_TOL",
    "THIN_TOL",
    "GroupTargets",
    "Targets",
    "corner_factors",
    "corner_vectors",
    "face_shapes_2d",
    "prepare_targets",
    "regular_polygon",
    "stretch_gain",
    "target_fallback_note",
]

# a target corner counts as flat when sin(angle) <= FLAT_TOL: straight corners of float32
# data (sin ~1e-7 of round-off) fall back instead of demanding an exactly straight corner
FLAT_TOL = 1e-6
# a target counts as degenerate when thinner than THIN_TOL times its length (aspect 1e8)
THIN_TOL = 1e-8


def stretch_gain(n: int) -> float:
    """c_n = sum_{r=1..R} 2 sin(2 pi r / n), R = ceil((n - 1) / 4): the paper's stretch of
    an n-gon's regular mode (eigenvalue (mu_1 - 1) / lambda of eq. 10)."""
    return _stretch_gain(int(n))


@lru_cache(maxsize=256)
def _stretch_gain(n: int) -> float:
    total = 0.0
    for r in range(1, math.ceil((n - 1) / 4.0) + 1):
        t = 2.0 * math.pi * r / n  # <= pi / 2 + pi / n <= pi
        total += 2.0 * fpmath.sin_cos(t)[0]
    return total


@lru_cache(maxsize=256)
def regular_polygon(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) of the regular n-gon on the unit circle, counterclockwise from (1, 0)
    (portable bits: core.fpmath's sin_cos, mirrored past pi)."""
    x, y = np.empty(n), np.empty(n)
    for k in range(n):
        if 2 * k <= n:
            s, c = fpmath.sin_cos(2.0 * math.pi * k / n)
        else:
            s, c = fpmath.sin_cos(2.0 * math.pi * (n - k) / n)
            s = -s
        x[k], y[k] = c, s
    x.flags.writeable = y.flags.writeable = False
    return x, y


@dataclass(frozen=True)
class GroupTargets:
    """Targets of one arity group; (n, F) arrays: corner k of face j of the group is [k, j]."""

    n: int
    fallback: np.ndarray  # (F,) bool: the target was unusable, the regular polygon is used
    x: np.ndarray  # centred target nodes, farthest node at (1, 0) (regular polygon: fallbacks)
    y: np.ndarray
    kx: np.ndarray  # c_n K: M c_n = P_centred (c_n K) is the least-squares map target -> face
    ky: np.ndarray
    cos_a: np.ndarray  # u01 / u00 of corner k (cos a for the regular n-gon)
    inv_sin: np.ndarray  # u00 / u11 of corner k (1 / sin a for the regular n-gon)

    @property
    def corners(self) -> tuple[np.ndarray, np.ndarray]:
        """(cos_a, inv_sin): what `quality.group_quality` needs per corner."""
        return self.cos_a, self.inv_sin


@dataclass(frozen=True)
class Targets:
    """Prepared targets of one FaceSet: `groups[i]` belongs to `faces.groups[i]`."""

    groups: tuple[GroupTargets, ...]
    fallback: np.ndarray  # (F,) bool in face order
    n_corners: int

    @property
    def n_fallback(self) -> int:
        return int(self.fallback.sum())


def target_fallback_note(n_fallback: int) -> str:
    """The sentence that reports faces whose target fell back to the regular polygon."""
    return (f"{n_fallback} faces have an unusable target shape (concave, straight, degenerate, "
            "clockwise or not finite): measured against the regular polygon")


def _check_array(targets, n_corners: int) -> np.ndarray:
    try:
        t = fpmath.float64_copy(targets)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"targets must be an ({n_corners}, 2) array of numbers ({exc})") from None
    if t.shape != (n_corners, 2):
        raise ValueError(
            f"targets must be an ({n_corners}, 2) array (one 2D point per face corner, "
            f"in the faces' corner order), got shape {t.shape}"
        )
    return t


def corner_vectors(x: np.ndarray, y: np.ndarray):
    """(w1x, w1y, w2x, w2y) of every corner of (n, F) corner coordinates: w1 = p_{k+1} - p_k
    (to the next corner), w2 = p_{k-1} - p_k (to the one before); det[w1, w2] > 0 where the
    face turns counterclockwise."""
    return (np.roll(x, -1, axis=0) - x, np.roll(y, -1, axis=0) - y,
            np.roll(x, 1, axis=0) - x, np.roll(y, 1, axis=0) - y)


def _normalised(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Targets of a group centred, scaled to max |coordinate| 1 per face (no overflow for any
    finite input) and turned so that the node farthest from the centroid lies on the x axis
    (near a thin target's long axis, which keeps T T^T's det free of cancellation); and the
    (F,) mask of faces with finite, not all equal values."""
    with np.errstate(invalid="ignore", over="ignore"):
        finite = np.isfinite(x).all(axis=0) & np.isfinite(y).all(axis=0)
        x, y = np.where(finite, x, 0.0), np.where(finite, y, 0.0)
        for _ in range(2):  # scale, centre, rescale (the centring cannot overflow)
            s = np.maximum(np.abs(x).max(axis=0), np.abs(y).max(axis=0))
            s = np.where(s > 0.0, s, 1.0)
            x, y = x / s, y / s
            x = x - x.sum(axis=0) / x.shape[0]
            y = y - y.sum(axis=0) / y.shape[0]
        r2 = x * x + y * y
        far = r2.argmax(axis=0)[None, :]
        r = np.sqrt(np.take_along_axis(r2, far, axis=0)[0])
        ok = finite & (r > 0.0)
        r = np.where(ok, r, 1.0)
        ux = np.take_along_axis(x, far, axis=0)[0] / r
        uy = np.take_along_axis(y, far, axis=0)[0] / r
        x, y = (ux * x + uy * y) / r, (ux * y - uy * x) / r
    return x, y, ok


def _group_targets(n: int, x: np.ndarray, y: np.ndarray) -> GroupTargets:
    x, y, ok = _normalised(x, y)
    w1x, w1y, w2x, w2y = corner_vectors(x, y)
    det = w1x * w2y - w1y * w2x
    l1sq = w1x * w1x + w1y * w1y
    l2sq = w2x * w2x + w2y * w2y
    a, b, d = (x * x).sum(axis=0), (x * y).sum(axis=0), (y * y).sum(axis=0)
    gram = a * d - b * b  # det(T T^T) = (a + d)^2 (thin / long)^2 roughly
    with np.errstate(invalid="ignore", over="ignore"):
        convex = det > FLAT_TOL * np.sqrt(l1sq * l2sq)
        thick = gram > (THIN_TOL * (a + d)) ** 2
    fallback = ~(ok & convex.all(axis=0) & thick)
    rx, ry = regular_polygon(n)
    cos_r, sin_r = fpmath.regular_corner(n)
    keep = ~fallback
    x = np.where(keep, x, rx[:, None])
    y = np.where(keep, y, ry[:, None])
    # K = T^T (T T^T)^-1 (T T^T is positive definite: a convex polygon spans the plane)
    a, b, d = (x * x).sum(axis=0), (x * y).sum(axis=0), (y * y).sum(axis=0)
    g = stretch_gain(n) / (a * d - b * b)
    kx = (x * d - y * b) * g
    ky = (y * a - x * b) * g
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_a = np.where(keep, (w1x * w2x + w1y * w2y) / l1sq, cos_r)
        inv_sin = np.where(keep, l1sq / det, 1.0 / sin_r)
    return GroupTargets(n, fallback, x, y, kx, ky, cos_a, inv_sin)


def prepare_targets(targets, faces: FaceSet) -> Targets | None:
    """Validate per-corner targets for `faces` and precompute their per-group data.

    None stays None (every face's target is the regular polygon: the paper's path). An
    already prepared Targets is checked against `faces` and returned. ValueError (one line)
    for anything but an (n_corners, 2) array of numbers."""
    if targets is None:
        return None
    if isinstance(targets, Targets):
        if targets.n_corners != faces.n_corners or [t.n for t in targets.groups] != [
            g.n for g in faces.groups
        ] or [t.fallback.size for t in targets.groups] != [g.size for g in faces.groups]:
            raise ValueError("prepared targets belong to other faces")
        return targets
    t = _check_array(targets, faces.n_corners)
    groups = []
    fallback = np.zeros(faces.n_faces, dtype=bool)
    for g in faces.groups:
        rows = faces.offsets[g.ids][None, :] + np.arange(g.n)[:, None]  # (n, F) corner rows
        gt = _group_targets(g.n, t[rows, 0], t[rows, 1])
        fallback[g.ids] = gt.fallback
        groups.append(gt)
    return Targets(tuple(groups), fallback, faces.n_corners)


def corner_factors(
    targets, faces: FaceSet
) -> dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Upper-triangular factors of the target corner matrices, for the global stage.

    `targets`: None, an (n_corners, 2) array or a prepared Targets of `faces`.
    Returns {arity n: (u00, u01, u11)}, each an (F_n, n) array whose row i belongs to row i
    of `faces.by_arity()[n]` and column k to its corner k (nodes k, k + 1, k - 1). Corner k's
    target matrix is W_k = [t_{k+1} - t_k, t_{k-1} - t_k] = Q_k [[u00, u01], [0, u11]] with
    Q_k a rotation, u00 > 0, u11 > 0, for the face's target scaled (uniformly) to the area
    of the regular n-gon with unit edges, n / (4 tan(pi / n)). So J_k U_k^-1 has the det and
    Frobenius norm of J_k W_k^-1, and multiplying U_k by a reference edge length s gives the
    target at the size of a regular n-gon of edge s. With `targets` None, and for fallback
    faces, U_k = [[1, cos a], [0, sin a]], a = (n - 2) pi / n, exactly the constants of
    core.fpmath.regular_corner: W = s U is the regular corner the stage uses without targets.
    """
    targets = prepare_targets(targets, faces)
    out = {}
    for i, g in enumerate(faces.groups):
        cos_r, sin_r = fpmath.regular_corner(g.n)
        shape = (g.size, g.n)
        u00, u01, u11 = np.ones(shape), np.full(shape, cos_r), np.full(shape, sin_r)
        if targets is not None:
            gt = targets.groups[i]
            keep = ~gt.fallback
            x, y = gt.x[:, keep], gt.y[:, keep]
            w1x, w1y, w2x, w2y = corner_vectors(x, y)
            area = 0.5 * (x * np.roll(y, -1, axis=0) - np.roll(x, -1, axis=0) * y).sum(axis=0)
            sigma = np.sqrt(g.n / (4.0 * fpmath.tan_pi_over(g.n)) / area)
            l1 = np.sqrt(w1x * w1x + w1y * w1y)
            u00[keep] = (l1 * sigma).T
            u01[keep] = ((w1x * w2x + w1y * w2y) / l1 * sigma).T
            u11[keep] = ((w1x * w2y - w1y * w2x) / l1 * sigma).T
        out[g.n] = (u00, u01, u11)
    return out


def face_shapes_2d(points3d, faces) -> np.ndarray:
    """(n_corners, 2) targets from faces in 3D: each face's corners in 2D coordinates of its
    own plane (Newell normal, counterclockwise about it), e.g. a UV face's 3D shape.

    Faces with a zero normal (degenerate) or non-finite points come out collinear or NaN,
    which makes them fall back to the regular polygon."""
    p = np.asarray(points3d, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points3d must be an (N, 3) array, got shape {p.shape}")
    faces = as_faceset(faces, p.shape[0])
    out = np.zeros((faces.n_corners, 2))
    for g in faces.groups:
        P = p[g.nodes]  # (n, F, 3)
        c = P.sum(axis=0) / g.n
        Q = P - c
        R = np.roll(Q, -1, axis=0)
        normal = np.stack([
            (Q[..., 1] * R[..., 2] - Q[..., 2] * R[..., 1]).sum(axis=0),
            (Q[..., 2] * R[..., 0] - Q[..., 0] * R[..., 2]).sum(axis=0),
            (Q[..., 0] * R[..., 1] - Q[..., 1] * R[..., 0]).sum(axis=0),
        ], axis=-1)  # (F, 3)
        nn = np.sqrt((normal * normal).sum(axis=-1, keepdims=True))
        normal = normal / np.where(nn > 0.0, nn, 1.0)
        # u: the longest edge direction of the face projected into its plane, v = n x u
        E = R - Q
        elen = (E * E).sum(axis=-1)
        e = np.take_along_axis(E, elen.argmax(axis=0)[None, :, None], axis=0)[0]
        e = e - (e * normal).sum(axis=-1, keepdims=True) * normal
        el = np.sqrt((e * e).sum(axis=-1, keepdims=True))
        u = e / np.where(el > 0.0, el, 1.0)
        v = np.cross(normal, u)
        rows = faces.offsets[g.ids][None, :] + np.arange(g.n)[:, None]
        out[rows, 0] = (Q * u).sum(axis=-1)
        out[rows, 1] = (Q * v).sum(axis=-1)
    return out
