"""Fold families side by side: ours (default parameters) and the peer untangler on every case
of the corpus (bench.corpus), one markdown table per case group (family, domain, mesher,
size) with a row per seed and the medians over seeds; then the (case, seed) pairs where ours
ends below the peer on q_min or q_avg; then ours on the repository's shared meshes
(tests/data/*.obj), the "no worse than this release" check against an earlier --json.

The peer (bench.peer_invertible_maps) needs EEGT_PEER_UNTANGLER; without it its columns read
"-" and one line says why. Both run single-threaded (our NumPy backend; the peer with
OMP_NUM_THREADS=1), one after the other in this process.

Run: `python -m bench.fold_families [--sizes 10000] [--only annulus] [--json out.json]
[--against earlier.json]`; `--held-out` runs the moved boundaries no default case has.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from bench.corpus import HELD_OUT, ROOT, load, specs
from bench.peer_invertible_maps import PeerMissing, peer_binary, run_peer
from core import EEGTParams, mesh_stats, untangle_and_smooth
from core.mesh.obj_io import read_obj

SHARED = ROOT / "tests" / "data"


def ours(points: np.ndarray, faces, fixed: np.ndarray | None, backend: str) -> dict:
    t0 = time.perf_counter()
    res = untangle_and_smooth(points, faces, fixed=fixed, params=EEGTParams(), backend=backend)
    dt = time.perf_counter() - t0
    st = mesh_stats(res.points, faces)
    return {"q_min": st.q_min, "q_avg": st.q_avg, "inv": st.n_inverted, "s": dt,
            "status": res.status}


def peer(case) -> dict | None:
    try:
        r = run_peer(case.points, case.faces, case.reference)
    except PeerMissing:
        return None
    except (RuntimeError, OSError) as exc:  # a crash or timeout of the peer: a row, not a stop
        return {"q_min": float("nan"), "q_avg": float("nan"), "inv": -1, "s": float("nan"),
                "error": str(exc)}
    return {"q_min": r.stats.q_min, "q_avg": r.stats.q_avg, "inv": r.stats.n_inverted,
            "s": r.seconds, "solve_s": r.solve_seconds, "success": r.success}


def cells(r: dict | None) -> str:
    if r is None:
        return "- | - | - | -"
    return f"{r['q_min']:.3f} | {r['q_avg']:.4f} | {r['inv']} | {r['s']:.2f}"


def median_row(rows: list[dict | None]) -> dict | None:
    rows = [r for r in rows if r is not None]
    if not rows:
        return None
    return {k: statistics.median(r[k] for r in rows) for k in ("q_min", "q_avg", "inv", "s")}


def group_name(spec) -> str:
    """family-domain-mesher-size: the case name without its seed and per-seed params."""
    return f"{spec.family}-{spec.domain}-{spec.mesher}-{spec.n}"


HEAD = ("| seed | params | faces | inverted in | ours q_min | ours q_avg | ours inv | ours s "
        "| peer q_min | peer q_avg | peer inv | peer s |\n|---|---|---|---|---|---|---|---|---|"
        "---|---|---|")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000])
    ap.add_argument("--only", default="", help="only cases whose name contains this")
    ap.add_argument("--backend", default="numpy")
    ap.add_argument("--held-out", action="store_true",
                    help="the held-out moved boundaries (bench.corpus.HELD_OUT) instead")
    ap.add_argument("--no-shared", action="store_true", help="skip the shared meshes")
    ap.add_argument("--json", type=Path, help="write every row here")
    ap.add_argument("--against", type=Path, help="an earlier --json: flag shared meshes worse now")
    args = ap.parse_args()
    try:
        exe = str(peer_binary())
        note = f"peer: {exe} (OMP_NUM_THREADS=1)"
    except PeerMissing as exc:
        note = str(exc)
    print(f"{platform.machine()}, {os.cpu_count()} cores (shared machine), load "
          f"{os.getloadavg()[0]:.1f}; ours: default parameters, backend {args.backend}; {note}")
    groups: dict[str, list] = {}
    for spec in HELD_OUT if args.held_out else specs(tuple(args.sizes)):
        if args.only in spec.name:
            groups.setdefault(group_name(spec), []).append(spec)
    rows, worse = [], []
    for gname, group in groups.items():
        print(f"\n### {gname}\n\n{HEAD}")
        ours_rows, peer_rows = [], []
        for spec in group:
            case = load(spec)
            before = mesh_stats(case.points, case.faces)
            o = ours(case.points, case.faces, case.fixed, args.backend)
            p = peer(case)
            ours_rows.append(o)
            peer_rows.append(p)
            params = ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                               for k, v in case.params.items())
            print(f"| {case.seed} | {params} | {case.n_faces} | {before.n_inverted} | "
                  f"{cells(o)} | {cells(p)} |", flush=True)
            rows.append({"case": case.name, "group": gname, "seed": case.seed,
                         "faces": case.n_faces, "inverted_in": before.n_inverted,
                         "ours": o, "peer": p})
            if p is not None and not np.isnan(p["q_min"]) and p["inv"] == 0 and (
                    o["inv"] > 0 or o["q_min"] < p["q_min"] or o["q_avg"] < p["q_avg"]):
                worse.append(f"{gname} s{case.seed}")
        print(f"| median | | | | {cells(median_row(ours_rows))} | {cells(median_row(peer_rows))} |")
    print("\nours below the peer on q_min or q_avg (or not untangled where it is): "
          + (", ".join(worse) if worse else "none"))
    shared = []
    if not args.no_shared:
        earlier = {}
        if args.against:
            earlier = {r["case"]: r["ours"] for r in json.loads(args.against.read_text())
                       if r.get("group") == "shared"}
        print("\n### shared meshes (tests/data), ours\n\n| mesh | faces | inverted in | q_min | "
              "q_avg | inverted | s | vs --against |\n|---|---|---|---|---|---|---|---|")
        for path in sorted(SHARED.glob("*.obj")):
            pts, fs = read_obj(path)
            if pts.shape[1] > 2 and np.ptp(pts[:, 2]) > 0:
                print(f"| {path.name} | {fs.n_faces} | not planar in z: the 3D path, skipped "
                      "| | | | | |")
                continue
            pts = np.ascontiguousarray(pts[:, :2])
            before = mesh_stats(pts, fs)
            o = ours(pts, fs, None, args.backend)
            e = earlier.get(path.name)
            verdict = "-" if e is None else (
                "worse" if (o["inv"], -o["q_min"], -o["q_avg"]) > (e["inv"], -e["q_min"], -e["q_avg"])
                else "no worse")
            print(f"| {path.name} | {fs.n_faces} | {before.n_inverted} | {o['q_min']:.4f} | "
                  f"{o['q_avg']:.4f} | {o['inv']} | {o['s']:.2f} | {verdict} |", flush=True)
            shared.append({"case": path.name, "group": "shared", "ours": o})
    if args.json:
        args.json.write_text(json.dumps(rows + shared, indent=1))


if __name__ == "__main__":
    main()
