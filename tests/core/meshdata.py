"""Test meshes: our OBJ copies in tests/data and the paper's Table 1 mesh read from ../shared."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.faces import FaceSet
from core.obj_io import read_obj

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


def read_vtk_quads(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) and cells (F, 4) of a legacy ASCII VTK unstructured grid of quads."""
    tokens = path.read_text().split()
    i = tokens.index("POINTS")
    n = int(tokens[i + 1])
    pts = np.array(tokens[i + 3 : i + 3 + 3 * n], dtype=float).reshape(n, 3)
    j = tokens.index("CELLS")
    m = int(tokens[j + 1])
    raw = np.array(tokens[j + 3 : j + 3 + int(tokens[j + 2])], dtype=np.int64).reshape(m, 5)
    assert (raw[:, 0] == 4).all()
    return pts, raw[:, 1:]


def mesquite_table1() -> tuple[np.ndarray, np.ndarray]:
    """The paper's Table 1 mesh (third-party, read in place), quads made counterclockwise."""
    if not SHARED_MESQUITE.exists():
        pytest.skip(f"third-party Table 1 mesh not present at {SHARED_MESQUITE} (../shared absent)")
    pts, quads = read_vtk_quads(SHARED_MESQUITE)
    return pts[:, :2].copy(), quads[:, ::-1].copy()
