"""Scale case from a mesher, with a phase breakdown: a Triangle quality mesh of the unit
square with three holes (min angle 30 degrees, about 1.06M triangles; bench.corpus's
`scale_specs`), 5 % of its faces inverted by node jitter, boundary fixed.

Each run is a child process (its own peak RSS) running `untangle_and_smooth` with default
parameters. It prints the totals (seconds, q_min, q_avg, inverted, peak RSS) per backend and,
per run, a phase table: set-up, EEGT untangling iterations, the local optimization around
what EEGT leaves, the whole-mesh polish (the lift's first run) and each lift round, EEGT
smoothing, and the hand-back; time and quality after each. The phases come from the progress
callback and from timing the pipeline's calls of `untangle_global` and `lift_min_quality`
(wrapped in the child only).

Run: `python -m bench.scale_mesher [--n 1060000] [--backends numpy auto] [--peer]`
(--peer also runs the peer untangler, see bench.peer_invertible_maps).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time

import numpy as np

from bench.corpus import ROOT, load, scale_specs


def child(n: int, backend: str) -> None:
    """One run with phase timing; prints one JSON line."""
    import core.run.pipeline as pipeline
    from core import EEGTParams, mesh_stats, untangle_and_smooth

    case = load(scale_specs((n,))[0])
    events: list[dict] = []  # {"t", "kind", ...}: progress reports and wrapped calls
    t0 = time.perf_counter()

    def now() -> float:
        return time.perf_counter() - t0

    def progress(it, phase, s) -> None:
        events.append({"t": now(), "kind": phase, "it": it, "inv": s.n_inverted,
                       "q_min": s.q_min, "q_avg": s.q_avg})

    real_global, real_lift = pipeline.untangle_global, pipeline.lift_min_quality

    def timed_global(*a, **k):
        start = now()
        out = real_global(*a, **k)
        info = out[1]
        events.append({"t": now(), "kind": "optimize", "start": start,
                       "it": int(info.get("iterations", 0)), "status": info.get("status"),
                       "elements": int(sum(g.shape[0] for g in a[1].values()))})
        return out

    def timed_lift(*a, **k):
        start = now()
        ends: dict[int, float] = {}
        inner = k.get("progress")

        def relay(iterations, r, q_min, q_avg):
            ends[r] = now()
            return None if inner is None else inner(iterations, r, q_min, q_avg)

        k["progress"] = relay
        out = real_lift(*a, **k)
        info = out[1]
        prev = start
        for r, (qm, qa) in enumerate(info.get("trail", [])):
            end = ends.get(r, now())
            events.append({"t": end, "kind": "polish" if r == 0 else f"lift round {r}",
                           "start": prev, "q_min": qm, "q_avg": qa,
                           "kept": r == 0 or r <= info.get("rounds", 0)})
            prev = end
        return out

    pipeline.untangle_global, pipeline.lift_min_quality = timed_global, timed_lift
    t0 = time.perf_counter()
    res = untangle_and_smooth(case.points, case.faces, fixed=case.fixed, params=EEGTParams(),
                              backend=backend, progress=progress)
    wall = now()
    st = mesh_stats(res.points, case.faces)
    print(json.dumps({
        "elements": case.n_faces, "backend": res.backend, "seconds": wall, "q_min": st.q_min,
        "q_avg": st.q_avg, "inverted": st.n_inverted, "inverted_in": res.before.n_inverted,
        "untangle": res.untangle_iterations, "global": res.global_iterations,
        "smooth": res.smooth_iterations, "events": events,
        "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def phases(r: dict) -> list[tuple[str, float, str, str]]:
    """(phase, seconds, iterations, 'inverted / q_min / q_avg after') rows of one run."""
    ev = r["events"]
    out: list[tuple[str, float, str, str]] = []
    first = ev[0]["t"] if ev else r["seconds"]
    out.append(("set-up (to the first report)", first, "", ""))
    last = first

    def after(e: dict) -> str:
        return f"{e.get('inv', 0)} / {e['q_min']:.4f} / {e['q_avg']:.4f}"

    for kind in ("untangle",):
        run = [e for e in ev if e["kind"] == kind and e["it"] > 0]
        if run:
            out.append((f"EEGT {kind} iterations", run[-1]["t"] - last, str(len(run)),
                        after(run[-1])))
            last = run[-1]["t"]
    for e in ev:
        if e["kind"] == "optimize":
            out.append((f"optimization ({e['elements']:,} elements, {e['status']})",
                        e["t"] - e["start"], str(e["it"]), ""))
            last = e["t"]
        elif e["kind"] == "polish" or e["kind"].startswith("lift"):
            name = e["kind"] + ("" if e["kept"] else " (rejected)")
            out.append((name, e["t"] - e["start"], "", after(e)))
            last = e["t"]
    sm = [e for e in ev if e["kind"] == "smooth" and e["t"] >= last]
    if sm:
        out.append(("EEGT smoothing iterations (engine restart included)", sm[-1]["t"] - last, str(len(sm)), after(sm[-1])))
        last = sm[-1]["t"]
    out.append(("hand-back (best iterate, result)", r["seconds"] - last, "", ""))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_060_000, help="about this many triangles")
    ap.add_argument("--backends", nargs="+", default=["numpy", "auto"])
    ap.add_argument("--peer", action="store_true", help="also run the peer untangler")
    ap.add_argument("--json", help="write the raw results here")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(int(args.child[0]), args.child[1])
        return
    spec = scale_specs((args.n,))[0]
    t = time.perf_counter()
    case = load(spec)
    print(f"{platform.machine()}, {os.cpu_count()} cores (shared machine), load "
          f"{os.getloadavg()[0]:.1f}; NumPy {np.__version__}; case {spec.name}: "
          f"{case.n_faces:,} faces (loaded/made in {time.perf_counter() - t:.1f} s)")
    results = []
    for backend in args.backends:
        out = subprocess.run([sys.executable, "-m", "bench.scale_mesher", "--child",
                              str(args.n), backend], cwd=ROOT, check=True,
                             capture_output=True, text=True).stdout
        r = json.loads(out.strip().splitlines()[-1])
        r["backend_asked"] = backend
        results.append(r)
    print("\n| backend | seconds | q_min | q_avg | inverted | iterations (untangle / global / "
          "smooth) | peak RSS MB |\n|---|---|---|---|---|---|---|")
    for r in results:
        print(f"| {r['backend_asked']} ({r['backend']}) | {r['seconds']:.2f} | {r['q_min']:.4f} | "
              f"{r['q_avg']:.4f} | {r['inverted_in']} -> {r['inverted']} | {r['untangle']} / "
              f"{r['global']} / {r['smooth']} | {r['rss_mb']:.0f} |")
    for r in results:
        print(f"\n#### phases, {r['backend_asked']}\n\n| phase | seconds | iterations | "
              "after: inverted / q_min / q_avg |\n|---|---|---|---|")
        for name, sec, its, aft in phases(r):
            print(f"| {name} | {sec:.2f} | {its} | {aft} |")
    if args.peer:
        from bench.peer_invertible_maps import PeerMissing, run_peer

        try:
            p = run_peer(case.points, case.faces, case.reference)
            print(f"\npeer (1 thread): {p.seconds:.2f} s wall ({p.solve_seconds} s solve), "
                  f"q_min {p.stats.q_min:.4f}, q_avg {p.stats.q_avg:.4f}, "
                  f"inverted {p.stats.n_inverted}")
        except PeerMissing as exc:
            print(f"\n{exc}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
