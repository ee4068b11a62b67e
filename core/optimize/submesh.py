"""The active sub-mesh: the elements within a few rings of some seed elements, with local
node numbers, for optimising only where it is needed."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..mesh.csr import bincount_csr, ragged_arange
from .mesh_tables import Factors

__all__ = ["Neighbourhood", "active_submesh"]

DISTINCT_SORT = 16  # `_distinct` sorts fewer than n / this ids, marks more

SubMesh = tuple[dict[int, np.ndarray], np.ndarray, np.ndarray, "Factors | None"]


class Neighbourhood:
    """Node -> element incidence of a mesh, built once, so that each sub-mesh costs only its
    own size (a lift round or a local untangle on a large mesh touches a few thousand of a
    million elements)."""

    def __init__(self, groups: Mapping[int, np.ndarray], free: np.ndarray,
                 factors: Factors | None = None):
        self.arities = [n for n in sorted(groups) if np.asarray(groups[n]).size]
        self.faces = [np.asarray(groups[n], dtype=np.int64).reshape(-1, int(n))
                      for n in self.arities]
        self.free, self.factors = free, factors
        self._loc: np.ndarray | None = None  # `_local`'s buffer
        sizes = [f.shape[0] for f in self.faces]
        self.first = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.n_elem = int(self.first[-1])
        if len(self.faces) == 1:  # one arity: corner c is in element c // n (no copies)
            self.node_ptr, order = bincount_csr(self.faces[0].ravel(), free.shape[0])
            self.node_elem = order // self.faces[0].shape[1]
            return
        corner = np.concatenate([f.ravel() for f in self.faces]) if self.faces else \
            np.zeros(0, dtype=np.int64)
        elem = np.concatenate([
            b + np.repeat(np.arange(f.shape[0], dtype=np.int64), f.shape[1])
            for f, b in zip(self.faces, self.first[:-1], strict=True)
        ]) if self.faces else np.zeros(0, dtype=np.int64)
        self.node_ptr, order = bincount_csr(corner, free.shape[0])
        self.node_elem = elem[order]

    def _elements_of(self, nodes: np.ndarray) -> np.ndarray:
        """The distinct elements (ascending) that contain one of `nodes`."""
        lo = self.node_ptr[nodes]
        return _distinct(self.node_elem[ragged_arange(lo, self.node_ptr[nodes + 1] - lo)],
                         self.n_elem)

    def _nodes_of(self, elems: np.ndarray) -> np.ndarray:
        """The distinct nodes (ascending) of `elems` (ascending element ids)."""
        parts = []
        for k, f in enumerate(self.faces):
            lo, hi = np.searchsorted(elems, self.first[k : k + 2])
            if hi > lo:
                parts.append(f[elems[lo:hi] - self.first[k]].ravel())
        if not parts:
            return np.zeros(0, dtype=np.int64)
        return _distinct(np.concatenate(parts) if len(parts) > 1 else parts[0],
                         self.free.shape[0])

    def _local(self, nodes: np.ndarray) -> np.ndarray:
        """A map from mesh node ids to positions in `nodes`, valid at `nodes` only (one
        buffer of the mesh's size, reused: a gather instead of a search per lookup)."""
        if self._loc is None:
            self._loc = np.empty(self.free.shape[0], dtype=np.int64)
        self._loc[nodes] = np.arange(nodes.size)
        return self._loc

    def submesh(self, seed: np.ndarray, rings: int) -> tuple[SubMesh, np.ndarray]:
        """`active_submesh` of these groups, and the sub-mesh's element ids (in the order of
        its elements: arities sorted, then the mesh's order)."""
        seed_ids = np.flatnonzero(seed) if seed.dtype == bool else np.asarray(seed, np.int64)
        near = self._nodes_of(np.unique(seed_ids))
        for _ in range(rings):
            near = self._nodes_of(self._elements_of(near))
        move_nodes = near[self.free[near]]
        elems = self._elements_of(move_nodes)
        nodes = self._nodes_of(elems)
        loc = self._local(nodes)
        out, sub_factors = {}, None
        for k, (n, f) in enumerate(zip(self.arities, self.faces, strict=True)):
            lo, hi = np.searchsorted(elems, self.first[k : k + 2])
            if hi <= lo:
                continue
            rows = elems[lo:hi] - self.first[k]
            out[n] = loc[f[rows]]
            if self.factors is not None:
                sub_factors = sub_factors or {}
                sub_factors[n] = tuple(np.asarray(u).reshape(-1, n)[rows] for u in self.factors[n])
        move = np.zeros(nodes.size, dtype=bool)
        move[loc[move_nodes]] = True
        return (out, nodes, move, sub_factors), elems


def _distinct(ids: np.ndarray, n: int) -> np.ndarray:
    """np.unique(ids) for ids in [0, n): a sort for a few ids, a mark over all n for many
    (a pass over n costs about as much as sorting n / 16 ids)."""
    if ids.size * DISTINCT_SORT < n:
        return np.unique(ids)
    mark = np.zeros(n, dtype=bool)
    mark[ids] = True
    return np.flatnonzero(mark)


def active_submesh(
    groups: Mapping[int, np.ndarray], free: np.ndarray, seed: np.ndarray, rings: int,
    factors: Factors | None = None,
) -> SubMesh:
    """The elements that touch a free node within `rings` rings of the seed elements.

    seed: (E,) bool over the elements in `mesh_tables` order (arities sorted). Returns the
    sub-mesh's groups with local node numbers, the global id of each local node, the local
    free mask (the free nodes within reach; the rest of the sub-mesh is fixed), and the
    sub-mesh's rows of the target `factors` (None without). Several sub-meshes of one mesh:
    build a `Neighbourhood` once.
    """
    return Neighbourhood(groups, free, factors).submesh(seed, rings)[0]
