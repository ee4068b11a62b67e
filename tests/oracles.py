"""The tests' oracles: which edges, nodes and loops of a polygon mesh are on its boundary,
computed here from the faces alone, and which faces are inverted (NumPy and Python only).

It deliberately imports nothing of the project (not core.mesh.topology, not core.eegt.boundary)
so the tests check the extension's boundary handling against a second implementation. It runs
in any Python 3.11+ with NumPy 1 or 2: pytest's (tests/conftest.py puts tests/ on ``sys.path``)
and Blender's own in the e2e tests (tests/e2e/meshcheck.py adds tests/ itself).

A boundary edge is an edge used by exactly one face (an edge of three or more faces is not);
its direction is the one that face walks it, so for counterclockwise faces a boundary loop
has the mesh's interior on its left.

``faces`` may be any of: an iterable of faces (each a sequence of node indices), a (F, k)
array of k-gons, a dict of such arrays (arity -> array, the global stage's format), or a
face set with CSR ``offsets`` and ``indices`` arrays (read as plain arrays, nothing else).
"""

from __future__ import annotations

import numpy as np


def _faces(faces) -> list[np.ndarray]:
    """The faces as a list of 1D integer arrays, in the order given."""
    if hasattr(faces, "offsets") and hasattr(faces, "indices"):
        off = np.asarray(faces.offsets)
        idx = np.asarray(faces.indices)
        return [idx[a:b] for a, b in zip(off[:-1].tolist(), off[1:].tolist())]
    if isinstance(faces, dict):
        return [f for g in faces.values() for f in _faces(g)]
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        return list(faces.astype(np.int64))
    return [np.asarray(f, dtype=np.int64).ravel() for f in faces]


def boundary_edges(faces) -> tuple[np.ndarray, np.ndarray]:
    """(a, b): the boundary edges a[i] -> b[i] as their one face walks them, in face order."""
    fs = _faces(faces)
    if not fs:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    a = np.concatenate(fs).astype(np.int64)
    b = np.concatenate([np.roll(f, -1) for f in fs]).astype(np.int64)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * (int(hi.max(initial=0)) + 1) + hi
    _, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    lone = cnt[inv.ravel()] == 1
    return a[lone], b[lone]


def boundary_mask(faces, n_nodes: int | None = None) -> np.ndarray:
    """(n_nodes,) bool: the nodes of a boundary edge (n_nodes: the largest index + 1 when
    not given)."""
    a, b = boundary_edges(faces)
    if n_nodes is None:
        fs = _faces(faces)
        n_nodes = int(max((int(f.max()) for f in fs if f.size), default=-1)) + 1
    mask = np.zeros(n_nodes, dtype=bool)
    mask[a] = True
    mask[b] = True
    return mask


def boundary_nodes(faces) -> list[int]:
    """The nodes of a boundary edge, ascending."""
    return np.flatnonzero(boundary_mask(faces)).tolist()


def boundary_loops(faces) -> list[np.ndarray]:
    """The closed boundary loops, each an array of nodes in walking order (interior on the
    left for counterclockwise faces), a loop per boundary component, first met first."""
    a, b = boundary_edges(faces)
    nxt = dict(zip(a.tolist(), b.tolist()))
    seen, loops = set(), []
    for s in nxt:
        if s in seen:
            continue
        loop, v = [], s
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt[v]
        loops.append(np.array(loop))
    return loops


def inverted_faces(points: np.ndarray, faces) -> np.ndarray:
    """(F,) bool, counted face by face: a face with a corner whose cross product of its
    edges (to the next and to the previous node) is not positive."""
    rings = _faces(faces)
    out = np.zeros(len(rings), dtype=bool)
    for f, nodes in enumerate(rings):
        ring = np.asarray(points, dtype=np.float64)[nodes, :2]
        e_next, e_prev = np.roll(ring, -1, axis=0) - ring, np.roll(ring, 1, axis=0) - ring
        out[f] = bool(np.any(e_next[:, 0] * e_prev[:, 1] - e_next[:, 1] * e_prev[:, 0] <= 0.0))
    return out
