"""Speed benchmark of the NumPy core: shared meshes and a generated 1M-triangle mesh.

Prints markdown tables: iterations, seconds (median of repeated runs), nanoseconds per
element per iteration, and the final quality; then the per-iteration cost and peak memory
at 1M triangles. Run: `make bench` or `python -m bench.run [--quick]`.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from core import EEGTParams, untangle_and_smooth
from core.eegt.engine_numpy import NumpyEngine
from core.mesh.obj_io import read_obj
from core.run.pipeline import free_nodes

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
MESHES = ["quad_hole", "tri_two_holes", "naca_deform", "mixed_quad_tri", "polygon_voronoi"]


def bench_mesh(name: str, params: EEGTParams, repeats: int) -> dict:
    v, f = read_obj(DATA / f"{name}.obj")
    p = v[:, :2].copy()
    times, res = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        res = untangle_and_smooth(p, f, params=params)
        times.append(time.perf_counter() - t)
    its = res.untangle_iterations + res.smooth_iterations
    sec = statistics.median(times)
    return {
        "mesh": name,
        "faces": f.n_faces,
        "status": res.status,
        "untangle": res.untangle_iterations,
        "smooth": res.smooth_iterations,
        "seconds": sec,
        "ns": sec / max(its, 1) / f.n_faces * 1e9,
        "inv": res.after.n_inverted,
        "q_min": res.after.q_min,
        "q_avg": res.after.q_avg,
    }


def table_meshes(params: EEGTParams, label: str, repeats: int) -> None:
    print(f"\n### {label}\n")
    print(
        "| mesh | faces | status | untangle it | smooth it | seconds (median) | ns/elem/iter | inverted | q_min | q_avg |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in MESHES:
        r = bench_mesh(name, params, repeats)
        print(
            f"| {r['mesh']} | {r['faces']} | {r['status']} | {r['untangle']} | {r['smooth']} | "
            f"{r['seconds']:.3f} | {r['ns']:.0f} | {r['inv']} | {r['q_min']:.4f} | {r['q_avg']:.4f} |",
            flush=True,
        )


def big_iteration(n_tri: int, refresh: int, steps: int) -> None:
    """Run in a child process so peak memory is this mesh's alone."""
    from bench.meshgen import jittered_square

    p, f = jittered_square(n_tri)
    t = time.perf_counter()
    eng = NumpyEngine(p, f, free_nodes(len(p), f), EEGTParams().with_(distance_refresh=refresh))
    setup = time.perf_counter() - t
    per = []
    for i in range(steps):
        t = time.perf_counter()
        eng.step("untangle" if i < steps // 2 else "smooth")
        per.append(time.perf_counter() - t)
    # amortized: total over whole refresh cycles, so refresh cost is counted once per cycle
    full = per[: (steps // refresh) * refresh] if steps >= refresh else per
    amort = sum(full) / len(full) / f.n_faces * 1e9
    med = statistics.median(per) / f.n_faces * 1e9
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(
        f"| {f.n_faces} | {refresh} | {setup:.2f} | {med:.0f} | {amort:.0f} | {rss:.0f} |",
        flush=True,
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats, no 1M mesh")
    ap.add_argument("--big", type=int, default=1_000_000, help="triangles of the generated mesh")
    ap.add_argument("--child", nargs=3, type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        big_iteration(*args.child)
        return
    repeats = 1 if args.quick else 3
    print(f"NumPy {np.__version__}, Python {sys.version.split()[0]}")
    table_meshes(EEGTParams.paper(), "Paper parameters (EEGTParams.paper())", repeats)
    table_meshes(EEGTParams(), "Default parameters (EEGTParams())", repeats)
    sizes = [100_000] if args.quick else [100_000, args.big]
    print("\n### Per-iteration cost, generated jittered square (NumPy)\n")
    print(
        "| triangles | distance refresh every | set-up s | median ns/elem/iter | amortized ns/elem/iter (incl. refresh) | peak RSS MB |"
    )
    print("|---|---|---|---|---|---|")
    for n in sizes:
        for refresh in (1, 10):
            subprocess.run(
                [sys.executable, "-m", "bench.run", "--child", str(n), str(refresh), "20"],
                check=True,
            )


if __name__ == "__main__":
    main()
