"""Test meshes: our OBJ copies in tests/data and the paper's Table 1 mesh read from ../shared."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.faces import FaceSet
from core.obj_io import read_legacy_vtk, read_obj

DATA = Path(__file__).resolve().parents[1] / "data"
SHARED_MESQUITE = (
    Path(__file__).resolve().parents[3]
    / "shared"
    / "meshes"
    / "mesquite"
    / "hole_in_square_tanglap.vtk"
)


def load(name: str) -> tuple[np.ndarray, FaceSet]:
    """(N, 3) points and faces of tests/data/NAME.obj."""
    return read_obj(DATA / f"{name}.obj")


def load2d(name: str) -> tuple[np.ndarray, FaceSet]:
    v, f = load(name)
    return v[:, :2].copy(), f


def mesquite_table1() -> tuple[np.ndarray, np.ndarray]:
    """The paper's Table 1 mesh (third-party, read in place), quads made counterclockwise."""
    if not SHARED_MESQUITE.exists():
        pytest.skip(f"third-party Table 1 mesh not present at {SHARED_MESQUITE} (../shared absent)")
    pts, cells = read_legacy_vtk(SHARED_MESQUITE)
    assert set(np.diff(cells.offsets).tolist()) == {4}  # quads only
    quads = cells.reversed().indices.reshape(-1, 4)
    return pts[:, :2].copy(), quads


def three_quads_around_a_triangle(collapsed: bool = True) -> tuple[np.ndarray, list, np.ndarray]:
    """(points, faces, outer): a triangle with a unit square on each of its sides (nine
    nodes, every one of them on the boundary). The six outer square corners are the nodes a
    Mesquite-style fixed flag pins; with `collapsed` the triangle's three nodes all start at
    its centroid (a fully collapsed triangle, its squares folded)."""
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3.0) / 2]])
    pts = [*tri]
    faces: list[list[int]] = [[0, 1, 2]]
    for k in range(3):
        u, v = k, (k + 1) % 3
        d = tri[v] - tri[u]
        out = np.array([d[1], -d[0]])  # outward for a counterclockwise triangle
        pts += [tri[u] + out, tri[v] + out]
        faces.append([u, 3 + 2 * k, 4 + 2 * k, v])
    p = np.array(pts)
    if collapsed:
        p[:3] = tri.mean(axis=0)
    outer = np.zeros(len(p), dtype=bool)
    outer[3:] = True
    return p, faces, outer


def mesquite_fixed_flags() -> np.ndarray:
    """The `fixed` point scalar of the Table 1 mesh (1 = fixed), read in place."""
    if not SHARED_MESQUITE.exists():
        pytest.skip(f"third-party Table 1 mesh not present at {SHARED_MESQUITE}")
    tokens = SHARED_MESQUITE.read_text().split()
    i = tokens.index("fixed")
    n = int(tokens[tokens.index("POINT_DATA") + 1])
    start = i + 2 + (tokens[i + 2] == "LOOKUP_TABLE") * 2  # "fixed TYPE [LOOKUP_TABLE default]"
    return np.array(tokens[start : start + n], dtype=float) != 0.0
