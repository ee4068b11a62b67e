"""Benchmark of core.optimize.untangle_global on the bundled meshes (tests/data) and the paper's
Table 1 mesh (stage alone, no EEGT smoothing).

Usage: python -m bench.global_untangle_bench [mesh ...] [--perturb K] [--repeat R]
Self-contained: own OBJ loader, boundary detection and mean-ratio quality (docs/method.md 3).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from core.optimize import GlobalOptions, untangle_global

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"  # the bundled OBJ meshes
# the paper's Table 1 mesh, third-party and read in place (docs/testing.md)
MESQUITE = ROOT.parent / "shared" / "meshes" / "mesquite" / "hole_in_square_tanglap.vtk"
DEFAULT = ["two_holes_twist", "naca_deform", "tri_two_holes", "quad_hole", "mixed_quad_tri",
           "polygon_voronoi", "mesquite"]


def load_obj(path: Path) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """Minimal OBJ reader: `v x y z` and `f i j k ...` (1-based, optional /vt/vn)."""
    verts: list[tuple[float, float]] = []
    faces: dict[int, list[list[int]]] = {}
    for line in path.read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            verts.append((float(parts[1]), float(parts[2])))
        elif parts[0] == "f":
            idx = [int(p.split("/")[0]) - 1 for p in parts[1:]]
            faces.setdefault(len(idx), []).append(idx)
    groups = {n: np.array(f, dtype=np.int64) for n, f in faces.items()}
    return np.array(verts, dtype=np.float64), groups


def load_mesquite_vtk(path: Path) -> tuple[np.ndarray, dict[int, np.ndarray], np.ndarray]:
    """The paper's Table 1 mesh (legacy VTK, read in place): points, CCW quads, fixed mask."""
    tok = path.read_text().split()
    i = tok.index("POINTS")
    n = int(tok[i + 1])
    pts = np.array(tok[i + 3 : i + 3 + 3 * n], dtype=np.float64).reshape(n, 3)[:, :2]
    i = tok.index("CELLS")
    m = int(tok[i + 1])
    cells = np.array(tok[i + 3 : i + 3 + 5 * m], dtype=np.int64).reshape(m, 5)[:, 1:]
    i = tok.index("fixed", tok.index("POINT_DATA"))
    j = tok.index("LOOKUP_TABLE", i) + 2
    fixed = np.array(tok[j : j + n], dtype=np.int64) == 1
    return pts, {4: cells[:, ::-1].copy()}, fixed


def boundary_nodes(n_nodes: int, groups: dict[int, np.ndarray]) -> np.ndarray:
    """Nodes of edges used by exactly one face."""
    e = np.concatenate([np.stack([f.ravel(), np.roll(f, -1, axis=1).ravel()], 1)
                        for f in groups.values()])
    e = np.sort(e, axis=1)
    key = e[:, 0] * n_nodes + e[:, 1]
    uniq, cnt = np.unique(key, return_counts=True)
    b = uniq[cnt == 1]
    mask = np.zeros(n_nodes, dtype=bool)
    mask[b // n_nodes] = True
    mask[b % n_nodes] = True
    return mask


def quality(points: np.ndarray, groups: dict[int, np.ndarray]) -> tuple[float, float, int]:
    """q_min, q_avg (inverted count as 0) and the number of inverted elements."""
    qs = []
    n_inv = 0
    for n, f in groups.items():
        P = points[f]
        a = (n - 2) * np.pi / n
        winv = np.linalg.inv(np.array([[1.0, np.cos(a)], [0.0, np.sin(a)]]))
        e1 = np.roll(P, -1, axis=1) - P
        e2 = np.roll(P, 1, axis=1) - P
        J = np.stack([e1, e2], axis=-1)  # (F, n, 2, 2) columns e1, e2
        det_j = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
        M = J @ winv
        det_m = M[..., 0, 0] * M[..., 1, 1] - M[..., 0, 1] * M[..., 1, 0]
        fro = np.sum(M * M, axis=(-1, -2))
        qk = 2.0 * det_m / np.maximum(fro, 1e-300)
        bad = np.any(det_j <= 0, axis=1)
        q = np.where(bad, 0.0, qk.mean(axis=1))
        n_inv += int(bad.sum())
        qs.append(q)
    q = np.concatenate(qs)
    return float(q.min()), float(q.mean()), n_inv


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("meshes", nargs="*", default=DEFAULT)
    ap.add_argument("--perturb", type=int, default=0, help="runs with 1e-9 interior noise")
    ap.add_argument("--max-iter", type=int, default=3000)
    ap.add_argument("--polish", type=int, default=300)
    ap.add_argument("--power", type=float, default=1.0)
    ap.add_argument("--repeat", type=int, default=1, help="report the median time of R runs")
    args = ap.parse_args()
    for name in args.meshes:
        if name == "mesquite":
            pts, groups, fixed = load_mesquite_vtk(MESQUITE)
            free = ~fixed
        else:
            pts, groups = load_obj(DATA / f"{name}.obj")
            free = ~boundary_nodes(len(pts), groups)
        q0 = quality(pts, groups)
        times = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            out, info = untangle_global(pts, groups, free, GlobalOptions(max_iter=args.max_iter, polish_iter=args.polish, polish_power=args.power))
            times.append(time.perf_counter() - t)
        dt = float(np.median(times))
        q1 = quality(out, groups)
        same = bool(np.array_equal(out[~free], pts[~free]))
        print(f"{name:16s} in: inv {q0[2]:5d} q {q0[0]:.3f}/{q0[1]:.3f} | out: inv {q1[2]:4d} "
              f"q_min {q1[0]:.3f} q_avg {q1[1]:.3f} | {dt:6.2f} s, {info['iterations']} it "
              f"({1e3 * dt / max(info['iterations'], 1):.2f} ms/it), rounds {info['rounds']}, "
              f"fixed same {same}, eps {[f'{e:.1e}' for e in info['eps_history']]}", flush=True)
        if args.perturb:
            span = float(np.ptp(pts, axis=0).max())
            ok = 0
            times = []
            for seed in range(args.perturb):
                rng = np.random.default_rng(seed)
                p2 = pts.copy()
                p2[free] += 1e-9 * span * rng.standard_normal((int(free.sum()), 2))
                t = time.perf_counter()
                o2, inf2 = untangle_global(p2, groups, free, GlobalOptions(max_iter=args.max_iter, polish_iter=args.polish, polish_power=args.power))
                times.append(time.perf_counter() - t)
                qq = quality(o2, groups)
                ok += qq[2] == 0
                print(f"   seed {seed}: inv {qq[2]} q {qq[0]:.3f}/{qq[1]:.3f} "
                      f"{times[-1]:.2f} s {inf2['iterations']} it", flush=True)
            print(f"   perturbed: {ok}/{args.perturb} untangled, median {np.median(times):.2f} s")


if __name__ == "__main__":
    main()
