"""Elementary functions built from IEEE basic operations only: the same bits on every CPU.

NumPy evaluates float64 log, exp, tan and power with code chosen at run time by CPU
feature (AVX-512 kernels where the CPU has them, libm elsewhere), and the two differ in the
last bit. A long optimization turns one ulp into another trajectory, so the core never calls
them: these use only +, -, *, /, sqrt (correctly rounded everywhere), frexp / ldexp / rint
(exact) and fixed polynomial orders. Accuracy is 1-3 ulp, which is all the core needs.
The OpenCL kernels implement `power` with the same operations in the same order.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import lru_cache

import numpy as np

__all__ = [
    "KERNEL_SCALARS",
    "PAIRWISE_BLOCK",
    "POW_CODES",
    "REDUCE_CHUNK",
    "add_reduce",
    "add_reduce_rows",
    "add_reducer",
    "atan2",
    "exp",
    "float64_copy",
    "log",
    "power",
    "power_code",
    "regular_corner",
    "sin_cos",
    "tan_pi_over",
]

_SQRT_HALF = 0.7071067811865476  # the double nearest sqrt(1/2)
_LN2_HI = 6.93147180369123816490e-01  # ln 2 split so that k * _LN2_HI is exact for |k| < 2^20
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.4426950408889634
# log(m) = 2 atanh(f) = 2 f sum_k s^k / (2k + 1), f = (m - 1) / (m + 1), s = f^2 <= 0.0295
LOG_COEFFS = tuple(1.0 / (2 * k + 1) for k in range(12))
# exp(r) = sum_j r^j / j!, |r| <= ln(2) / 2
EXP_COEFFS = tuple(1.0 / math.factorial(j) for j in range(14))
_EXP_MAX, _EXP_MIN = 709.782712893384, -745.1332191019412
# the scalars above under the kernels' names (build defines: core.opencl.build.fpmath_options)
KERNEL_SCALARS = {"FP_SQRT_HALF": _SQRT_HALF, "FP_LN2_HI": _LN2_HI, "FP_LN2_LO": _LN2_LO,
                  "FP_INV_LN2": _INV_LN2, "FP_EXP_MAX": _EXP_MAX, "FP_EXP_MIN": _EXP_MIN}
# `power`'s exact fast paths (what NumPy's `x ** e` computes for these e), as codes for the
# OpenCL kernels' np_pow; POW_GENERAL: exp(e log x)
POW_CODES = {"POW_GENERAL": 0, "POW_SQUARE": 1, "POW_IDENTITY": 2, "POW_ONE": 3, "POW_SQRT": 4,
             "POW_RECIPROCAL": 5}
_POW_FAST = {2.0: "POW_SQUARE", 1.0: "POW_IDENTITY", 0.0: "POW_ONE", 0.5: "POW_SQRT",
             -1.0: "POW_RECIPROCAL"}
# NumPy's float64 add.reduce order, which the OpenCL kernels reproduce: buffers of
# REDUCE_CHUNK values in order (NumPy 1's reduction buffer), each by pairwise_sum, which
# halves a run at n / 2 rounded down to a multiple of 8 down to blocks of at most
# PAIRWISE_BLOCK values (NumPy's PW_BLOCKSIZE), added with 8 interleaved partial sums
PAIRWISE_BLOCK = 128
REDUCE_CHUNK = 8192


def add_reduce(values: np.ndarray) -> float:
    """The sum of a float64 array (all its values, C order) in the order above, whatever the
    NumPy: NumPy 2 sums more than REDUCE_CHUNK values as one pairwise tree, NumPy 1 chunk by
    chunk, and the two differ in the last bits. Each chunk goes to NumPy as a row of its own
    (rows of at most REDUCE_CHUNK values are summed alike by every NumPy), the chunk sums are
    added in order."""
    a = values.reshape(-1)
    n = a.size
    if n <= REDUCE_CHUNK:
        return float(np.add.reduce(a))
    full = n - n % REDUCE_CHUNK
    parts = np.add.reduce(a[:full].reshape(-1, REDUCE_CHUNK), axis=1)
    if full < n:
        parts = np.append(parts, np.add.reduce(a[full:]))
    return float(np.add.accumulate(parts)[-1])


def add_reducer(n: int) -> Callable[[np.ndarray], float]:
    """`add_reduce` for contiguous 1-D arrays of n values, picked once for a loop that sums
    many: NumPy's own add.reduce when n fits one chunk (the same order under every NumPy,
    without add_reduce's reshaping and size test: a fifth of a small L-BFGS iteration's time
    went to those), add_reduce otherwise."""
    if n > REDUCE_CHUNK:
        return add_reduce
    reduce = np.add.reduce
    return lambda a: float(reduce(a))


def add_reduce_rows(values: np.ndarray) -> list[float]:
    """`add_reduce` of each row of a 2-D float64 array."""
    if values.shape[1] <= REDUCE_CHUNK:
        return np.add.reduce(values, axis=1).tolist()
    return [add_reduce(row) for row in values]


def power_code(e: float) -> int:
    """How `power` evaluates x ** e: a POW_CODES value (a fast path, or POW_GENERAL)."""
    return POW_CODES[_POW_FAST.get(float(e), "POW_GENERAL")]


def float64_copy(values) -> np.ndarray:
    """A float64 copy of array-like input; TypeError for complex numbers, whose imaginary
    parts NumPy's cast would drop with only a ComplexWarning (ValueError or TypeError, as
    NumPy raises them, for other non-numbers)."""
    raw = np.asarray(values)
    if np.iscomplexobj(raw):
        raise TypeError(f"got complex numbers ({raw.dtype}), the imaginary parts would be lost")
    return np.array(raw, dtype=np.float64)


def log(x: np.ndarray) -> np.ndarray:
    """Natural log of positive finite values (others: NaN or -inf as math says)."""
    x = np.asarray(x, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        m, e = np.frexp(x)  # x = m 2^e, 0.5 <= m < 1
        low = m < _SQRT_HALF
        m = np.where(low, m * 2.0, m)  # now sqrt(1/2) <= m < sqrt(2)
        k = (e - low).astype(np.float64)
        f = (m - 1.0) / (m + 1.0)
        s = f * f
        p = np.full_like(s, LOG_COEFFS[-1])
        for c in LOG_COEFFS[-2::-1]:
            p = p * s + c
        out = k * _LN2_HI + (k * _LN2_LO + 2.0 * f * p)
    if x.size and float(x.min()) > 0.0 and float(x.max()) < np.inf:
        return out  # the usual case: no special values to patch
    out = np.where(x > 0.0, out, np.where(x == 0.0, -np.inf, np.nan))
    return np.where(np.isposinf(x), np.inf, out)


def exp(x: np.ndarray) -> np.ndarray:
    """e^x (overflow gives inf, underflow 0; NaN stays NaN)."""
    x = np.asarray(x, dtype=np.float64)
    xc = np.clip(x, _EXP_MIN, _EXP_MAX)
    k = np.rint(xc * _INV_LN2)
    r = (xc - k * _LN2_HI) - k * _LN2_LO
    p = np.full_like(r, EXP_COEFFS[-1])
    for c in EXP_COEFFS[-2::-1]:
        p = p * r + c
    out = np.ldexp(p, np.nan_to_num(k).astype(np.intc))
    if x.size and float(x.min()) >= _EXP_MIN and float(x.max()) <= _EXP_MAX:
        return out  # the usual case (NaN fails both tests)
    out = np.where(x > _EXP_MAX, np.inf, np.where(x < _EXP_MIN, 0.0, out))
    return np.where(np.isnan(x), np.nan, out)


def power(x: np.ndarray, e: float) -> np.ndarray:
    """x^e for x >= 0: NumPy's exact fast paths for e in {2, 1, 0, 0.5, -1} (what `x ** e`
    computes there), exp(e log x) otherwise."""
    x = np.asarray(x, dtype=np.float64)
    e = float(e)
    if e == 2.0:
        return x * x
    if e == 1.0:
        return x.copy()
    if e == 0.0:
        return np.ones_like(x)
    if e == 0.5:
        return np.sqrt(x)
    if e == -1.0:
        return 1.0 / x
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return exp(e * log(x))


def sin_cos(t: float) -> tuple[float, float]:
    """(sin t, cos t) for 0 <= t <= pi by fixed-length Taylor series on Python floats."""
    t = float(t)
    h = 0.5 * t  # series at t / 2, then the double-angle formulas (cos from 1 - 2 sin^2)
    s = c = 0.0
    term_s, term_c = h, 1.0
    h2 = h * h
    for j in range(1, 16):
        s += term_s
        c += term_c
        term_s = -term_s * h2 / ((2 * j) * (2 * j + 1))
        term_c = -term_c * h2 / ((2 * j - 1) * (2 * j))
    return 2.0 * s * c, (c - s) * (c + s)


@lru_cache(maxsize=256)
def tan_pi_over(n: int) -> float:
    """tan(pi / n) for n >= 3, exact where the value is a square root."""
    special = {3: math.sqrt(3.0), 4: 1.0, 6: 1.0 / math.sqrt(3.0)}
    if n in special:
        return special[n]
    s, c = sin_cos(math.pi / n)
    return s / c


@lru_cache(maxsize=256)
def regular_corner(n: int) -> tuple[float, float]:
    """(cos a, sin a) of the regular n-gon's interior angle a = (n - 2) pi / n."""
    half3 = 0.5 * math.sqrt(3.0)
    special = {3: (0.5, half3), 4: (0.0, 1.0), 6: (-0.5, half3)}
    if n in special:
        return special[n]
    s, c = sin_cos(2.0 * math.pi / n)  # a = pi - 2 pi / n
    return -c, s


_TAN_PI_8 = 0.41421356237309503  # sqrt(2) - 1
# atan(u) = u sum_k (-1)^k s^k / (2k + 1), s = u^2 <= tan^2(pi/8) = 0.1716: 24 terms
ATAN_COEFFS = tuple((1.0 if k % 2 == 0 else -1.0) / (2 * k + 1) for k in range(24))


def atan2(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Angle of the vector (x, y) in (-pi, pi], 0 for (0, 0). A zero y counts as positive
    whatever its sign (y = -0.0 with x < 0 gives +pi). Finite inputs only."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    a, b = np.abs(x), np.abs(y)
    big, small = np.maximum(a, b), np.minimum(a, b)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(big > 0.0, small / big, 0.0)  # tan of the angle folded into [0, pi/4]
    high = t > _TAN_PI_8  # atan t = pi/4 + atan((t - 1) / (t + 1)), |u| <= tan(pi/8)
    u = np.where(high, (t - 1.0) / (t + 1.0), t)
    s = u * u
    p = np.full_like(s, ATAN_COEFFS[-1])
    for c in ATAN_COEFFS[-2::-1]:
        p = p * s + c
    r = np.where(high, 0.25 * math.pi + u * p, u * p)
    r = np.where(b > a, 0.5 * math.pi - r, r)
    r = np.where(x < 0.0, math.pi - r, r)
    return np.where(y < 0.0, -r, r)
