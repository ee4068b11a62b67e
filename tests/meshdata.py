"""The tests' one mesh loader: the OBJ meshes of tests/data and the paper's Table 1 mesh,
read in place (third-party, never copied here: docs/testing.md says where it is looked for).

Every test folder imports it as ``meshdata`` (tests/conftest.py puts tests/ on ``sys.path``);
a child Python process started by a test gets it with ``tests`` on its PYTHONPATH. The meshes
are read with the core's own reader (core.mesh.obj_io); nothing is cached, so every call returns
fresh arrays a test may change.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.mesh.faces import FaceSet, as_faceset
from core.mesh.obj_io import read_legacy_vtk, read_obj

ROOT = Path(__file__).resolve().parents[1]  # the repository (= the extension package)
DATA = ROOT / "tests" / "data"
SHARED_MESHES = ROOT.parent / "shared" / "meshes"
SHARED_MESQUITE = SHARED_MESHES / "mesquite" / "hole_in_square_tanglap.vtk"

# the bundled meshes: planar in z = 0 but tilted_plane (a plane in 3D), all tangled but the
# naca_undeformed reference of naca_deform
NAMES = tuple(sorted(f.stem for f in DATA.glob("*.obj")))
PLANAR = ("quad_hole", "tri_two_holes", "naca_deform", "mixed_quad_tri", "polygon_voronoi",
          "two_holes_twist")


def path(name: str) -> Path:
    """tests/data/NAME.obj (FileNotFoundError naming the bundled meshes when absent)."""
    p = DATA / f"{name}.obj"
    if not p.is_file():
        raise FileNotFoundError(f"no test mesh {p} (bundled: {', '.join(NAMES)})")
    return p


def read(obj_path: Path | str) -> tuple[np.ndarray, FaceSet]:
    """(N, 3) float64 points and the faces of any OBJ file (a test's output, say)."""
    return read_obj(obj_path)


def load(name: str) -> tuple[np.ndarray, FaceSet]:
    """(N, 3) float64 points and the faces of tests/data/NAME.obj."""
    return read(path(name))


def load2d(name: str) -> tuple[np.ndarray, FaceSet]:
    """(N, 2) float64 points (x, y; C-contiguous copy) and the faces of tests/data/NAME.obj."""
    v, f = load(name)
    return np.ascontiguousarray(v[:, :2]), f


def load_groups(name: str) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """(N, 2) points and the faces by arity, {n: (F_n, n) nodes}: the global stage's format
    (``FaceSet.by_arity``, each group's faces in file order)."""
    p, f = load2d(name)
    return p, as_faceset(f, len(p)).by_arity()


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


def spun_hole(rings: int, around: int, degrees: float, triangles: bool):
    """An annulus (hole radius 1, outer radius 2) whose hole boundary alone is spun by
    `degrees`: every face of the innermost ring folds, the rest of the mesh is at rest."""
    r = np.linspace(1.0, 2.0, rings + 1)
    t = np.linspace(0.0, 2 * np.pi, around, endpoint=False)
    rr, tt = np.meshgrid(r, t, indexing="ij")
    tt = tt + np.where(rr == 1.0, np.radians(degrees), 0.0)
    pts = np.column_stack([(rr * np.cos(tt)).ravel(), (rr * np.sin(tt)).ravel()])
    i, j = np.meshgrid(np.arange(rings), np.arange(around), indexing="ij")
    a = (i * around + j).ravel()
    b = (i * around + (j + 1) % around).ravel()
    c, d = b + around, a + around
    if triangles:
        return pts, {3: np.concatenate([np.column_stack([a, c, b]), np.column_stack([a, d, c])])}
    return pts, {4: np.column_stack([a, d, c, b])}


def quad_strip(nx: int = 6, ny: int = 3, x0: float = 0.0) -> tuple[np.ndarray, list[list[int]]]:
    """nx x ny unit quads from (x0, 0), counterclockwise; node (i, j) is j (nx + 1) + i."""
    m = nx + 1
    xs, ys = np.meshgrid(np.arange(m, dtype=float) + x0, np.arange(ny + 1, dtype=float))
    p = np.column_stack([xs.ravel(), ys.ravel()])
    return p, [[m * j + i, m * j + i + 1, m * j + i + m + 1, m * j + i + m]
               for j in range(ny) for i in range(nx)]


def spiked_strip(x0: float = 0.0) -> tuple[np.ndarray, list[list[int]]]:
    """The 6 x 3 `quad_strip` with bottom boundary node 3 dragged up through the top
    boundary to (x0 + 3, 4): inside the spike, above the top edge, the boundary winds -1
    times, so no positions of the interior nodes make the faces valid."""
    p, f = quad_strip(x0=x0)
    p[3] = [x0 + 3.0, 4.0]
    return p, f

