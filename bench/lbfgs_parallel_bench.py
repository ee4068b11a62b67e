"""Per-iteration time of the global stage's L-BFGS: host NumPy, the single-work-item OpenCL
kernel and the parallel kernels, side by side on generated meshes (bench.meshgen.holed_square).

Run `python -m bench.lbfgs_parallel_bench` (`--sizes 10000 100000` to choose, `--repeats`,
`--only numpy,parallel`, `EEGT_OPENCL_DEVICE=...` for another device). Three stages:
- untangle: the foldover-free energy on the tangled mesh (guard off, the first eps of
  `untangle_global`);
- polish: the same energy on a valid mesh (the mesh's lattice before the jitter), guarded,
  eps at its floor;
- lift: the lift energy on that valid mesh (floor = its q_min), guarded.
One iteration = the two-loop direction, the line search (its energy evaluations), the
gradient at the accepted point and the memory update. Each time is the median over
`--repeats` of (T(long) - T(short)) / (long - short iterations), rel_tol 0 so that the
runs stop only at the cap or (untangle) when the mesh becomes valid; the iterations are
printed (the same for every solver: checked with the end points); the solvers' tables are
built before.
Also checks that the three solvers end at the same point (bit for bit), and prints the
process CPU time per iteration (every thread, the device's included): on a machine shared
with other jobs it tells the work apart from the waiting (wall = CPU / cores when the
device's threads have the cores to themselves).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import time

import numpy as np

from core.optimize.energy import FoldoverEnergy, LiftEnergy
from core.optimize.solver import lbfgs
from core.optimize.stages import EPS_MIN
from core.optimize.state import State
from core.run.pipeline import free_nodes

from .meshgen import holed_square


def solvers(only: set[str]) -> dict:
    out = {"numpy": lbfgs}
    try:
        from core.optimize.solver_opencl import OpenCLLbfgs
        from core.optimize.solver_parallel import ParallelLbfgs

        out["single"] = OpenCLLbfgs()
        out["parallel"] = ParallelLbfgs()
        out["device"] = out["parallel"].device_name
    except RuntimeError as exc:  # no OpenCL device: the host column only
        print(f"(no OpenCL: {exc})")
    return {k: v for k, v in out.items() if k in only or k == "device"}


def problems(n: int):
    """(stage, energy, state, v0, eps, guard) for the three stages on a mesh of ~n triangles."""
    p, fs = holed_square(n, jitter=0.47, shake=0.35)  # the mesh docs/opencl.md's table used
    p_valid, _ = holed_square(n, jitter=0.0, shake=0.35)
    groups = fs.by_arity()
    free = free_nodes(len(p), fs)
    out = []
    en = FoldoverEnergy(p, groups, free)
    st = State(p, free)
    dmin = float(np.min(en.dets(st.x, st.y)))
    eps = max(0.1 * abs(dmin), 1e-3) if dmin <= 0.0 else EPS_MIN
    out.append(("untangle", en, st, st.pack(st.x, st.y), eps, False))
    en = FoldoverEnergy(p_valid, groups, free)
    st = State(p_valid, free)
    assert en.n_inverted(st.x, st.y) == 0
    out.append(("polish", en, st, st.pack(st.x, st.y), EPS_MIN, True))
    en = LiftEnergy(p_valid, groups, free)
    st = State(p_valid, free)
    en.qc = float(en.element_quality(st.x, st.y).min())
    out.append(("lift", en, st, st.pack(st.x, st.y), EPS_MIN, True))
    return fs.n_faces, out


def cpu_seconds() -> float:
    """CPU time of this process, all threads (the pocl device's included)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def per_iteration(run, en, st, v0, eps, guard, short: int, long: int, repeats: int):
    """(median wall seconds, median CPU seconds per iteration, end point of the long run).
    A stage that stops before `long` iterations (untangling reaches a valid mesh) is timed
    over (its iterations // 3, its iterations)."""
    _, its = run(en, st, v0, eps, max_it=long, guard=guard, rel_tol=0.0)  # tables, builds
    if its < long:
        short, long = its // 3, its
    wall, cpu, end = [], [], None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), cpu_seconds()
        _, its_s = run(en, st, v0, eps, max_it=short, guard=guard, rel_tol=0.0)
        t1, c1 = time.perf_counter(), cpu_seconds()
        end, its_l = run(en, st, v0, eps, max_it=long, guard=guard, rel_tol=0.0)
        t2, c2 = time.perf_counter(), cpu_seconds()
        if its_l <= its_s:
            raise RuntimeError(f"stopped early: {its_s}, {its_l} iterations")
        wall.append(((t2 - t1) - (t1 - t0)) / (its_l - its_s))
        cpu.append(((c2 - c1) - (c1 - c0)) / (its_l - its_s))
    return statistics.median(wall), statistics.median(cpu), (end, its_s, its_l)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--iters", type=int, nargs=2, default=[10, 30], metavar=("SHORT", "LONG"))
    ap.add_argument("--only", default="numpy,single,parallel")
    args = ap.parse_args()
    sv = solvers(set(args.only.split(",")))
    names = [k for k in ("numpy", "single", "parallel") if k in sv]
    print(f"device: {sv.get('device', 'none')}; load before: "
          + "/".join(f"{x:.2f}" for x in os.getloadavg()))
    head = "| triangles | stage | corners | iterations | " + " | ".join(f"{k} ms" for k in names)
    head += " | parallel vs numpy | parallel vs single | CPU ms " + "/".join(names)
    head += " | same point |"
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for n in args.sizes:
        n_faces, probs = problems(n)
        for stage, en, st, v0, eps, guard in probs:
            res, cpu, ends = {}, {}, []
            for k in names:
                res[k], cpu[k], end = per_iteration(sv[k], en, st, v0, eps, guard, *args.iters,
                                                    args.repeats)
                ends.append(end)
            same = all(np.array_equal(ends[0][0], e[0]) and ends[0][1:] == e[1:] for e in ends)
            its = f"{ends[0][1]}/{ends[0][2]}"
            ms = " | ".join(f"{1e3 * res[k]:.2f}" for k in names)
            r_np = f"{res['numpy'] / res['parallel']:.1f}x" if {"numpy", "parallel"} <= res.keys() else "-"
            r_si = f"{res['single'] / res['parallel']:.1f}x" if {"single", "parallel"} <= res.keys() else "-"
            c_ms = "/".join(f"{1e3 * cpu[k]:.1f}" for k in names)
            print(f"| {n_faces} | {stage} | {en.i0.size} | {its} | {ms} | {r_np} | {r_si} | {c_ms} | {same} |",
                  flush=True)
        for k in names:
            if hasattr(sv[k], "release"):
                sv[k].release()
    print("load after: " + "/".join(f"{x:.2f}" for x in os.getloadavg()))


if __name__ == "__main__":
    main()
