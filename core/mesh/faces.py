"""Polygon faces grouped by arity: the one mesh-connectivity model the core works on.

Any face list (Python lists, an (F, k) array, or Blender-style CSR arrays) becomes a
`FaceSet`: one `ArityGroup` per polygon size, each holding its node indices as an (n, F_n)
array (structure of arrays, so corner k of every face is one contiguous row) and the
original face numbers, so per-face results can be returned in the caller's order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .csr import ragged_arange

__all__ = ["ArityGroup", "FaceSet", "as_faceset", "corner_rows", "face_subset", "faces_from_csr",
           "next_corner"]


@dataclass(frozen=True)
class ArityGroup:
    """All faces with `n` corners: `nodes[k, j]` is corner k of face `ids[j]`."""

    n: int
    ids: np.ndarray  # (F_n,) original face numbers
    nodes: np.ndarray  # (n, F_n) node indices, counterclockwise = valid

    @property
    def size(self) -> int:
        return int(self.ids.size)


class FaceSet:
    """Validated polygon faces over `n_nodes` nodes, grouped by arity (ascending)."""

    def __init__(self, offsets: np.ndarray, indices: np.ndarray, n_nodes: int | None = None):
        offsets = np.asarray(offsets, dtype=np.int64)
        indices = np.asarray(indices, dtype=np.int64)
        if offsets.ndim != 1 or offsets.size < 1 or offsets[0] != 0:
            raise ValueError("face offsets must be a 1D array starting at 0")
        counts = np.diff(offsets)
        if counts.size == 0:
            raise ValueError("mesh has no faces")
        if indices.ndim != 1 or offsets[-1] != indices.size:
            raise ValueError("face offsets do not match the number of face corners")
        small = np.flatnonzero(counts < 3)
        if small.size:
            f = int(small[0])
            raise ValueError(f"face {f} has {int(counts[f])} vertices (at least 3 are needed)")
        self.n_faces = int(counts.size)
        self.offsets = offsets
        self.indices = indices
        self.counts = counts
        groups = []
        arities = np.unique(counts)
        for n in arities:
            if arities.size == 1:  # one arity: corner k of every face is a strided row
                ids = np.arange(counts.size)
                nodes = np.ascontiguousarray(indices.reshape(-1, int(n)).T)
            else:
                ids = np.flatnonzero(counts == n)
                nodes = np.ascontiguousarray(indices[offsets[ids][None, :] + np.arange(n)[:, None]])
            groups.append(ArityGroup(int(n), ids, nodes))
        self.groups: tuple[ArityGroup, ...] = tuple(groups)
        self._valid_from: int | None = None  # smallest node count a check has passed for
        if n_nodes is not None:
            self.check(n_nodes)

    def check(self, n_nodes: int) -> None:
        """Raise ValueError for an index outside [0, n_nodes) or a face repeating a node.
        Checked once: every stage checks the faces it is given, and they do not change."""
        if self._valid_from is not None and n_nodes >= self._valid_from:
            return
        if self.indices.size and (self.indices.min() < 0 or self.indices.max() >= n_nodes):
            bad = np.flatnonzero((self.indices < 0) | (self.indices >= n_nodes))[0]
            face = int(np.searchsorted(self.offsets, bad, side="right") - 1)
            raise ValueError(
                f"face {face} references node {int(self.indices[bad])}, "
                f"but there are only {n_nodes} nodes"
            )
        for g in self.groups:
            if g.n <= 4:  # every pair of corners: cheaper than a sorted copy
                same = np.zeros(g.size, dtype=bool)
                for i in range(g.n):
                    for k in range(i + 1, g.n):
                        same |= g.nodes[i] == g.nodes[k]
            else:
                srt = np.sort(g.nodes, axis=0)
                same = (srt[1:] == srt[:-1]).any(axis=0)
            dup = np.flatnonzero(same)
            if dup.size:
                j = int(dup[0])
                col = np.sort(g.nodes[:, j])
                node = int(col[1:][col[1:] == col[:-1]][0])
                raise ValueError(f"face {int(g.ids[j])} repeats node {node}")
        self._valid_from = int(self.indices.max()) + 1 if self.indices.size else 0

    @property
    def n_corners(self) -> int:
        return int(self.indices.size)

    def used_nodes(self, n_nodes: int) -> np.ndarray:
        """(n_nodes,) bool: nodes that belong to at least one face."""
        used = np.zeros(n_nodes, dtype=bool)
        used[self.indices] = True
        return used

    def reversed(self) -> FaceSet:
        """The same faces with every corner order reversed (clockwise <-> counterclockwise)."""
        starts = np.repeat(self.offsets[:-1], self.counts)
        ends = np.repeat(self.offsets[1:], self.counts)
        pos = np.arange(self.indices.size)
        return FaceSet(self.offsets, self.indices[starts + ends - 1 - pos])

    def by_arity(self) -> dict[int, np.ndarray]:
        """arity -> (F_n, n) node array, a face per row: the global stage's mesh format."""
        return {g.n: np.ascontiguousarray(g.nodes.T) for g in self.groups}

    def arity_order(self) -> np.ndarray:
        """(F,) the face id of each element in `by_arity`'s order (the arity groups in turn,
        each group's faces in order): the global stage's element -> face map."""
        return np.concatenate([g.ids for g in self.groups])

    def to_lists(self) -> list[list[int]]:
        return [self.indices[a:b].tolist() for a, b in zip(self.offsets[:-1], self.offsets[1:])]


def faces_from_csr(loop_start, loop_total, corner_verts, n_nodes: int | None = None) -> FaceSet:
    """Faces from Blender-style arrays: face i uses corner_verts[loop_start[i]:+loop_total[i]]."""
    loop_start = np.asarray(loop_start, dtype=np.int64)
    loop_total = np.asarray(loop_total, dtype=np.int64)
    corner_verts = np.asarray(corner_verts, dtype=np.int64)
    if loop_start.shape != loop_total.shape or loop_start.ndim != 1:
        raise ValueError("loop_start and loop_total must be 1D arrays of the same length")
    offsets = np.concatenate([[0], np.cumsum(loop_total)])
    if loop_start.size and np.array_equal(loop_start, offsets[:-1]):
        indices = corner_verts[: offsets[-1]]
    else:  # faces not stored in corner order: gather them
        indices = corner_verts[ragged_arange(loop_start, loop_total)]
    return FaceSet(offsets, indices, n_nodes)


def _integer_indices(flat: np.ndarray) -> np.ndarray:
    """int64 copy of whole-number indices given as floats; ValueError for anything else
    (strings, None, booleans, fractions, NaN)."""
    if flat.dtype.kind in "US":
        raise ValueError("face indices must be integers, got strings")
    if flat.dtype.kind != "f":
        bad = next((v for v in flat.tolist() if not isinstance(v, int) or isinstance(v, bool)),
                   flat[0])
        raise ValueError(f"face indices must be integers, got {bad!r}")
    whole = np.isfinite(flat) & (flat == np.round(flat))
    if not whole.all():
        # .item(): the Python number, shown alike under NumPy 1 and 2 (no "np.float64(...)")
        raise ValueError(f"face indices must be integers, got {flat[~whole][0].item()!r}")
    return flat.astype(np.int64)


def as_faceset(faces, n_nodes: int) -> FaceSet:
    """Accept a FaceSet, an (F, k) integer array or a sequence of index sequences."""
    if isinstance(faces, FaceSet):
        faces.check(n_nodes)
        return faces
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        if faces.size and not np.issubdtype(faces.dtype, np.integer):
            faces = _integer_indices(faces.reshape(-1)).reshape(faces.shape)
        f, k = faces.shape
        if f == 0:
            raise ValueError("mesh has no faces")
        return FaceSet(np.arange(f + 1, dtype=np.int64) * k, faces.reshape(-1), n_nodes)
    if not isinstance(faces, Sequence | np.ndarray):
        raise ValueError("faces must be a sequence of vertex-index sequences")
    if len(faces) == 0:
        raise ValueError("mesh has no faces")
    try:
        counts = np.fromiter((len(f) for f in faces), dtype=np.int64, count=len(faces))
        flat = np.concatenate([np.asarray(f).reshape(-1) for f in faces])
    except (TypeError, ValueError):
        raise ValueError("faces must be a sequence of vertex-index sequences") from None
    if flat.size and not np.issubdtype(flat.dtype, np.integer):
        flat = _integer_indices(flat)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    return FaceSet(offsets, flat, n_nodes)


def face_subset(fs: FaceSet, face_ids: np.ndarray) -> tuple[FaceSet, np.ndarray, np.ndarray]:
    """The faces ``face_ids`` (in that order) as a FaceSet over their own nodes: (faces,
    global node of each local node, row of each local corner in ``fs``'s corner order)."""
    face_ids = np.asarray(face_ids, dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(fs.counts[face_ids])])
    rows = corner_rows(fs, face_ids)
    nodes, local = np.unique(fs.indices[rows], return_inverse=True)
    return FaceSet(offsets, local.reshape(-1)), nodes, rows


def corner_rows(fs: FaceSet, face_ids: np.ndarray) -> np.ndarray:
    """The corner rows of the faces ``face_ids`` in ``fs``'s corner order, face after face
    (in that order), without a pass over every corner."""
    face_ids = np.asarray(face_ids, dtype=np.int64)
    counts = fs.counts[face_ids]
    before = np.cumsum(counts) - counts  # corners of the faces listed before each
    return np.repeat(fs.offsets[face_ids] - before, counts) + np.arange(int(counts.sum()))


def next_corner(fs: FaceSet) -> np.ndarray:
    """(C,) row of the next corner of the same face, for every corner row of ``fs``."""
    nxt = np.arange(1, fs.n_corners + 1, dtype=np.int64)
    nxt[fs.offsets[1:] - 1] = fs.offsets[:-1]
    return nxt
