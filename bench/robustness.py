"""Robustness: untangling success over runs with tiny random perturbations of interior nodes.

naca_deform's untangling is chaotic under round-off (docs/usage.md: round-off changes the
iteration count): each run adds Gaussian noise of 1e-9 of the domain size to the free nodes.
Prints one markdown row per (mesh, parameters).
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import numpy as np

from core import EEGTParams, free_nodes, untangle_and_smooth
from core.mesh.obj_io import read_obj

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"


def robustness(name: str, params: EEGTParams, runs: int, label: str) -> None:
    v, f = read_obj(DATA / f"{name}.obj")
    p = v[:, :2].copy()
    free = free_nodes(len(p), f)
    size = float(np.ptp(p, axis=0).max())
    ok, qmin, qavg, secs = 0, [], [], []
    for seed in range(runs):
        rng = np.random.default_rng(seed)
        q = p.copy()
        q[free] += 1e-9 * size * rng.normal(size=(int(free.sum()), 2))
        r = untangle_and_smooth(q, f, params=params)
        ok += r.after.n_inverted == 0
        qmin.append(r.after.q_min)
        qavg.append(r.after.q_avg)
        secs.append(r.seconds)
    print(f"| {name} | {label} | {ok}/{runs} | {min(qmin):.3f}-{max(qmin):.3f} | "
          f"{min(qavg):.3f}-{max(qavg):.3f} | {statistics.median(secs):.2f} / {max(secs):.2f} |",
          flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--paper", action="store_true", help="also the paper's parameters (slow)")
    args = ap.parse_args()
    print("| mesh | parameters | untangled | q_min range | q_avg range | seconds median / max |")
    print("|---|---|---|---|---|---|")
    for name in ("naca_deform", "two_holes_twist"):
        robustness(name, EEGTParams(), args.runs, "defaults")
    if args.paper:
        robustness("naca_deform", EEGTParams.paper().with_(max_untangle_iterations=2000),
                   args.runs, "paper, max 2000 untangle iterations")


if __name__ == "__main__":
    main()
