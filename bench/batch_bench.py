"""Batch benchmark in a real Blender: many generated meshes through the ``eegt`` command.

Modes, each on the same files: a plain shell loop of single-file ``blender -b -c eegt`` calls,
the batch with ``--jobs 1`` and ``--jobs 2``, and ``--dask local:2``, each also with
``--files-per-worker 20`` (one Blender start-up per 20 files); plus the fixed cost of one
Blender process (start with the extension, parse, quit). Every mode's outputs must be
byte-identical to the loop's. Prints a markdown table with the load average around each mode
(the machine may be shared: repeat when it was busy).

Runs inside the e2e root (Blender 4.3.2); ``bench/batch_bench.sh`` drives it, one mode per
hold of the root's lock:

    python3 -m bench.batch_bench prepare --files 200     # extension, meshes, start-up cost
    python3 -m bench.batch_bench mode loop               # ... jobs1, jobs2, dask2, jobs2_k
    python3 -m bench.batch_bench memory                  # peak memory of one worker
    python3 -m bench.batch_bench table
"""

from __future__ import annotations

import argparse
import glob
import hashlib
import json
import os
import shutil
import statistics
import subprocess
import sys
import time

import numpy as np

from bench.meshgen import jittered_square

WORK = os.environ.get("EEGT_BATCH_BENCH", "/tmp/eegt-batch-bench")
HOME = f"{WORK}/home"
IN, RESULTS = f"{WORK}/in", f"{WORK}/results"
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
K = 20  # --files-per-worker of the *_k modes
MODES = {
    "loop": "shell loop of single-file calls",
    "jobs1": "batch `--jobs 1`",
    "jobs2": "batch `--jobs 2`",
    "dask2": "batch `--dask local:2`",
    "jobs1_k": f"batch `--jobs 1 --files-per-worker {K}`",
    "jobs2_k": f"batch `--jobs 2 --files-per-worker {K}`",
    "dask2_k": f"batch `--dask local:2 --files-per-worker {K}`",
}
FLAGS = {"jobs1": ["--jobs", "1"], "jobs2": ["--jobs", "2"], "dask2": ["--dask", "local:2"]}


def env() -> dict[str, str]:
    return dict(os.environ, HOME=HOME, BLENDER_USER_RESOURCES=f"{HOME}/blender")


def run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, env=env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                          text=True, errors="replace", **kw)


def write_obj(path: str, pts: np.ndarray, tris: np.ndarray) -> None:
    with open(path, "w") as fh:
        fh.write("".join(f"v {x:.9g} {y:.9g} 0\n" for x, y in pts))
        fh.write("".join(f"f {a} {b} {c}\n" for a, b, c in tris + 1))


def prepare(n_files: int, lo: int, hi: int, startups: int) -> None:
    """Install the extension into a sandboxed user folder, generate the meshes, time the
    start-up of one Blender process with the extension."""
    shutil.rmtree(WORK, ignore_errors=True)
    os.makedirs(IN)
    os.makedirs(RESULTS)
    os.makedirs(HOME)
    dist = f"{WORK}/dist"
    os.makedirs(dist)
    p = run(["blender", "--command", "extension", "build", "--source-dir", REPO,
             "--output-dir", dist])
    zips = glob.glob(f"{dist}/*.zip")
    if p.returncode or len(zips) != 1:
        sys.exit(f"extension build failed: {p.stdout[-2000:]}")
    p = run(["blender", "--command", "extension", "install-file", "-r", "user_default", "-e",
             zips[0]])
    if p.returncode:
        sys.exit(f"extension install failed: {p.stdout[-2000:]}")
    rng = np.random.default_rng(2024)
    sizes = rng.integers(lo, hi + 1, n_files)
    faces = []
    for i, n in enumerate(sizes):
        pts, fs = jittered_square(int(n), jitter=0.45, seed=i)
        tris = fs.indices.reshape(-1, 3)  # all triangles
        write_obj(f"{IN}/mesh_{i:04d}.obj", pts, tris)
        faces.append(int(tris.shape[0]))
    times = []
    for _ in range(startups):
        t = time.perf_counter()
        p = run(["blender", "-b", "-c", "eegt", "--help"])
        times.append(time.perf_counter() - t)
        if p.returncode:
            sys.exit(f"blender -b -c eegt --help failed: {p.stdout[-2000:]}")
    info = {"files": n_files, "faces_min": min(faces), "faces_max": max(faces),
            "faces_total": sum(faces), "startup_s": times,
            "blender": run(["blender", "--version"]).stdout.splitlines()[0],
            "cpus": os.cpu_count()}
    with open(f"{RESULTS}/prepare.json", "w") as fh:
        json.dump(info, fh, indent=1)
    print(f"{n_files} meshes of {min(faces)}-{max(faces)} triangles; start-up "
          f"{statistics.median(times):.2f} s (median of {startups})")


def command(mode: str, out: str) -> list[str]:
    if mode == "loop":
        script = ('for f in "$1"/*.obj; do blender -b -c eegt "$f" -o "$2/${f##*/}" --quiet '
                  '>/dev/null 2>&1 || echo "FAILED $f $?"; done')
        return ["bash", "-c", script, "loop", IN, out]
    extra = FLAGS[mode.removesuffix("_k")]
    if mode.endswith("_k"):
        extra = [*extra, "--files-per-worker", str(K)]
    return ["blender", "-b", "-c", "eegt", IN, "-o", out, "--quiet", *extra]


def digest(folder: str) -> dict[str, str]:
    out = {}
    for path in sorted(glob.glob(f"{folder}/*.obj")):
        with open(path, "rb") as fh:
            out[os.path.basename(path)] = hashlib.sha256(fh.read()).hexdigest()
    return out


def most_at_once(files: list[dict]) -> int:
    """The most files of a batch report that ran at the same time."""
    spans = [(f["started"], f["started"] + f["seconds"]) for f in files if f.get("started")]
    return max((sum(1 for s, e in spans if s <= a + 0.2 < e) for a, _ in spans), default=0)


def mode(name: str) -> None:
    """Run one mode on every file; keep its wall time, load and the outputs' hashes."""
    out = f"{WORK}/out_{name}"
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)
    load0 = os.getloadavg()
    t = time.perf_counter()
    p = run(command(name, out))
    wall = time.perf_counter() - t
    load1 = os.getloadavg()
    hashes = digest(out)
    failed = [ln for ln in p.stdout.splitlines() if ln.startswith("FAILED")]
    report = f"{out}/eegt_report.json"
    counts = per_file = at_once = None
    if os.path.exists(report):
        with open(report) as fh:
            files = json.load(fh)["files"]
        counts = {s: sum(f["status"] == s for f in files) for s in {f["status"] for f in files}}
        per_file = statistics.mean(f["seconds"] for f in files)
        at_once = most_at_once(files)
    res = {"mode": name, "wall_s": wall, "exit": p.returncode, "load_before": load0,
           "load_after": load1, "outputs": len(hashes), "hashes": hashes, "failed": failed,
           "counts": counts, "file_s": per_file, "at_once": at_once, "tail": p.stdout[-1500:]}
    with open(f"{RESULTS}/{name}.json", "w") as fh:
        json.dump(res, fh, indent=1)
    shutil.rmtree(out, ignore_errors=True)
    print(f"{name}: {wall:.1f} s, exit {p.returncode}, {len(hashes)} outputs, load "
          f"{load0[0]:.2f} -> {load1[0]:.2f}")


def memory(sizes: list[int]) -> None:
    """Peak resident memory of one worker's Blender: idle (start, parse, quit) and running
    the single-file command on generated meshes of these sizes (what --jobs N multiplies)."""
    rows = []
    probe = ("import resource, subprocess, sys; subprocess.run(sys.argv[1:], "
             "stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL); "
             "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")
    cases = [("idle: `blender -b -c eegt --help`", ["--help"])]
    for n in sizes:
        path = f"{WORK}/mem_{n}.obj"
        pts, fs = jittered_square(n, jitter=0.45, seed=7)
        write_obj(path, pts, fs.indices.reshape(-1, 3))
        cases.append((f"{fs.n_faces} triangles", [path, "-o", f"{WORK}/mem_out.obj"]))
    for label, args in cases:
        t = time.perf_counter()
        p = run([sys.executable, "-c", probe, "blender", "-b", "-c", "eegt", *args])
        rows.append({"case": label, "peak_mb": int(p.stdout.split()[-1]) / 1024,
                     "seconds": time.perf_counter() - t})
    with open(f"{RESULTS}/memory.json", "w") as fh:
        json.dump(rows, fh, indent=1)
    for r in rows:
        print(f"{r['case']}: {r['peak_mb']:.0f} MB peak, {r['seconds']:.1f} s")


def table() -> None:
    with open(f"{RESULTS}/prepare.json") as fh:
        info = json.load(fh)
    rows = {}
    for name in MODES:
        path = f"{RESULTS}/{name}.json"
        if os.path.exists(path):
            with open(path) as fh:
                rows[name] = json.load(fh)
    n = info["files"]
    start = statistics.median(info["startup_s"])
    print(f"\n{n} meshes, {info['faces_min']}-{info['faces_max']} triangles "
          f"({info['faces_total'] / n:.0f} on average), {info['blender']}, "
          f"{info['cpus']} cores\n")
    print("| mode | wall (s) | s / file | files / s | vs shell loop | outputs | at once | "
          "one file's run (s, mean) | load 1 min (before / after) |")
    print("|---|---|---|---|---|---|---|---|---|")
    ref = rows.get("loop")
    for name, r in rows.items():
        same = "" if ref is None or name == "loop" else \
            (" identical" if r["hashes"] == ref["hashes"] else " DIFFER")
        speed = f"{ref['wall_s'] / r['wall_s']:.2f}x" if ref else ""
        own = f"{r['file_s']:.2f}" if r.get("file_s") else ""
        print(f"| {MODES[name]} | {r['wall_s']:.1f} | {r['wall_s'] / n:.2f} | "
              f"{n / r['wall_s']:.2f} | {speed} | {r['outputs']}/{n}{same} | "
              f"{r.get('at_once') or ''} | {own} | "
              f"{r['load_before'][0]:.2f} / {r['load_after'][0]:.2f} |")
    print(f"\nStart-up of one `blender -b -c eegt --help` (Blender with the extension, parse, "
          f"quit): median {start:.2f} s of {len(info['startup_s'])} "
          f"(min {min(info['startup_s']):.2f} s)")
    if ref:
        per_file = ref["wall_s"] / n
        print(f"Shell loop: {per_file:.2f} s per file, of which ~{start:.2f} s "
              f"({100 * start / per_file:.0f} %) is the start-up every file pays")
    if os.path.exists(f"{RESULTS}/memory.json"):
        with open(f"{RESULTS}/memory.json") as fh:
            mem = json.load(fh)
        print("\n| one worker Blender | peak memory (MB) | wall (s) |\n|---|---|---|")
        for r in mem:
            print(f"| {r['case']} | {r['peak_mb']:.0f} | {r['seconds']:.1f} |")
    bad = [k for k, r in rows.items() if r["exit"] != 0 or r["failed"] or r["outputs"] != n]
    if bad:
        print(f"\nWARNING: modes with failures or missing outputs: {bad}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="step", required=True)
    pp = sub.add_parser("prepare")
    pp.add_argument("--files", type=int, default=200)
    pp.add_argument("--min-faces", type=int, default=10_000)
    pp.add_argument("--max-faces", type=int, default=50_000)
    pp.add_argument("--startups", type=int, default=7)
    mp = sub.add_parser("mode")
    mp.add_argument("name", choices=list(MODES))
    me = sub.add_parser("memory")
    me.add_argument("--sizes", type=int, nargs="+", default=[50_000, 250_000, 1_000_000])
    sub.add_parser("table")
    a = ap.parse_args()
    if a.step == "prepare":
        prepare(a.files, a.min_faces, a.max_faces, a.startups)
    elif a.step == "mode":
        mode(a.name)
    elif a.step == "memory":
        memory(a.sizes)
    else:
        table()
    return 0


if __name__ == "__main__":
    sys.exit(main())
