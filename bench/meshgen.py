"""Generated tangled triangle meshes of any size, for benchmarks (deterministic)."""

from __future__ import annotations

import numpy as np

from bench import libm
from core.mesh.faces import FaceSet

__all__ = ["jittered_square"]


def jittered_square(
    n_triangles: int, jitter: float = 0.45, seed: int = 0
) -> tuple[np.ndarray, FaceSet]:
    """Unit square split into m x m quads, each cut into 2 triangles (about `n_triangles`);
    interior nodes moved by uniform noise of `jitter` cell sizes, which inverts some faces."""
    m = max(2, round(np.sqrt(n_triangles / 2)))
    h = 1.0 / m
    ys, xs = np.mgrid[0 : m + 1, 0 : m + 1]
    pts = np.column_stack([xs.ravel() * h, ys.ravel() * h]).astype(np.float64)
    interior = ((xs > 0) & (xs < m) & (ys > 0) & (ys < m)).ravel()
    rng = np.random.default_rng(seed)
    pts[interior] += rng.uniform(-jitter * h, jitter * h, (int(interior.sum()), 2))
    i, j = np.mgrid[0:m, 0:m]
    a = (i * (m + 1) + j).ravel()
    b, c, d = a + 1, a + m + 2, a + m + 1
    tris = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    return pts, FaceSet(np.arange(tris.shape[0] + 1) * 3, tris.ravel())


HOLES = ((0.3, 0.3, 0.12), (0.7, 0.35, 0.1), (0.45, 0.72, 0.11))  # (x, y, radius)


def holed_square(
    n_triangles: int, jitter: float = 0.525, seed: int = 0, shake: float = 0.25
) -> tuple[np.ndarray, FaceSet]:
    """Unit square with three round holes, an unstructured Delaunay mesh of about
    `n_triangles` triangles (nodes: the sides and hole circles sampled at the edge length h,
    inside a triangular lattice moved by up to `shake` h, triangulated by matplotlib's qhull);
    then interior nodes moved by uniform noise of `jitter` h (0.525 inverts about 5 % of the
    triangles). With `shake` 0.25 interior nodes have degree 4 to 8 as a mesher's output
    would; from about 0.3 on, Delaunay makes nodes of degree 3, whose three triangles cap the
    reachable q_min near 0.60."""
    from matplotlib.tri import Triangulation

    rng = np.random.default_rng(seed)
    area = 1.0 - sum(np.pi * r * r for _, _, r in HOLES)
    h = float(np.sqrt(4.0 * area / (np.sqrt(3.0) * max(n_triangles, 8))))
    k = max(4, round(1.0 / h))
    t = np.arange(k) / k
    sides = [np.column_stack([t, 0 * t]), np.column_stack([1 + 0 * t, t]),
             np.column_stack([1 - t, 1 + 0 * t]), np.column_stack([0 * t, 1 - t])]
    circles = []
    for hx, hy, r in HOLES:
        a = np.arange(max(8, round(2 * np.pi * r / h))) * (2 * np.pi / max(8, round(2 * np.pi * r / h)))
        circles.append(np.column_stack([hx + r * np.cos(a), hy + r * np.sin(a)]))
    rows = round(1.0 / (h * np.sqrt(3.0) / 2.0))
    i, j = np.mgrid[1:rows, 0 : k + 1]
    lat = np.column_stack([((j + 0.5 * (i % 2)) / k).ravel(), (i / rows).ravel()])
    lat += rng.uniform(-shake * h, shake * h, lat.shape)
    inside = np.all((lat > 0.5 * h) & (lat < 1 - 0.5 * h), axis=1)
    for hx, hy, r in HOLES:
        inside &= np.hypot(lat[:, 0] - hx, lat[:, 1] - hy) > r + 0.5 * h
    n_fixed = sum(len(b) for b in sides + circles)
    pts = np.concatenate([*sides, *circles, lat[inside]])
    tris = Triangulation(pts[:, 0], pts[:, 1]).triangles.astype(np.int64)
    cen = pts[tris].mean(axis=1)
    keep = np.ones(tris.shape[0], dtype=bool)
    for hx, hy, r in HOLES:
        keep &= np.hypot(cen[:, 0] - hx, cen[:, 1] - hy) > r
    tris = tris[keep]
    x, y = pts[tris, 0], pts[tris, 1]  # counterclockwise
    cw = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (y[:, 1] - y[:, 0]) * (x[:, 2] - x[:, 0]) < 0
    tris[cw] = tris[cw][:, ::-1]
    pts[n_fixed:] += rng.uniform(-jitter * h, jitter * h, (pts.shape[0] - n_fixed, 2))
    return pts, FaceSet(np.arange(tris.shape[0] + 1) * 3, tris.ravel())


def holed_quads(n_quads: int, jitter: float = 0.455, seed: int = 0) -> tuple[np.ndarray, FaceSet]:
    """Unit square with the three round holes of `holed_square`, a grid of about `n_quads`
    square cells (those whose centre is in a hole removed), interior nodes moved by uniform
    noise of `jitter` cell sizes (0.455 inverts about 5 % of the quads)."""
    area = 1.0 - sum(np.pi * r * r for _, _, r in HOLES)
    m = max(4, round(np.sqrt(max(n_quads, 16) / area)))
    h = 1.0 / m
    ys, xs = np.mgrid[0 : m + 1, 0 : m + 1]
    pts = np.column_stack([xs.ravel() * h, ys.ravel() * h]).astype(np.float64)
    i, j = np.mgrid[0:m, 0:m]
    a = (i * (m + 1) + j).ravel()
    quads = np.column_stack([a, a + 1, a + m + 2, a + m + 1])
    cx, cy = (j.ravel() + 0.5) * h, (i.ravel() + 0.5) * h
    keep = np.ones(quads.shape[0], dtype=bool)
    for hx, hy, r in HOLES:
        keep &= np.hypot(cx - hx, cy - hy) > r
    quads = quads[keep]
    used = np.zeros(pts.shape[0], dtype=bool)
    used[quads] = True
    edges = np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1)
    key, count = np.unique(edges[:, 0] * pts.shape[0] + edges[:, 1], return_counts=True)
    border = np.zeros(pts.shape[0], dtype=bool)
    lo, hi = np.divmod(key[count == 1], pts.shape[0])
    border[lo] = border[hi] = True
    inner = used & ~border
    rng = np.random.default_rng(seed)
    pts[inner] += rng.uniform(-jitter * h, jitter * h, (int(inner.sum()), 2))
    new = np.cumsum(used) - 1
    quads = new[quads]
    return pts[used], FaceSet(np.arange(quads.shape[0] + 1) * 4, quads.ravel())


def boundary_layer_annulus(
    n_around: int = 40, first: float = 0.0015, growth: float = 1.2, outer: float = 20.0
) -> tuple[np.ndarray, FaceSet]:
    """An O-grid of quads around a unit circle (a round body): `n_around` cells around, rows
    of geometrically growing height from `first` (a boundary layer of thin cells, aspect
    about 2 pi / n_around / first at the wall) until the radius reaches `outer` (the last row
    ends exactly there). A graded, anisotropic solver mesh: with the defaults 1720 nodes,
    1680 quads, cell sizes (square roots of the areas) 1:257, aspect ratios 1 to 105.
    Faces counterclockwise; the body is the hole."""
    radii = [1.0]
    h = first
    while radii[-1] + h < outer:
        radii.append(radii[-1] + h)
        h *= growth
    radii[-1] = outer
    r = np.asarray(radii)
    t = 2.0 * np.pi * np.arange(n_around) / n_around
    pts = np.column_stack([np.outer(r, np.cos(t)).ravel(), np.outer(r, np.sin(t)).ravel()])
    i, j = np.mgrid[0 : r.size - 1, 0:n_around]
    a = (i * n_around + j).ravel()
    b = (i * n_around + (j + 1) % n_around).ravel()
    quads = np.column_stack([a, a + n_around, b + n_around, b])
    return pts, FaceSet(np.arange(quads.shape[0] + 1) * 4, quads.ravel())


def moved_body(
    pts: np.ndarray, shift: tuple[float, float] = (0.9, 0.3), turn_deg: float = 25.0,
    reach: float = 2.5,
) -> np.ndarray:
    """The annulus of `boundary_layer_annulus` after its body moved in one step: the unit
    circle turned by `turn_deg` about its centre and shifted by `shift`; every other node
    follows by a weight 1 at the body fading smoothly to 0 at `reach` radii (outer ring
    fixed). The thin cells where the weight falls fastest fold (like the paper's naca case):
    43 of the default annulus's quads."""
    r = np.hypot(pts[:, 0], pts[:, 1])
    s = np.clip((r - 1.0) / (reach - 1.0), 0.0, 1.0)
    w = libm.power(1.0 - s, 3) * (1.0 + 3.0 * s)  # 1 at the body, 0 (and flat) at `reach`
    a = np.radians(turn_deg)
    c, si = np.cos(a), np.sin(a)
    moved = np.column_stack([c * pts[:, 0] - si * pts[:, 1] + shift[0],
                             si * pts[:, 0] + c * pts[:, 1] + shift[1]])
    return pts + w[:, None] * (moved - pts)
