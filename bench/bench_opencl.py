"""NumPy vs OpenCL backend: per-iteration and end-to-end times, as markdown tables.

Run `python -m bench.bench_opencl` (add `--quick` for a smoke run, `EEGT_OPENCL_DEVICE=...`
to pick a device, e.g. a GPU on a machine that has one). Every time is the median of
`--repeats` runs (a case whose first run takes longer than `--slow` seconds runs once).

Tables:
1. End to end (`untangle_and_smooth`) on the shared meshes, with the paper's parameters
   (`EEGTParams.paper()`: EEGT untangling, distance refresh every iteration; `--params
   default` for the defaults, whose global untangling stage runs on the host): iterations,
   seconds, speed-up, ns per element per iteration, and the largest position difference
   between the two backends' results (relative to the mesh size).
2. End to end on the generated meshes with the iterations capped (`--cap`, untangling and
   smoothing each), so set-up, upload and download are included but the run stays short.
3. Per iteration on the shared meshes and generated triangle meshes (bench/meshgen.py):
   engine set-up time and the median time of one `step("untangle")` after a warm-up, in
   ms and ns per element, with the default parameters (distance refresh every 10th
   iteration; timed over whole multiples of 10 steps, so the refresh is amortized as in a
   run) and with a refresh every iteration (the paper's setting).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

from core.eegt import backends
from core.mesh.faces import FaceSet
from core.mesh.obj_io import read_obj
from core.params import EEGTParams
from core.run.pipeline import free_nodes, untangle_and_smooth

from .meshgen import jittered_square

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
SHARED = ["quad_hole", "tri_two_holes", "naca_deform", "mixed_quad_tri", "polygon_voronoi"]
SLOW_E2E = ["two_holes_twist"]  # fails after 5000 iterations: per-iteration table only


def timed(fn, repeats: int, slow: float) -> tuple[float, object]:
    """(median seconds, last result) of fn(); one run only if the first one is slow."""
    times, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
        if times[0] > slow:
            break
    return statistics.median(times), out


def load_mesh(name: str) -> tuple[np.ndarray, FaceSet]:
    v, f = read_obj(DATA / f"{name}.obj")
    return v[:, :2].copy(), f


def end_to_end(name, p, f, params, repeats, slow) -> str:
    """One markdown row: both backends run the whole pipeline."""
    t_np, r_np = timed(lambda: untangle_and_smooth(p, f, params=params), repeats, slow)
    t_cl, r_cl = timed(
        lambda: untangle_and_smooth(p, f, params=params, backend="opencl"), repeats, slow
    )
    its = (r_np.untangle_iterations, r_np.smooth_iterations)
    its_cl = (r_cl.untangle_iterations, r_cl.smooth_iterations)
    scale = float(np.ptp(p, axis=0).max())
    diff = float(np.abs(r_np.points - r_cl.points).max()) / scale
    n_it = max(1, sum(its_cl))
    same = "same" if its == its_cl else f"{its_cl[0]}+{its_cl[1]}"
    return (
        f"| {name} | {f.n_faces} | {its[0]}+{its[1]} | {same} | {t_np:.3f} | {t_cl:.3f} | "
        f"{t_np / t_cl:.1f}x | {t_np / max(1, sum(its)) / f.n_faces * 1e9:.0f} | "
        f"{t_cl / n_it / f.n_faces * 1e9:.0f} | {diff:.1e} | "
        f"{r_np.after.n_inverted}/{r_cl.after.n_inverted} | "
        f"{r_np.after.q_avg:.4f}/{r_cl.after.q_avg:.4f} |"
    )


def per_iteration(name, p, f, repeats: int, steps: int, params: EEGTParams) -> str:
    """One markdown row: set-up and per-step time of each engine."""
    free = free_nodes(len(p), f)
    cells = []
    for backend in ("numpy", "opencl"):
        t = time.perf_counter()
        eng, used = backends.make_engine(backend, p, f, free, params)
        setup = time.perf_counter() - t
        assert used == backend, used
        for _ in range(2):  # warm-up: kernels, caches, first distance refresh
            eng.step("untangle")
        per = []
        for _ in range(repeats):
            t = time.perf_counter()
            for _ in range(steps):
                eng.step("untangle")
            per.append((time.perf_counter() - t) / steps)
        sec = statistics.median(per)
        cells.append((setup, sec))
        del eng
    (s_np, t_np), (s_cl, t_cl) = cells
    nf = f.n_faces
    return (
        f"| {name} | {nf} | {s_np:.2f} | {s_cl:.2f} | {t_np * 1e3:.2f} | {t_cl * 1e3:.2f} | "
        f"{t_np / nf * 1e9:.0f} | {t_cl / nf * 1e9:.1f} | {t_np / t_cl:.1f}x |"
    )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes, one repeat")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--slow", type=float, default=15.0, help="run once if slower (s)")
    ap.add_argument("--sizes", default="100000,1000000", help="generated triangle counts")
    ap.add_argument("--cap", type=int, default=20, help="iteration cap, generated e2e")
    ap.add_argument("--no-e2e", action="store_true", help="skip the end-to-end tables")
    ap.add_argument("--params", choices=["paper", "default"], default="paper", help="end to end")
    args = ap.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",") if s]
    repeats = args.repeats
    if args.quick:
        sizes, repeats = [20000], 1

    cls, why = backends._opencl_engine_class()
    if cls is None:
        raise SystemExit(f"no OpenCL backend: {why}")
    from core.opencl.runtime import runtime

    dev = runtime().name
    load = "/".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"OpenCL device: {dev}; NumPy {np.__version__}; median of {repeats} runs")
    print(f"{time.strftime('%Y-%m-%d %H:%M')}; load average {load} on {os.cpu_count()} CPUs\n")
    p, f = load_mesh("quad_hole")  # build the kernels outside the timings (once per process)
    untangle_and_smooth(p, f, params=EEGTParams(max_untangle_iterations=1), backend="opencl")

    generated = {f"square {n // 1000}k": jittered_square(n) for n in sizes}
    if not args.no_e2e:
        e2e = EEGTParams.paper() if args.params == "paper" else EEGTParams()
        print(f"End to end, {args.params} parameters (seconds; ns per element per iteration):\n")
        print(
            "| mesh | faces | iterations numpy | opencl | numpy s | opencl s | speed-up | "
            "numpy ns | opencl ns | max diff | inverted | q_avg |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for name in SHARED if not args.quick else SHARED[:2]:
            p, f = load_mesh(name)
            print(end_to_end(name, p, f, e2e, repeats, args.slow), flush=True)
        capped = e2e.with_(max_untangle_iterations=args.cap, max_smooth_iterations=args.cap)
        for name, (p, f) in generated.items():
            row = end_to_end(f"{name} (cap {args.cap})", p, f, capped, repeats, args.slow)
            print(row, flush=True)
        print()

    shared = SHARED + SLOW_E2E if not args.quick else SHARED[:2]
    meshes = [(name, *load_mesh(name)) for name in shared]
    meshes += [(name, p, f) for name, (p, f) in generated.items()]
    for refresh in (10, 1):
        params = EEGTParams(distance_refresh=refresh)
        print(
            f"\nPer iteration, distance refresh every {refresh} (one untangling step after 2 "
            "warm-up steps):\n"
        )
        print(
            "| mesh | faces | numpy set-up s | opencl set-up s | numpy ms | opencl ms | "
            "numpy ns/el | opencl ns/el | speed-up |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        for name, p, f in meshes:
            steps = 10 if refresh > 1 or f.n_faces < 300_000 else 3
            print(per_iteration(name, p, f, repeats, steps, params), flush=True)

    load = "/".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"\n{time.strftime('%Y-%m-%d %H:%M')}; load average at the end {load}")


if __name__ == "__main__":
    main()
