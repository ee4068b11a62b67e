"""Scale benchmark: generated tangled meshes from 100k to 4M elements, NumPy and auto.

Each run is a child process (its own peak RSS) that loads a cached mesh (build/meshes/*.npz,
made once by `bench.meshgen`) and runs `untangle_and_smooth` with default parameters.
Prints a markdown table (elements, backend, seconds, q_min, q_avg, inverted, iterations, peak
RSS, nanoseconds per element) and, with --plot, a picture of time against size beside the
peer's measured point (the single-threaded foldover-free untangler: 45 s at 1M triangles,
measured earlier on this machine class, not rerun: README.md, "Results").

Run: `make bench` (or `python -m bench.scale [--sizes 100000 1000000] [--plot docs/scale.png]`).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "build" / "meshes"
PEER = {"label": "foldover-free untangler (C++, 1 thread; quoted)", "elements": 1_058_228,
        "seconds": 45.0, "q_min": 0.654, "q_avg": 0.968}


MESH_TAG = {"tri": "shake25", "tri-deg3": "shake35", "quad": "grid"}  # in the cache names


def mesh_file(kind: str, n: int) -> Path:
    """The cached mesh `kind` of about n elements, made on first use: 'tri' (a mesher-like
    Delaunay mesh, interior nodes of degree 4 to 8), 'tri-deg3' (its lattice shaken more
    before the triangulation: nodes of degree 3 to 9, whose degree-3 nodes cap q_min near
    0.60) or 'quad' (a grid)."""
    from bench.meshgen import holed_quads, holed_square

    path = CACHE / f"{kind}_{n}_{MESH_TAG[kind]}.npz"
    if not path.exists():
        CACHE.mkdir(parents=True, exist_ok=True)
        if kind == "quad":
            p, fs = holed_quads(n)
        else:
            p, fs = holed_square(n, **({"shake": 0.35, "jitter": 0.47} if kind == "tri-deg3"
                                       else {}))
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, points=p, offsets=fs.offsets, indices=fs.indices)
        tmp.replace(path)
    return path


def child(path: str, backend: str, params: str) -> None:
    """One run; prints a JSON line with its numbers (peak RSS of this process included)."""
    from core import EEGTParams, faces_from_csr, untangle_and_smooth

    data = np.load(path)
    offsets = data["offsets"]
    fs = faces_from_csr(offsets[:-1], np.diff(offsets), data["indices"])
    p = data["points"]
    prm = EEGTParams(**json.loads(params))
    t0 = time.perf_counter()
    c0 = time.process_time()
    res = untangle_and_smooth(p, fs, params=prm, backend=backend)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(json.dumps({
        "elements": fs.n_faces, "seconds": wall, "cpu": cpu, "status": res.status,
        "q_min": res.after.q_min, "q_avg": res.after.q_avg, "inverted": res.after.n_inverted,
        "inverted_in": res.before.n_inverted, "untangle": res.untangle_iterations,
        "global": res.global_iterations, "smooth": res.smooth_iterations,
        "backend": res.backend, "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }))


def run(kind: str, n: int, backend: str, params: dict, repeats: int) -> dict:
    path = mesh_file(kind, n)
    runs = []
    for _ in range(repeats):
        out = subprocess.run(
            [sys.executable, "-m", "bench.scale", "--child", str(path), backend, json.dumps(params)],
            cwd=ROOT, check=True, capture_output=True, text=True,
        ).stdout
        runs.append(json.loads(out.strip().splitlines()[-1]))
    best = dict(runs[0])
    best["seconds"] = statistics.median(r["seconds"] for r in runs)
    best["cpu"] = statistics.median(r["cpu"] for r in runs)
    best["rss_mb"] = max(r["rss_mb"] for r in runs)
    best["kind"], best["repeats"] = kind, repeats
    return best


def row(r: dict) -> str:
    ns = r["seconds"] / r["elements"] * 1e9
    its = f"{r['untangle']} / {r['global']} / {r['smooth']}"
    return (f"| {r['elements']:,} {r['kind']} | {r['backend_asked']} | {r['seconds']:.2f} | "
            f"{r['q_min']:.3f} | {r['q_avg']:.4f} | {r['inverted_in']} -> {r['inverted']} | "
            f"{its} | {r['rss_mb']:.0f} | {ns:.0f} |")


def plot(results: list[dict], path: Path, note: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=110)
    for backend, style in (("numpy", "o-"), ("auto", "s-")):
        pts = sorted((r["elements"], r["seconds"]) for r in results
                     if r["backend_asked"] == backend and r["kind"] == "tri")
        if pts:
            ax.plot(*zip(*pts, strict=True), style, label=f"eegt_blender, {backend}")
    ax.plot([PEER["elements"]], [PEER["seconds"]], "r*", markersize=12, label=PEER["label"])
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("triangles")
    ax.set_ylabel("seconds (untangle + smooth, default parameters)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    title = "Tangled square with three holes (5 % inverted)"
    ax.set_title(title + (f"\n{note}" if note else ""), fontsize=9)
    fig.tight_layout()
    fig.savefig(path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100_000, 1_000_000, 4_000_000])
    ap.add_argument("--quads", type=int, nargs="*", default=[1_000_000])
    ap.add_argument("--deg3", type=int, nargs="*", default=[1_000_000],
                    help="sizes of the mesh with degree-3 nodes (q_min capped near 0.60)")
    ap.add_argument("--backends", nargs="+", default=["numpy", "auto"])
    ap.add_argument("--params", default="{}", help="EEGTParams fields as JSON")
    ap.add_argument("--plot", type=Path, help="write the time-against-size picture here")
    ap.add_argument("--json", type=Path, help="write the raw results here")
    ap.add_argument("--note", default="", help="a second title line for the plot")
    ap.add_argument("--replot", type=Path, nargs="+", metavar="JSON",
                    help="no runs: print and plot (with --plot) the results of earlier --json files")
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(*args.child)
        return
    if args.replot:
        results = [r for path in args.replot for r in json.loads(path.read_text())]
        for r in results:
            print(row(r))
        if args.plot:
            plot(results, args.plot, args.note)
        return
    params = json.loads(args.params)
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}; NumPy {np.__version__}; params {params or 'defaults'}")
    print("\n| elements | backend | seconds | q_min | q_avg | inverted | iterations "
          "(untangle / global / smooth) | peak RSS MB | ns/element |")
    print("|---|---|---|---|---|---|---|---|---|")
    results = []
    jobs = [("tri", n) for n in args.sizes] + [("tri-deg3", n) for n in args.deg3] + \
        [("quad", n) for n in args.quads]
    for kind, n in jobs:
        for backend in args.backends:
            r = run(kind, n, backend, params, 3 if n <= 1_000_000 and kind != "quad" else 1)
            r["backend_asked"] = backend
            results.append(r)
            print(row(r), flush=True)
    print(f"\npeer: {PEER['label']}: {PEER['seconds']:.0f} s, q_min {PEER['q_min']}, "
          f"q_avg {PEER['q_avg']} at {PEER['elements']:,} triangles")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    if args.plot:
        plot(results, args.plot, args.note)


if __name__ == "__main__":
    main()
