"""The active sub-mesh: the elements within a few rings of some seed elements, with local
node numbers, for optimising only where it is needed."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .reference import Factors

__all__ = ["active_submesh"]


def active_submesh(
    groups: Mapping[int, np.ndarray], free: np.ndarray, seed: np.ndarray, rings: int,
    factors: Factors | None = None,
) -> tuple[dict[int, np.ndarray], np.ndarray, np.ndarray, Factors | None]:
    """The elements that touch a free node within `rings` rings of the seed elements.

    seed: (E,) bool over the elements in `mesh_tables` order (arities sorted). Returns the
    sub-mesh's groups with local node numbers, the global id of each local node, the local
    free mask (the free nodes within reach; the rest of the sub-mesh is fixed), and the
    sub-mesh's rows of the target `factors` (None without).
    """
    arities = [n for n in sorted(groups) if np.asarray(groups[n]).size]
    faces = [np.asarray(groups[n], dtype=np.int64).reshape(-1, int(n)) for n in arities]
    near = np.zeros(free.shape[0], dtype=bool)
    base = 0
    for f in faces:
        near[f[seed[base : base + f.shape[0]]]] = True
        base += f.shape[0]
    for _ in range(rings):
        grow = near.copy()
        for f in faces:
            grow[f[near[f].any(axis=1)]] = True
        near = grow
    move = near & free
    rows = [move[f].any(axis=1) for f in faces]
    sub = [f[r] for f, r in zip(faces, rows, strict=True)]
    nodes = np.unique(np.concatenate([f.ravel() for f in sub])) if sub else np.zeros(0, int)
    local = np.full(free.shape[0], -1, dtype=np.int64)
    local[nodes] = np.arange(nodes.size)
    out = {f.shape[1]: local[f] for f in sub if f.shape[0]}
    sub_factors = None
    if factors is not None:
        sub_factors = {
            n: tuple(np.asarray(u).reshape(-1, n)[r] for u in factors[n])
            for n, r in zip(arities, rows, strict=True) if r.any()
        }
    return out, nodes, move[nodes], sub_factors
