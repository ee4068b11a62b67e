"""Mean-ratio quality (docs/method.md 3) of arity groups, one definition for every arity.

For corner k of an n-gon, J_k = [p_{k+1} - p_k, p_{k-1} - p_k] and M_k = J_k W_n^{-1}, with
W_n the same corner of the regular n-gon; q_k = 2 det(M_k) / |M_k|_F^2 and q(E) = mean_k q_k,
or 0 when any det(J_k) <= 0 (inverted, reflex corner, degenerate). With per-face targets
(core.metrics.targets) W_k is the target's corner instead: quality 1 = similar to the target.

The engines call `group_quality` on the run's normalised coordinates (no extra pass); the
public functions (core.metrics.face_quality, core.metrics.measures) use the scale-safe
`scaled_group_quality`: a face whose squared edges would overflow or underflow is computed
again at unit size (a power of two: exact), so every finite scale reads the same.
"""

from __future__ import annotations

import numpy as np

from ..fpmath import regular_corner

__all__ = [
    "SAFE_HI",
    "SAFE_LO",
    "corner_constants",
    "group_quality",
    "scaled_group_quality",
    "unit_scaled",
]

_SQRT3 = np.sqrt(3.0)
FACE_PIECE = 32768  # faces per piece of `_mean_ratio`


def corner_constants(n: int) -> tuple[float, float]:
    """(cos a, 1 / sin a) of the regular n-gon's interior angle a = (n - 2) pi / n."""
    cos_a, sin_a = regular_corner(n)  # CPU-independent bits (core.fpmath)
    return cos_a, 1.0 / sin_a


def group_quality(
    X: np.ndarray, Y: np.ndarray, corners: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    """Mean ratio of each face of one arity group; X, Y are (n, F) corner coordinates.

    `corners`: None (the regular n-gon) or per-corner target factors (cos_a, inv_sin), (n, F)
    arrays (`GroupTargets.corners`): W_k = Q_k U_k with U_k proportional to
    [[1, cos_a], [0, 1 / inv_sin]]; every arity then takes the general corner formula.
    The engines' path: squared edges overflow beyond about 1e154 (`scaled_group_quality`
    is the scale-safe one)."""
    return _mean_ratio(X, Y, corners, False)[0]


def _mean_ratio(
    X: np.ndarray, Y: np.ndarray, corners: tuple[np.ndarray, np.ndarray] | None, sized: bool
) -> tuple[np.ndarray, np.ndarray | None]:
    """(mean ratio, each face's sum of squared edges when `sized`, else None), in pieces of
    at most FACE_PIECE faces: the temporaries stay in cache instead of a dozen fresh arrays
    of the whole group. Every value is per face and every piece is as wide as half a piece
    or more, so each sum over a face's corners runs as on the whole array: the same bits."""
    m = X.shape[1]
    if m <= FACE_PIECE:
        return _mean_ratio_piece(X, Y, corners, sized)
    q, ssq = np.empty(m), np.empty(m) if sized else None
    cuts = -(-m // FACE_PIECE)  # pieces of equal width (up to one face)
    for i in range(cuts):
        k = slice(i * m // cuts, (i + 1) * m // cuts)
        part = None if corners is None else (corners[0][:, k], corners[1][:, k])
        q[k], s = _mean_ratio_piece(X[:, k], Y[:, k], part, sized)
        if sized:
            ssq[k] = s
    return q, ssq


def _mean_ratio_piece(
    X: np.ndarray, Y: np.ndarray, corners: tuple[np.ndarray, np.ndarray] | None, sized: bool
) -> tuple[np.ndarray, np.ndarray | None]:
    """`_mean_ratio` of a few faces."""
    n = X.shape[0]
    EX = np.roll(X, -1, axis=0) - X  # edge k: p_{k+1} - p_k
    EY = np.roll(Y, -1, axis=0) - Y
    if corners is not None:
        return _target_quality(EX, EY, *corners, sized)
    if n == 3:
        two_area = EX[0] * EY[1] - EY[0] * EX[1]
        ssq = (EX * EX + EY * EY).sum(axis=0)
        ok = (two_area > 0) & (ssq > 0)
        q = np.zeros(X.shape[1])
        np.divide(2.0 * _SQRT3 * two_area, ssq, out=q, where=ok)
        return q, ssq
    # corner k: e1 = E_k, e2 = -E_{k-1}
    PX = np.roll(EX, 1, axis=0)  # E_{k-1}
    PY = np.roll(EY, 1, axis=0)
    det = PX * EY - PY * EX  # det[e1, e2] = E_{k-1} x E_k
    cos_a, inv_sin = corner_constants(n)
    e1sq = EX * EX + EY * EY
    if n == 4:
        fro = e1sq + PX * PX + PY * PY
        scale = 2.0
    else:
        mx = (-PX - cos_a * EX) * inv_sin
        my = (-PY - cos_a * EY) * inv_sin
        fro = e1sq + mx * mx + my * my
        scale = 2.0 * inv_sin
    ok = (det > 0).all(axis=0) & (fro > 0).all(axis=0)
    qk = np.zeros_like(det)
    np.divide(scale * det, fro, out=qk, where=det > 0)
    return np.where(ok, qk.mean(axis=0), 0.0), e1sq.sum(axis=0) if sized else None


def _target_quality(
    EX: np.ndarray, EY: np.ndarray, cos_a: np.ndarray, inv_sin: np.ndarray, sized: bool
) -> tuple[np.ndarray, np.ndarray | None]:
    """group_quality's n >= 5 corner formula with per-corner constants, for every arity."""
    PX = np.roll(EX, 1, axis=0)  # E_{k-1}
    PY = np.roll(EY, 1, axis=0)
    det = PX * EY - PY * EX
    e1sq = EX * EX + EY * EY
    mx = (-PX - cos_a * EX) * inv_sin
    my = (-PY - cos_a * EY) * inv_sin
    fro = e1sq + mx * mx + my * my
    ok = (det > 0).all(axis=0) & (fro > 0).all(axis=0)
    qk = np.zeros_like(det)
    np.divide((2.0 * inv_sin) * det, fro, out=qk, where=det > 0)
    return np.where(ok, qk.mean(axis=0), 0.0), e1sq.sum(axis=0) if sized else None


def unit_scaled(X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, F) corner coordinates, each face times the power of two that brings its largest
    |coordinate| into [0.5, 1). Exact, and every measure here is scale-invariant, so the
    values stay; but squared edges can neither overflow (faces beyond about 1e154) nor
    underflow (below about 1e-154)."""
    big = np.abs(X[0])
    for row in (*X[1:], *Y):
        np.maximum(big, np.abs(row), out=big)
    _, e = np.frexp(big)
    if e.size and (int(e.min()) < -1021 or int(e.max()) > 1021):  # 2^-e is no normal float
        return np.ldexp(X, -e), np.ldexp(Y, -e)
    s = np.ldexp(1.0, -e)  # X * 2^-e: the same bits as ldexp, several times faster
    return X * s, Y * s


# Sums of squared edges in [SAFE_LO, SAFE_HI]: no square, product or corner term is near
# overflow or the subnormal range (a margin of 2^400 left for target corner factors)
SAFE_LO, SAFE_HI = 2.0**-600, 2.0**600


def scaled_group_quality(
    X: np.ndarray, Y: np.ndarray, corners: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    """`group_quality`, right at any finite scale: faces whose squared edges leave
    [SAFE_LO, SAFE_HI] (or overflow) are computed again scaled by `unit_scaled` (exact).
    Faces in range keep `group_quality`'s bits; any face scaled by 2^k reads the same."""
    with np.errstate(over="ignore", invalid="ignore"):  # the faces it hits are redone
        q, size = _mean_ratio(X, Y, corners, True)
    redo = np.flatnonzero(~((size >= SAFE_LO) & (size <= SAFE_HI)))
    if redo.size == q.size:  # the whole group (a mesh far from unit size): no gathering
        return group_quality(*unit_scaled(X, Y), corners)
    if redo.size:
        part = None if corners is None else (corners[0][:, redo], corners[1][:, redo])
        q[redo] = group_quality(*unit_scaled(X[:, redo], Y[:, redo]), part)
    return q
