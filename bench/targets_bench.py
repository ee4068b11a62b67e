"""Per-face target shapes: quality against the targets with and without them, and the cost.

Run `python -m bench.targets_bench` (`--quick`: fewer repeats). Tables (markdown):
1. Whole runs on tangled meshes whose faces have target shapes, each run pulled towards the
   regular polygon (targets=None, the paper) and towards the targets: stats measured against
   the targets before and after (n_inverted, q_min, q_avg), the mean ratio against the
   regular polygon after, iterations and seconds. Cases: a grid of 1 x 4 cells, a graded
   grid (row heights x1.25 per row) with its own cells as targets, and a "UV map" (a sphere
   band's longitude-latitude map, interior jittered) with the faces' 3D shapes as targets.
2. Cost per EEGT iteration (`step("untangle")`, median after a warm-up) on the shared meshes
   and a generated 100k-triangle mesh, with targets=None and with targets (every face's regular polygon given explicitly, so the
   general formulas run), NumPy and OpenCL.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from core import EEGTParams, mesh_stats, untangle_and_smooth
from core.eegt import backends
from core.mesh.faces import FaceSet, as_faceset
from core.mesh.obj_io import read_obj
from core.metrics.targets import face_shapes_2d, prepare_targets
from core.run.pipeline import free_nodes

from .meshgen import jittered_square

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
EEGT_ONLY = EEGTParams(untangle="eegt", polish_iterations=0, lift_rounds=0)


def grid(xs: np.ndarray, ys: np.ndarray, jitter: float, seed: int):
    """Quads on the tensor grid xs x ys; interior nodes moved by up to `jitter` of the local
    cell size (tangles it); returns (points, faces, the untangled points)."""
    X, Y = np.meshgrid(xs, ys)
    pts = np.column_stack([X.ravel(), Y.ravel()])
    m, n = len(ys) - 1, len(xs) - 1
    hx = np.gradient(xs)[None, :].repeat(m + 1, 0).ravel()
    hy = np.gradient(ys)[:, None].repeat(n + 1, 1).ravel()
    iy, ix = np.mgrid[0 : m + 1, 0 : n + 1]
    inner = ((ix > 0) & (ix < n) & (iy > 0) & (iy < m)).ravel()
    rng = np.random.default_rng(seed)
    moved = pts.copy()
    noise = rng.uniform(-jitter, jitter, (int(inner.sum()), 2))
    moved[inner] += noise * np.column_stack([hx[inner], hy[inner]])
    a = (np.arange(m)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    return moved, np.column_stack([a, a + 1, a + n + 2, a + n + 1]), pts


def cases():
    """(name, points, faces, targets) of every table-1 case."""
    out = []
    p, f, _ = grid(np.arange(17.0), 4.0 * np.arange(9.0), 0.6, 0)
    out.append(("grid 16 x 8, cells 1 x 4", p, f, np.tile([[0, 0], [1, 0], [1, 4], [0, 4]],
                                                           (len(f), 1)).astype(float)))
    heights = 0.2 * np.array([1.25**k for k in range(12)])  # the C library's pow: see bench.libm
    ys = np.concatenate([[0.0], np.cumsum(heights)])
    p, f, ref = grid(np.linspace(0, ys[-1], 13), ys, 0.45, 1)
    out.append(("graded grid 12 x 12 (x1.25)", p, f, ref[f.ravel()]))
    # longitude-latitude "UV" of a sphere band: faces' 3D shapes as targets
    lon, lat = np.linspace(0, np.pi / 2, 17), np.linspace(-1.2, 1.2, 17)
    p, f, uv = grid(lon, lat, 0.5, 2)
    L, B = uv[:, 0], uv[:, 1]
    xyz = np.column_stack([np.cos(B) * np.cos(L), np.cos(B) * np.sin(L), np.sin(B)])
    shapes = face_shapes_2d(xyz, as_faceset(f, len(p)))
    out.append(("sphere band, lon-lat UV, 3D shapes", p, f, shapes))
    return out


def table_runs(repeats: int) -> list[str]:
    rows = ["| case | params | pulled towards | before (inv, q_min, q_avg) vs target | after vs target | after q_avg vs regular | iterations (untangle + global + smooth) | seconds |",
            "|---|---|---|---|---|---|---|---|"]
    for name, p, f, T in cases():
        before = mesh_stats(p, f, T)
        for plabel, prm in (("EEGT only", EEGT_ONLY), ("default", EEGTParams())):
            for tlabel, tg in (("regular (paper)", None), ("targets", T)):
                times = []
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    r = untangle_and_smooth(p, f, params=prm, targets=tg)
                    times.append(time.perf_counter() - t0)
                s = mesh_stats(r.points, f, T)
                reg = mesh_stats(r.points, f)
                rows.append(
                    f"| {name} | {plabel} | {tlabel} | {before.n_inverted}, {before.q_min:.3f}, "
                    f"{before.q_avg:.3f} | {s.n_inverted}, {s.q_min:.3f}, {s.q_avg:.3f} | "
                    f"{reg.q_avg:.3f} | {r.untangle_iterations} + {r.global_iterations} + "
                    f"{r.smooth_iterations} | {statistics.median(times):.3f} |"
                )
    return rows


def step_ms(backend: str, p, f: FaceSet, tg, steps: int, repeats: int) -> tuple[float, float]:
    """Median ms of one step("untangle") without and with targets: the two engines step
    in alternating rounds of `steps`, so both see the same machine load."""
    free = free_nodes(len(p), f)
    engines = []
    for targets in (None, tg):
        eng, name = backends.make_engine(backend, p, f, free, EEGTParams(), targets)
        if not name.startswith(backend):
            return float("nan"), float("nan")
        for _ in range(3):
            eng.step("untangle")
        engines.append(eng)
    times: list[list[float]] = [[], []]
    for _ in range(repeats):
        for i, eng in enumerate(engines):
            t0 = time.perf_counter()
            for _ in range(steps):
                eng.step("untangle")
            times[i].append((time.perf_counter() - t0) / steps * 1e3)
    return statistics.median(times[0]), statistics.median(times[1])


def table_cost(repeats: int) -> list[str]:
    rows = ["| mesh | faces | NumPy ms/it none | NumPy ms/it targets | ratio | OpenCL ms/it none | OpenCL ms/it targets | ratio |",
            "|---|---|---|---|---|---|---|---|"]
    meshes = ["quad_hole", "mixed_quad_tri", "polygon_voronoi", "tri_two_holes", "naca_deform"]
    for name in [*meshes, "jittered square 100k"]:
        if name in meshes:
            v, f = read_obj(DATA / f"{name}.obj")
            p = v[:, :2].copy()
        else:
            p, f = jittered_square(100_000)
        reg = np.concatenate([np.column_stack([np.cos(2 * np.pi * np.arange(n) / n),
                                               np.sin(2 * np.pi * np.arange(n) / n)])
                              for n in f.counts])
        tg = prepare_targets(reg, f)
        cells = [f"| {name} | {f.n_faces} "]
        for backend in ("numpy", "opencl"):
            a, b = step_ms(backend, p, f, tg, 10, repeats)
            cells.append(f"| {a:.3f} | {b:.3f} | {b / a:.2f} ")
        rows.append("".join(cells) + "|")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one repeat per measurement")
    args = ap.parse_args()
    repeats = 1 if args.quick else 15
    print("\n".join(table_runs(1 if args.quick else 3)))
    print()
    print("\n".join(table_cost(repeats)))


if __name__ == "__main__":
    main()
