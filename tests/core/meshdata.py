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
