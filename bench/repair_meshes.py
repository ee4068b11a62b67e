"""Solver meshes as engineers build them, deformed until they fold: the cases of
bench.repair_bench (docs/repair.md), made reproducibly and cached under build/repair_bench/.

Base meshes (undeformed, valid, graded towards the wall on purpose):

- `ogrid`: a structured O-grid of quads around a cylinder (bench.meshgen's
  boundary_layer_annulus; chord = the diameter 2), first cell 1e-3 to 1e-5 of the chord,
  geometric growth; `ogridtri`: the same grid, each quad cut in two (anisotropic triangles);
- `cgrid`: a structured C-grid of quads around a NACA 0012 (chord 1, closed trailing edge,
  wake cut nodes shared, far field 20 chords away), first cell 1e-5 to 1e-4 of the chord;
  `cgridtri`: the same cut in two;
- `gmshbl`: gmsh 4.15's BoundaryLayer field around a NACA 0012 or a cylinder (quads in the
  layer, Frontal-Delaunay triangles outside: a hybrid mesh), `gmshbltri`: the same field
  with triangles in the layer (anisotropic triangles);
- `public`: SU2's tutorial meshes (su2code/Tutorials) and regression test meshes
  (su2code/TestCases, keys `tc-*`), each at a pinned commit and checked by SHA-256,
  fetched, never generated: from build/public_meshes (scripts/fetch_public_meshes.py) or
  from a bare snapshot of the repository (``--mirror``).

Deformations (what a mesh-deformation tool does when it goes too far): the wall moves
rigidly (`turn`: rotated about a point and shifted; `slide`: a body translated; `flap`: the
aft part of the airfoil rotated about a hinge on its lower surface) and every node follows
with a blend weight that falls smoothly from 1 at the moving wall to 0 at `reach` chords
from it ((1 - s)^3 (1 + 3 s), s = distance / reach, flat at both ends; for a flap also 0 on
the fixed part of the wall). The thin cells where the weight falls fastest fold.

A case: deformed `points`, the undeformed `reference`, `faces`, `fixed` (every boundary
node), `wall` (the moving wall's nodes, where the first layer is measured) and `held_out`
(cases whose deformation was set once and never tuned). Cached as .npz (never committed).
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing as mp
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from bench import libm
from bench.corpus import compact_mesh, naca0012
from bench.meshgen import boundary_layer_annulus
from bench.public_pins import (
    DEFAULT_MIRROR,
    SU2_TESTCASES,
    SU2_TUTORIALS,
    from_snapshot,
    snapshot,
)
from core import FaceSet, faces_from_csr, mesh_stats
from core.mesh.topology import boundary_nodes

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "build" / "repair_bench"
VERSION = 2  # part of every cache name: bump when a generator changes its output
T = TypeVar("T")

__all__ = ["CACHE", "PUBLIC", "Case", "Spec", "load", "make"]


@dataclass(frozen=True)
class Case:
    name: str
    family: str
    points: np.ndarray  # (N, 2) deformed
    reference: np.ndarray  # (N, 2) undeformed
    faces: FaceSet
    fixed: np.ndarray  # (N,) bool: boundary nodes (never moved)
    wall: np.ndarray  # (N,) bool: the moving wall (first-layer heights are measured there)
    held_out: bool = False

    @property
    def n_faces(self) -> int:
        return self.faces.n_faces


@dataclass(frozen=True)
class Spec:
    """A case: base mesh `mesh` with its `size` (about this many cells; public: the file's
    key), deformation `motion` with its `params`, `held_out`."""

    mesh: str
    size: int | str
    motion: str
    params: dict = field(default_factory=dict)
    held_out: bool = False

    @property
    def name(self) -> str:
        extra = ",".join(f"{k}{v}" for k, v in sorted(self.params.items()))
        return f"{self.mesh}-{self.size}-{self.motion}" + (f"({extra})" if extra else "")

    @property
    def path(self) -> Path:
        digest = hashlib.sha256(self.name.encode()).hexdigest()[:12]
        return CACHE / f"v{VERSION}_{self.mesh}_{self.size}_{digest}.npz"


# ------------------------------------------------------------------------------ helpers


def _faceset(rows: list[np.ndarray], n: int) -> FaceSet:
    sizes = np.concatenate([np.full(r.shape[0], r.shape[1]) for r in rows])
    flat = np.concatenate([r.ravel() for r in rows]).astype(np.int64)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    return faces_from_csr(starts, sizes, flat, n)


def _split(quads: np.ndarray) -> np.ndarray:
    """Each quad cut in two along alternating diagonals (no preferred direction)."""
    alt = (np.arange(quads.shape[0]) % 2).astype(bool)
    a = np.where(alt[:, None], quads[:, [0, 1, 2]], quads[:, [0, 1, 3]])
    b = np.where(alt[:, None], quads[:, [0, 2, 3]], quads[:, [1, 2, 3]])
    return np.concatenate([a, b])


def _quads_of(fs: FaceSet) -> np.ndarray:
    return next(g.nodes.T for g in fs.groups if g.n == 4)


def min_dist(x: np.ndarray, targets: np.ndarray, cap: float = np.inf) -> np.ndarray:
    """(N,) distance from each x to the nearest of `targets` (chunked brute force), `cap`
    for the points farther than `cap` from the targets' bounding box (not searched)."""
    t = np.asarray(targets, dtype=np.float64)
    lo, hi = t.min(axis=0) - cap, t.max(axis=0) + cap
    out = np.full(x.shape[0], cap)
    near = np.flatnonzero(np.all((x >= lo) & (x <= hi), axis=1))
    step = max(1, 4_000_000 // max(1, t.shape[0]))
    for i in range(0, near.size, step):
        rows = near[i:i + step]
        d = x[rows, None, :] - t[None, :, :]
        out[rows] = np.sqrt(np.min(np.einsum("ijk,ijk->ij", d, d), axis=1))
    return out


def _falloff(d: np.ndarray, reach: float) -> np.ndarray:
    s = np.clip(d / reach, 0.0, 1.0)
    return libm.power(1.0 - s, 3) * (1.0 + 3.0 * s)


def _rigid(p: np.ndarray, centre, angle: float, shift) -> np.ndarray:
    a = np.radians(angle)
    c, s = np.cos(a), np.sin(a)
    q = p - np.asarray(centre, dtype=np.float64)
    return np.column_stack([c * q[:, 0] - s * q[:, 1], s * q[:, 0] + c * q[:, 1]]) + \
        np.asarray(centre, dtype=np.float64) + np.asarray(shift, dtype=np.float64)


def deform(p: np.ndarray, wall: np.ndarray, motion: str, params: dict,
           chord: float) -> np.ndarray:
    """The deformed points: `motion` "turn" (angle about `centre`, then `dx`, `dy`),
    "slide" (`dx`, `dy`) or "flap" (`angle` degrees, negative: trailing edge down, the
    wall nodes aft of `hinge` chords rotated about the lower surface there); the blend falls
    from 1 at the moving wall to 0 at `reach` chords (nodes on the fixed wall: 0)."""
    reach = params.get("reach", 1.0) * chord
    if motion in ("turn", "slide"):
        angle = params.get("angle", 0.0) if motion == "turn" else 0.0
        centre = params.get("centre", (0.25 * chord, 0.0))
        moved = _rigid(p, centre, angle, (params.get("dx", 0.0) * chord,
                                          params.get("dy", 0.0) * chord))
        w = _falloff(min_dist(p, p[wall], reach), reach)
        w[wall] = 1.0
        return p + w[:, None] * (moved - p)
    if motion == "flap":
        x0 = params.get("hinge", 0.75) * chord
        wi = np.flatnonzero(wall)
        aft = wi[p[wi, 0] > x0]
        main = wi[p[wi, 0] <= x0]
        hinge = (x0, float(p[main][np.argmin(np.abs(p[main, 0] - x0) + 10 * (p[main, 1] > 0))
                                   , 1]))
        moved = _rigid(p, hinge, params["angle"], (0.0, 0.0))
        d_f, d_m = min_dist(p, p[aft], reach), min_dist(p, p[main], 2 * reach)
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.where(d_f == 0, 1.0, d_m * d_m / (d_m * d_m + d_f * d_f))
        w = _falloff(d_f, reach) * share
        w[aft], w[main] = 1.0, 0.0
        return p + w[:, None] * (moved - p)
    raise ValueError(f"unknown motion {motion!r}")


# ------------------------------------------------------------------------------ meshes


def ogrid(n: int, first: float = 1e-4, quads: bool = True
          ) -> tuple[np.ndarray, FaceSet, np.ndarray, float]:
    """(points, faces, wall, chord) of an O-grid with about n cells around a cylinder of
    diameter 2 (the chord), first cell `first` chords, growth 1.1-1.2, far field 20
    diameters."""
    growth = 1.15
    rows = int(np.ceil(np.log(1 + 40.0 * (growth - 1) / (2 * first)) / np.log(growth)))
    cells = n if quads else n // 2
    around = max(32, round(cells / max(rows, 1) / 4) * 4)
    pts, fs = boundary_layer_annulus(around, first * 2.0, growth, 40.0)
    wall = np.hypot(pts[:, 0], pts[:, 1]) < 1.0 + 1e-12
    if not quads:
        fs = _faceset([_split(_quads_of(fs))], pts.shape[0])
    return pts, fs, wall, 2.0


def _c_outer(t: np.ndarray, radius: float, x_out: float) -> np.ndarray:
    """The C-grid's outer boundary at parameter t in [0, 1]: (x_out, -R) left along y = -R to
    x = 0.25, a half circle of radius R about (0.25, 0) in front, right along y = R to x_out,
    by arc length."""
    straight = x_out - 0.25
    total = 2 * straight + np.pi * radius
    s = t * total
    out = np.empty((t.size, 2))
    a = s < straight
    out[a] = np.column_stack([x_out - s[a], -radius + 0 * s[a]])
    b = (s >= straight) & (s <= straight + np.pi * radius)
    ang = -np.pi / 2 - (s[b] - straight) / radius
    out[b] = np.column_stack([0.25 + radius * np.cos(ang), radius * np.sin(ang)])
    c = s > straight + np.pi * radius
    out[c] = np.column_stack([0.25 + (s[c] - straight - np.pi * radius), radius + 0 * s[c]])
    return out


def cgrid(n: int, first: float = 1e-5, quads: bool = True
          ) -> tuple[np.ndarray, FaceSet, np.ndarray, float]:
    """(points, faces, wall, chord) of a C-grid with about n cells around a NACA 0012 of
    chord 1: the inner C line is the wake (x from 1 to 20, stretched) below, the airfoil
    (cosine-spaced, trailing edge to trailing edge), the wake above; the outer line is
    `_c_outer` (R = 20) matched piece by piece (wake to the straight parts at the same x,
    airfoil to the rest by arc length); grid lines straight from the inner to the outer
    line, rows geometric from `first` chords (the first row at the wall is exactly it).
    The wake's lower and upper nodes are the same nodes (one zone, like SU2's C-meshes)."""
    radius, x_out = 20.0, 20.0
    cells = n if quads else n // 2
    # rows and columns: about 2.5 columns per row (as SU2's 225 x 65 C-mesh has 3.5)
    nj = max(16, round(np.sqrt(cells / 2.5)))
    ni = max(64, round(cells / nj))
    n_wake = max(8, ni // 6)
    n_foil = ni - 2 * n_wake
    n_foil += n_foil % 2
    foil = naca0012(2.0 / n_foil)  # TE upper -> LE -> TE lower, closed TE not repeated
    foil = np.concatenate([foil[:1], foil[1:][::-1]])  # TE -> lower -> LE -> upper
    # the wake: rows from the trailing edge's cell size growing geometrically to x_out
    h0 = float(np.hypot(*(foil[1] - foil[0])))
    gw = _growth_for(h0 / (x_out - 1.0), n_wake)
    xw = 1.0 + (x_out - 1.0) * np.concatenate([[0.0], np.cumsum(gw ** np.arange(n_wake))]) \
        / np.sum(gw ** np.arange(n_wake))
    wake = np.column_stack([xw[1:], np.zeros(n_wake)])
    # outflow (below) -> TE -> lower side -> LE -> upper side -> TE -> outflow (above)
    inner = np.concatenate([wake[::-1], foil, foil[:1], wake])
    n_in = inner.shape[0]
    # outer: the wake parts at the same x, the airfoil part by its arc length in between
    t_low = (x_out - wake[::-1, 0]) / (2 * (x_out - 0.25) + np.pi * radius)
    t_lo_te = (x_out - 1.0) / (2 * (x_out - 0.25) + np.pi * radius)
    af = np.concatenate([foil[:1], foil[1:], foil[:1]])
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(af, axis=0).T))])
    t_af = t_lo_te + (1 - 2 * t_lo_te) * arc / arc[-1]
    t_out = np.concatenate([t_low, t_af, 1.0 - t_low[::-1]])
    outer = _c_outer(t_out, radius, x_out)
    length = np.hypot(*(outer - inner).T)
    # per grid line: the first row exactly `first` long; the rest geometric to the outer line
    grid = np.empty((nj + 1, n_in, 2))
    for i in range(n_in):
        gi = _growth_for(first / length[i], nj)
        si = np.concatenate([[0.0], np.cumsum(gi ** np.arange(nj))])
        si /= si[-1]
        grid[:, i] = inner[i] + si[:, None] * (outer[i] - inner[i])
    pts = grid.reshape(-1, 2)
    idx = np.arange(pts.shape[0]).reshape(nj + 1, n_in)
    # merge the wake: row 0, lower node i (< n_wake) is upper node n_in - 1 - i
    nw = n_wake
    merge = np.arange(pts.shape[0])
    merge[idx[0, n_in - nw:]] = idx[0, nw - 1::-1]
    # the trailing edge appears twice in the inner line (first and last of the airfoil)
    merge[idx[0, n_in - nw - 1]] = idx[0, nw]
    a = idx[:-1, :-1].ravel()
    q = np.column_stack([a, a + 1, a + n_in + 1, a + n_in])
    q = merge[q]
    wall_pts = np.zeros(pts.shape[0], dtype=bool)
    wall_pts[idx[0, nw:n_in - nw]] = True
    rows = [q] if quads else [_split(q)]
    p2, fs = compact_mesh(pts, rows)
    used = np.zeros(pts.shape[0], dtype=bool)
    used[q.ravel()] = True
    wall = wall_pts[used]
    return p2, fs, wall, 1.0


def _growth_for(ratio: float, n: int) -> float:
    """g with ratio * (g^n - 1) / (g - 1) = 1 (bisection): rows of geometric height whose
    first is `ratio` of the whole."""
    lo, hi = 1.0 + 1e-12, 3.0
    for _ in range(100):
        g = 0.5 * (lo + hi)
        if ratio * (g ** n - 1) / (g - 1) > 1.0:
            hi = g
        else:
            lo = g
    return 0.5 * (lo + hi)


def gmsh_bl(body: str, n: int, first: float = 1e-4, quads: bool = True
            ) -> tuple[np.ndarray, FaceSet, np.ndarray, float]:
    """(points, faces, wall, chord) of a gmsh mesh with a BoundaryLayer field around `body`
    ("naca": NACA 0012 of chord 1; "cylinder": diameter 1), first cell `first` chords,
    ratio 1.2, 30 layers at most (quads, or triangles with `quads` False), Frontal-Delaunay
    triangles outside graded from the body to a circle of 20 chords (size h near the body
    for about n cells)."""
    import gmsh

    h = 2.0 / np.sqrt(max(n, 1000) / 3.0)
    for _ in range(4):
        pts, groups, wall_tags = _gmsh_bl_once(gmsh, body, h, first, quads)
        got = sum(g.shape[0] for g in groups)
        if abs(got - n) < 0.12 * n:
            break
        h *= float(np.sqrt(got / n))
    p, fs = compact_mesh(pts, groups)
    used = np.zeros(pts.shape[0], dtype=bool)
    for g in groups:
        used[g.ravel()] = True
    wall = wall_tags[used]
    return p, fs, wall, 1.0


def fresh_gmsh_bl(body: str, n: int, first: float = 1e-4, quads: bool = True
                  ) -> tuple[np.ndarray, FaceSet, np.ndarray, float]:
    """`gmsh_bl` in a new process: gmsh keeps state from one mesh to the next inside a
    process (the same call made twice in one process gives another mesh), so each case is
    made from a fresh gmsh and is the same mesh whatever this process made before it. Not
    bit for bit across processes in general: gmsh orders some of its sets by memory
    address, and the same call from another checkout path (or in a first run that writes
    the bytecode cache) placed and numbered the nodes of the 10k cylinder differently, with
    the same counts; the case cache keeps the mesh first made (docs/repair.md)."""
    return in_fresh_process(gmsh_bl, body, n, first, quads)


def in_fresh_process(fn: Callable[..., T], *args: Any) -> T:
    """fn(*args) in a new spawned process of its own (none of this process's state)."""
    ctx = mp.get_context("spawn")
    with ProcessPoolExecutor(max_workers=1, mp_context=ctx) as pool:
        return pool.submit(fn, *args).result()


def _gmsh_bl_once(gmsh, body: str, h: float, first: float, quads: bool):
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        gmsh.model.add("bl")
        geo = gmsh.model.geo
        if body == "naca":
            outline = naca0012(0.004)  # TE upper -> LE -> TE lower
            centre = (0.5, 0.0)
            tags = [geo.addPoint(float(x), float(y), 0.0, h) for x, y in outline]
            body_curves = [geo.addSpline(tags[: len(tags) // 2 + 1]),
                           geo.addSpline(tags[len(tags) // 2:] + tags[:1])]
        else:
            centre = (0.0, 0.0)
            mid = geo.addPoint(0.0, 0.0, 0.0, h)
            tags = [geo.addPoint(0.5 * np.cos(t), 0.5 * np.sin(t), 0.0, h)
                    for t in (0.0, 1.5 * np.pi, np.pi, 0.5 * np.pi)]  # clockwise: a hole
            body_curves = [geo.addCircleArc(tags[i], mid, tags[(i + 1) % 4]) for i in range(4)]
        far = []
        r = 20.0
        c0 = geo.addPoint(centre[0], centre[1], 0.0, 8.0)
        ps = [geo.addPoint(centre[0] + r * np.cos(t), centre[1] + r * np.sin(t), 0.0, 8.0)
              for t in (0.0, 0.5 * np.pi, np.pi, 1.5 * np.pi)]
        for i in range(4):
            far.append(geo.addCircleArc(ps[i], c0, ps[(i + 1) % 4]))
        outer = geo.addCurveLoop(far)
        hole = geo.addCurveLoop(body_curves)
        geo.addPlaneSurface([outer, hole])
        geo.synchronize()
        fld = gmsh.model.mesh.field
        bl = fld.add("BoundaryLayer")
        fld.setNumbers(bl, "CurvesList", body_curves)
        fld.setNumber(bl, "Size", first)
        fld.setNumber(bl, "Ratio", 1.2)
        fld.setNumber(bl, "Thickness", min(0.05, first * (1.2 ** 30 - 1) / 0.2))
        fld.setNumber(bl, "Quads", 1 if quads else 0)
        if body == "naca":
            fld.setNumbers(bl, "FanPointsList", [tags[0]])
        fld.setAsBoundaryLayer(bl)
        dist = fld.add("Distance")
        fld.setNumbers(dist, "CurvesList", body_curves)
        fld.setNumber(dist, "Sampling", 200)
        thr = fld.add("Threshold")
        fld.setNumber(thr, "InField", dist)
        fld.setNumber(thr, "SizeMin", h)
        fld.setNumber(thr, "SizeMax", 2.0)
        fld.setNumber(thr, "DistMin", 0.05)
        fld.setNumber(thr, "DistMax", 10.0)
        fld.setAsBackgroundMesh(thr)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.model.mesh.generate(2)
        ntags, coords, _ = gmsh.model.mesh.getNodes()
        types, _, nodes = gmsh.model.mesh.getElements(2)
        wall_nodes = np.concatenate([gmsh.model.mesh.getNodes(1, c, includeBoundary=True)[0]
                                     for c in body_curves]).astype(np.int64)
    finally:
        gmsh.finalize()
    index = np.full(int(ntags.max()) + 1, -1, dtype=np.int64)
    index[ntags.astype(np.int64)] = np.arange(ntags.size)
    pts = coords.reshape(-1, 3)[:, :2].copy()
    groups = []
    for t, nd in zip(types, nodes):
        k = {2: 3, 3: 4}[int(t)]
        groups.append(index[nd.astype(np.int64)].reshape(-1, k))
    wall = np.zeros(pts.shape[0], dtype=bool)
    wall[index[wall_nodes]] = True
    return pts, groups, wall


@dataclass(frozen=True)
class Public:
    """A public SU2 mesh: its repository and commit, path, SHA-256's first 16 hex digits
    ("" unchecked), the markers of its moving wall, its chord and whether it turns about
    its centre (a bluff body) instead of its quarter chord."""

    repo: tuple[str, str]
    path: str
    digest: str
    wall: tuple[str, ...]
    chord: float = 1.0
    centred: bool = False


PUBLIC: dict[str, Public] = {
    "n0012c": Public(SU2_TUTORIALS, "compressible_flow/UQ_NACA0012/mesh_n0012_225-65.su2", "",
                     ("airfoil",)),
    "n0012tri": Public(SU2_TUTORIALS,
                       "design/Inviscid_2D_Unconstrained_NACA0012/mesh_NACA0012_inv.su2",
                       "9094b51c2628d3bb", ("airfoil",)),
    "hydrofoil": Public(SU2_TUTORIALS,
                        "incompressible_flow/Inc_Inviscid_Hydrofoil/mesh_NACA0012_5deg_6814.su2",
                        "26d0d1dcfdfb2643", ("airfoil",)),
    "cylinder": Public(SU2_TUTORIALS, "compressible_flow/Laminar_Cylinder/mesh_cylinder_lam.su2",
                       "", ("cylinder",), centred=True),
    "rae2822": Public(SU2_TUTORIALS,
                      "design/Turbulent_2D_Constrained_RAE2822/mesh_RAE2822_turb.su2", "",
                      ("AIRFOIL",)),
    # SU2's regression test cases (`--testcases`, all held out)
    "tc-n64a010hyb": Public(SU2_TESTCASES, "aeroelastic/mesh_NACA64A010_hybrid_inv.su2",
                            "697a5eb5ffdec554", ("airfoil",)),
    "tc-n64a010turb": Public(SU2_TESTCASES,
                             "harmonic_balance/hb_rans_preconditioning/n64a010_turb.su2",
                             "279a08566f5d6f92", ("airfoil",)),
    "tc-cylinder": Public(SU2_TESTCASES, "disc_adj_rans/cylinder/mesh_cylinder.su2",
                          "67769badbccc20a3", ("Cylinder",), centred=True),
    "tc-naca4412": Public(SU2_TESTCASES, "deformation/naca4412/mesh_NACA4412_turb.su2",
                          "5c2a91605b5d0d9a", ("pressure", "TE", "suction")),
    # `--unseen`: more of SU2's test meshes, run only once the code they check was final
    "un-square": Public(SU2_TESTCASES, "unsteady/square_cylinder/mesh_square_turb_hybrid.su2",
                        "f966f166f58eadcf", ("square",), centred=True),
    "un-n64a010tri": Public(SU2_TESTCASES,
                            "unsteady/pitching_naca64a010_euler/mesh_NACA64A010_inv.su2",
                            "fdf038360ffb3724", ("airfoil",)),
    "un-n0012hyb": Public(SU2_TESTCASES, "navierstokes/naca0012/mesh_NACA0012_lam_hybrid_v1.su2",
                          "5d44d67319dba2c5", ("airfoil",)),
    "un-n0012c113": Public(SU2_TESTCASES, "disc_adj_rans/naca0012/n0012_113-33.su2",
                           "9a872a3de5a1b6b6", ("airfoil",)),
    "un-plate": Public(SU2_TESTCASES,
                       "py_wrapper/flatPlate_rigidMotion/2D_FlatPlate_Rounded.su2",
                       "9ebf9edc75058ec8", ("plate",), chord=0.035),
    "un-stator": Public(SU2_TESTCASES,
                        "turbomachinery/transonic_stator_2D/mesh_stator_turb.su2",
                        "08c74dd9617f66f6", ("airfoil",), chord=0.068),
    "un-blunt": Public(SU2_TESTCASES, "euler/bluntbody/blunt_91.su2", "ed9020437ac45665",
                       ("wall",), centred=True),
}


def public_file(key: str, mirror: Path | None = None) -> Path:
    """The SU2 file of `key`: build/public_meshes/OWNER+NAME/PATH when there, else taken
    from a bare snapshot (`mirror`/OWNER+NAME/repo) with git show at its commit into
    build/repair_bench/public/; FileNotFoundError when neither has it."""
    pub = PUBLIC[key]
    repo_name, path = pub.repo[0], pub.path
    local = repo_name.replace("/", "+")
    here = ROOT / "build" / "public_meshes" / local / path
    if here.is_file():
        return here
    out = CACHE / "public" / local / path
    if not out.is_file():
        where = mirror or DEFAULT_MIRROR
        repo = snapshot(where, repo_name)
        if not Path(repo).is_dir():
            raise FileNotFoundError(f"{path}: not in build/public_meshes and no snapshot at "
                                    f"{repo} (scripts/fetch_public_meshes.py, --mirror)")
        data = from_snapshot(where, pub.repo, path)
        if not data:
            raise FileNotFoundError(f"{path}: not in the snapshot {repo}")
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_bytes(data)
    if pub.digest and hashlib.sha256(out.read_bytes()).hexdigest()[:16] != pub.digest:
        raise ValueError(f"{out}: its SHA-256 is not the pinned one")
    return out


def public_mesh(key: str, mirror: Path | None = None
                ) -> tuple[np.ndarray, FaceSet, np.ndarray, float]:
    from fileio import solver_mesh

    sm = solver_mesh.read(str(public_file(key, mirror)))
    pts = np.asarray(sm.mesh.points, dtype=np.float64)[:, :2].copy()
    counts = np.diff(sm.offsets)
    corners = np.asarray(sm.corners, dtype=np.int64).copy()
    fs = faces_from_csr(sm.offsets[:-1], counts, corners, pts.shape[0])
    area = np.zeros(fs.n_faces)
    for g in fs.groups:
        x, y = pts[g.nodes, 0], pts[g.nodes, 1]
        area[g.ids] = np.sum(x * np.roll(y, -1, axis=0) - np.roll(x, -1, axis=0) * y, axis=0)
    for f in np.flatnonzero(area < 0):  # SU2 files may list cells clockwise (RAE 2822)
        s, e = sm.offsets[f], sm.offsets[f + 1]
        corners[s:e] = corners[s:e][::-1]
    fs = faces_from_csr(sm.offsets[:-1], counts, corners, pts.shape[0])
    wall = np.zeros(pts.shape[0], dtype=bool)
    for name in PUBLIC[key].wall:
        wall |= sm.group_nodes(name)
    return pts, fs, wall, PUBLIC[key].chord


# ------------------------------------------------------------------------------ cases


def base(spec: Spec, mirror: Path | None = None):
    m, n = spec.mesh, spec.size
    first = spec.params.get("first", None)
    if m in ("ogrid", "ogridtri"):
        return ogrid(int(n), first or 1e-4, quads=m == "ogrid")
    if m in ("cgrid", "cgridtri"):
        return cgrid(int(n), first or 1e-5, quads=m == "cgrid")
    if m.startswith("gmshbl"):
        body = "naca" if m.endswith("naca") else "cylinder"
        return fresh_gmsh_bl(body, int(n), first or 1e-4, quads="tri" not in m)
    if m == "public":
        return public_mesh(str(n), mirror)
    raise ValueError(f"unknown mesh {m!r}")


def make(spec: Spec, mirror: Path | None = None) -> Case:
    ref, fs, wall, chord = base(spec, mirror)
    params = {k: v for k, v in spec.params.items() if k != "first"}
    lo, hi = ref[wall].min(axis=0), ref[wall].max(axis=0)
    round_body = spec.mesh.startswith("ogrid") or spec.mesh.endswith("cyl") or \
        (spec.mesh == "public" and PUBLIC[str(spec.size)].centred)
    # turned about the body's centre (a cylinder) or its quarter chord (an airfoil)
    params.setdefault("centre", (float(lo[0] + (0.5 if round_body else 0.25) * (hi[0] - lo[0])),
                                 float(0.5 * (lo[1] + hi[1]))))
    pts = deform(ref, wall, spec.motion, params, chord)
    fixed = boundary_nodes(ref.shape[0], fs)
    pts[fixed & ~wall] = ref[fixed & ~wall]
    return Case(spec.name, spec.mesh, pts, ref, fs, fixed, wall, spec.held_out)


def load(spec: Spec, mirror: Path | None = None) -> Case:
    """The case, from build/repair_bench/ (made and cached on first use)."""
    path = spec.path
    if not path.exists():
        c = make(spec, mirror)
        CACHE.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, points=c.points, reference=c.reference, offsets=c.faces.offsets,
                 indices=c.faces.indices, fixed=c.fixed, wall=c.wall,
                 meta=json.dumps({"name": spec.name}))
        tmp.replace(path)
    with np.load(path) as d:
        a = {k: d[k] for k in d.files}
    fs = FaceSet(a["offsets"], a["indices"], a["points"].shape[0])
    return Case(spec.name, spec.mesh, a["points"], a["reference"], fs, a["fixed"], a["wall"],
                spec.held_out)


def describe(c: Case) -> str:
    st = mesh_stats(c.points, c.faces)
    return f"{c.name}: {c.points.shape[0]} nodes, {c.n_faces} cells, {st.n_inverted} folded"
