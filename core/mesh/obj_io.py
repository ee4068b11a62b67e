"""Minimal Wavefront OBJ reading and writing (`v` and `f` lines) for tests, benches, demos."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .faces import FaceSet

__all__ = ["read_legacy_vtk", "read_obj", "write_obj"]


def read_obj(path) -> tuple[np.ndarray, FaceSet]:
    """(N, 3) float64 vertices and the faces (0-based) of an OBJ file."""
    verts: list[list[float]] = []
    counts: list[int] = []
    flat: list[int] = []
    for line in Path(path).read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            verts.append([float(t) for t in parts[1:4]])
        elif parts[0] == "f":
            idx = [int(t.split("/")[0]) for t in parts[1:]]
            n = len(verts)
            flat.extend(i - 1 if i > 0 else n + i for i in idx)
            counts.append(len(idx))
    offsets = np.concatenate([[0], np.cumsum(counts, dtype=np.int64)])
    return np.array(verts, dtype=np.float64).reshape(-1, 3), FaceSet(offsets, np.array(flat))


def read_legacy_vtk(path) -> tuple[np.ndarray, FaceSet]:
    """(N, 3) points and the cells, as stored, of an ASCII legacy VTK unstructured grid
    (e.g. Mesquite's test meshes; their quads are clockwise: use `FaceSet.reversed()`)."""
    tokens = Path(path).read_text().split()
    i = tokens.index("POINTS")
    n = int(tokens[i + 1])
    pts = np.array(tokens[i + 3 : i + 3 + 3 * n], dtype=np.float64).reshape(n, 3)
    j = tokens.index("CELLS")
    m, size = int(tokens[j + 1]), int(tokens[j + 2])
    raw = np.array(tokens[j + 3 : j + 3 + size], dtype=np.int64)
    # each cell: its corner count, then the corners
    if m and size % m == 0 and (raw[:: size // m] == size // m - 1).all():
        starts = np.arange(m, dtype=np.int64) * (size // m)  # one arity: no walk needed
    else:
        starts = np.zeros(m, dtype=np.int64)
        for k in range(1, m):  # mixed arities: a sequential walk of the file, once
            starts[k] = starts[k - 1] + raw[starts[k - 1]] + 1
    counts = raw[starts]
    pos = np.repeat(starts + 1, counts) + np.arange(counts.sum()) - np.repeat(
        np.cumsum(counts) - counts, counts
    )
    return pts, FaceSet(np.concatenate([[0], np.cumsum(counts)]), raw[pos])


def write_obj(path, points, faces: FaceSet) -> None:
    p = np.asarray(points, dtype=np.float64)
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in p]
    lines += ["f " + " ".join(str(i + 1) for i in face) for face in faces.to_lists()]
    Path(path).write_text("\n".join(lines) + "\n")
