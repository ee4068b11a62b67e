"""Synthetic UV maps for the core's UV tests: a quad grid in 3D with Blender-style loops."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class GridUV:
    """An n x n vertex grid of quads (z = 0) with one UV per loop."""

    co: np.ndarray  # (N, 3) vertex positions
    loop_start: np.ndarray
    loop_total: np.ndarray
    corner_verts: np.ndarray
    uv: np.ndarray  # (L, 2) float32
    n: int

    @property
    def n_faces(self) -> int:
        return int(self.loop_start.size)

    def face_centres(self) -> np.ndarray:
        return self.co[self.corner_verts.reshape(-1, 4)].mean(axis=1)[:, :2]

    def loops_of_faces(self, mask: np.ndarray) -> np.ndarray:
        return np.repeat(mask, 4)


def grid_uv(n: int = 8, seam_x: float | None = None, gap: float = 10.0) -> GridUV:
    """UVs = the vertex xy; with ``seam_x`` the faces right of x = seam_x form a second
    island shifted by ``gap`` in u (the seam's vertices get two UVs)."""
    g = np.arange(n, dtype=np.float64)
    x, y = np.meshgrid(g, g)
    co = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    i = (np.arange(n - 1)[None, :] + n * np.arange(n - 1)[:, None]).ravel()
    quads = np.stack([i, i + 1, i + n + 1, i + n], axis=1)
    cv = quads.ravel().astype(np.int64)
    uv = co[cv, :2].astype(np.float32)
    if seam_x is not None:
        right = co[quads[:, 0], 0] >= seam_x
        uv[np.repeat(right, 4), 0] += np.float32(gap)
    ls = np.arange(quads.shape[0], dtype=np.int64) * 4
    return GridUV(co, ls, np.full(quads.shape[0], 4, np.int64), cv, uv, n)


def jitter_interior(uv: np.ndarray, loop_node: np.ndarray, free: np.ndarray, amount: float,
                    seed: int = 0) -> np.ndarray:
    """Move the UV vertices in ``free`` by up to ``amount``: every loop of one UV vertex
    moves together (float32 result)."""
    rng = np.random.default_rng(seed)
    delta = rng.uniform(-amount, amount, (free.size, 2)) * free[:, None]
    return (uv + delta[loop_node]).astype(np.float32)
