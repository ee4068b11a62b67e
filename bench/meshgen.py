"""Generated tangled triangle meshes of any size, for benchmarks (deterministic)."""

from __future__ import annotations

import numpy as np

from core.faces import FaceSet

__all__ = ["jittered_square"]


def jittered_square(
    n_triangles: int, jitter: float = 0.45, seed: int = 0
) -> tuple[np.ndarray, FaceSet]:
    """Unit square split into m x m quads, each cut into 2 triangles (about `n_triangles`);
    interior nodes moved by uniform noise of `jitter` cell sizes, which inverts some faces."""
    m = max(2, round(np.sqrt(n_triangles / 2)))
    h = 1.0 / m
    ys, xs = np.mgrid[0 : m + 1, 0 : m + 1]
    pts = np.column_stack([xs.ravel() * h, ys.ravel() * h]).astype(np.float64)
    interior = ((xs > 0) & (xs < m) & (ys > 0) & (ys < m)).ravel()
    rng = np.random.default_rng(seed)
    pts[interior] += rng.uniform(-jitter * h, jitter * h, (int(interior.sum()), 2))
    i, j = np.mgrid[0:m, 0:m]
    a = (i * (m + 1) + j).ravel()
    b, c, d = a + 1, a + m + 2, a + m + 1
    tris = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    return pts, FaceSet(np.arange(tris.shape[0] + 1) * 3, tris.ravel())
