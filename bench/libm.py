"""Powers for the generated meshes that come out the same on every x86-64 CPU.

NumPy's float64 `power` takes its own vector code on CPUs with AVX-512 and the C library's
`pow` elsewhere; the two differ in the last bit, so a mesh made with `**` on one machine
was not the mesh made on another, and a long untangling run from it ended elsewhere. The
C library's `pow`, element by element, gives the values NumPy gives on CPUs without AVX-512
everywhere (squares and square roots are exact in NumPy already).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["power"]

_pow = np.frompyfunc(math.pow, 2, 1)


def power(x, p: float) -> np.ndarray:
    """x ** p element by element through the C library's pow; 0 ** (p < 0) is inf, as
    NumPy gives it."""
    x = np.asarray(x, dtype=np.float64)
    if p >= 0:
        return np.asarray(_pow(x, float(p)), dtype=np.float64)
    out = np.full(x.shape, np.inf)  # math.pow(0, p < 0) raises
    nz = x != 0.0
    out[nz] = _pow(x[nz], float(p))
    return out
