"""Fuzz the core on thousands of small random polygon meshes (not part of CI).

    .venv/bin/python -m bench.fuzz --n 10000 [--seed 0] [--backends numpy,opencl] [--workers 2]
    .venv/bin/python -m bench.fuzz --replay out/fuzz_failures/case_000123.npz

Each case is a small planar mesh (10-200 nodes: jittered grids of triangles / quads / mixed
faces, polar disks and rings, honeycomb patches, random merges of neighbouring faces into
n-gons up to 8 corners), valid or tangled (jitter, pushed nodes, coincident nodes, a twist),
some nodes pinned, rotated, sometimes mirrored (clockwise input), scaled by 1e-300 .. 1e300
and translated, with its nodes and faces renumbered, run with random parameters in their
valid ranges (sometimes `EEGTParams.paper()`). Invariants checked on every backend:

    error       no exception but ValueError, and a ValueError's message is one line
    nan         no NaN or infinity in the output points or the stats
    fixed       fixed (boundary + pinned) nodes bit-identical to the input
    worse       result stats not worse than the input's (after == before or better)
    determinism the same run twice gives identical bits (every --det-every'th case)
    units       the mesh scaled by a power of two 2^k gives the result scaled by 2^k, bit
                for bit, and the same status and iteration counts (the same cases)
    parity      OpenCL == NumPy bit for bit (points, status, stats, iteration counts,
                or the same ValueError)

Failing cases go to --out (default out/fuzz_failures/case_NNNNNN.npz); `--replay FILE` runs
one again and prints what each backend gives. Case i of seed s is the same mesh on every
machine (`np.random.default_rng([s, i])`), so `--case I` re-runs one by number too.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import re
import sys
import time
import traceback
from collections import Counter, defaultdict
from itertools import pairwise
from pathlib import Path

import numpy as np

from core import EEGTParams, untangle_and_smooth
from core.mesh.faces import as_faceset
from core.mesh.topology import boundary_nodes
from core.params import UNTANGLE_METHODS

INVARIANTS = ("error", "nan", "fixed", "worse", "determinism", "units", "parity")
DEFAULT_OUT = Path("out/fuzz_failures")


# ---- meshes ----------------------------------------------------------------------------


def _grid(rng) -> tuple[np.ndarray, list[list[int]]]:
    """Jittered-grid topology: triangles (random diagonals), quads, or a mix with some
    pairs of quads merged into hexagons."""
    while True:
        m, n = (int(v) for v in rng.integers(2, 14, 2))
        if 10 <= (m + 1) * (n + 1) <= 200:
            break
    style = rng.choice(["tri", "quad", "mixed"])
    ys, xs = np.mgrid[0 : m + 1, 0 : n + 1]
    pts = np.column_stack([xs.ravel(), ys.ravel()]).astype(np.float64)
    faces: list[list[int]] = []
    for i in range(m):
        j = 0
        while j < n:
            a = i * (n + 1) + j
            b, c, d = a + 1, a + n + 2, a + n + 1
            kind = {"tri": 1, "quad": 0}.get(style, int(rng.integers(0, 3)))
            if kind == 2 and j + 1 < n:
                faces.append([a, b, b + 1, c + 1, c, d])
                j += 2
                continue
            if kind == 0 or kind == 2:
                faces.append([a, b, c, d])
            elif rng.random() < 0.5:
                faces += [[a, b, c], [a, c, d]]
            else:
                faces += [[a, b, d], [b, c, d]]
            j += 1
    return pts, faces


def _polar(rng) -> tuple[np.ndarray, list[list[int]]]:
    """A disk (centre fan of triangles, or a central k-gon) or an annulus (a hole), rings of
    quads, some split into triangles; rings may be twisted."""
    k = int(rng.integers(3, 17))
    rings = int(rng.integers(1, 7))
    while rings * k + 1 > 200 or rings * k + 1 < 10:
        k = int(rng.integers(3, 17))
        rings = int(rng.integers(1, 7))
    center = rng.choice(["fan", "ngon", "hole"]) if k <= 8 else rng.choice(["fan", "hole"])
    if center != "fan" and rings == 1:
        rings = 2
    twist = rng.uniform(-0.5, 0.5) * 2 * np.pi / k if rng.random() < 0.3 else 0.0
    pts = [[0.0, 0.0]] if center == "fan" else []
    first = len(pts)
    for i in range(rings):
        t = 2 * np.pi * np.arange(k) / k + i * twist
        pts += np.column_stack([(i + 1) * np.cos(t), (i + 1) * np.sin(t)]).tolist()

    def ring(i, s):
        return first + i * k + s % k

    faces: list[list[int]] = []
    if center == "fan":
        faces += [[0, ring(0, s), ring(0, s + 1)] for s in range(k)]
    elif center == "ngon":
        faces.append([ring(0, s) for s in range(k)])
    for i in range(rings - 1):
        for s in range(k):
            a, b, c, d = ring(i, s), ring(i + 1, s), ring(i + 1, s + 1), ring(i, s + 1)
            if rng.random() < 0.3:
                faces += [[a, b, c], [a, c, d]]
            else:
                faces.append([a, b, c, d])
    return np.array(pts, dtype=np.float64), faces


def _honeycomb(rng) -> tuple[np.ndarray, list[list[int]]]:
    """A patch of hexagons (radius 1-3 cells), some cut into two quads or a triangle fan."""
    radius = int(rng.integers(1, 4))
    keys: dict[tuple[int, int], int] = {}
    pts: list[tuple[float, float]] = []
    faces: list[list[int]] = []
    for q in range(-radius, radius + 1):
        for r in range(-radius, radius + 1):
            if abs(q + r) > radius:
                continue
            cx, cy = math.sqrt(3.0) * (q + 0.5 * r), 1.5 * r
            hexa = []
            for i in range(6):
                t = math.radians(30 + 60 * i)
                x, y = cx + math.cos(t), cy + math.sin(t)
                key = (round(x * 1e6), round(y * 1e6))
                if key not in keys:
                    keys[key] = len(pts)
                    pts.append((x, y))
                hexa.append(keys[key])
            u = rng.random()
            if u < 0.6:
                faces.append(hexa)
            elif u < 0.8:
                faces += [hexa[0:4], [*hexa[3:6], hexa[0]]]
            else:  # fan around a new centre node
                c = len(pts)
                pts.append((cx, cy))
                faces += [[c, hexa[i], hexa[(i + 1) % 6]] for i in range(6)]
    return np.array(pts, dtype=np.float64), faces


def merge_faces(rng, faces: list[list[int]], max_n: int, tries: int) -> list[list[int]]:
    """Merge random pairs of faces sharing exactly one edge into polygons of <= max_n
    corners (Voronoi-like irregular n-gons)."""
    faces = [list(f) for f in faces]
    alive = [True] * len(faces)
    for _ in range(tries):
        edges: dict[tuple[int, int], int] = {}
        for fi, f in enumerate(faces):
            if alive[fi]:
                for k in range(len(f)):
                    edges[(f[k], f[(k + 1) % len(f)])] = fi
        pairs = [(fi, edges[(v, u)], u, v) for (u, v), fi in edges.items() if (v, u) in edges]
        if not pairs:
            break
        fa, fb, u, v = pairs[int(rng.integers(len(pairs)))]
        A, B = faces[fa], faces[fb]
        if len(A) + len(B) - 2 > max_n or len(set(A) & set(B)) != 2:
            continue
        ia = A.index(v)  # A = .. u v ..: walk A from v round to u
        a_walk = A[ia:] + A[:ia]
        ib = B.index(u)  # B = .. v u ..: then B from u round to v, ends dropped
        b_walk = B[ib:] + B[:ib]
        faces[fa] = a_walk + b_walk[1:-1]
        alive[fb] = False
    return [f for f, ok in zip(faces, alive) if ok]


def _topology(rng) -> tuple[str, np.ndarray, list[list[int]]]:
    kind = str(rng.choice(["grid", "polar", "honeycomb", "merged"], p=[0.35, 0.2, 0.15, 0.3]))
    if kind == "grid":
        pts, faces = _grid(rng)
    elif kind == "polar":
        pts, faces = _polar(rng)
    elif kind == "honeycomb":
        pts, faces = _honeycomb(rng)
    else:
        pts, faces = (_grid if rng.random() < 0.7 else _polar)(rng)
        faces = merge_faces(rng, faces, int(rng.integers(5, 9)), int(rng.integers(1, len(faces) + 1)))
    return kind, pts, faces


def _edge_length(pts: np.ndarray, faces: list[list[int]]) -> float:
    return float(np.median([np.hypot(*(pts[f[1]] - pts[f[0]])) for f in faces]))


def make_case(seed: int, index: int) -> dict:
    """Case `index` of `seed`: points, faces, fixed mask (or None), params and a description."""
    rng = np.random.default_rng([seed, index])
    kind, pts, faces = _topology(rng)
    n = len(pts)
    bnd = boundary_nodes(n, faces)
    h = _edge_length(pts, faces)
    notes = [kind]
    # deform: interior jitter (small: mostly valid, large: tangled), some boundary jitter
    amp = rng.uniform(0.0, 0.3) if rng.random() < 0.5 else rng.uniform(0.3, 1.0)
    inner = np.flatnonzero(~bnd)
    pts[inner] += rng.uniform(-amp * h, amp * h, (inner.size, 2))
    if rng.random() < 0.3:
        pts[bnd] += rng.uniform(-0.1 * h, 0.1 * h, (int(bnd.sum()), 2))
        notes.append("boundary jitter")
    if inner.size and rng.random() < 0.3:  # push a few nodes far
        sel = rng.choice(inner, size=min(inner.size, int(rng.integers(1, 4))), replace=False)
        ang = rng.uniform(0, 2 * np.pi, sel.size)
        pts[sel] += rng.uniform(1, 3, (sel.size, 1)) * h * np.column_stack([np.cos(ang), np.sin(ang)])
        notes.append("pushed")
    if inner.size and rng.random() < 0.1:  # coincident nodes
        i = int(rng.choice(inner))
        nb = [v for f in faces if i in f for v in f if v != i]
        pts[i] = pts[int(rng.choice(nb))]
        notes.append("coincident")
    if inner.size and rng.random() < 0.05:  # twist the interior about the centre
        c = pts.mean(axis=0)
        t = rng.uniform(-2, 2)
        rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        pts[inner] = (pts[inner] - c) @ rot.T + c
        notes.append("twist")
    fixed = None
    if rng.random() < 0.3:
        fixed = rng.random(n) < rng.uniform(0.0, 0.3)
        if rng.random() < 0.02:
            fixed[:] = True
        notes.append("pinned")
    # renumber nodes, reorder faces, rotate each face's first corner
    if rng.random() < 0.5:
        perm = rng.permutation(n)  # new index of old node
        new = np.empty_like(pts)
        new[perm] = pts
        pts = new
        faces = [[int(perm[v]) for v in f] for f in faces]
        if fixed is not None:
            fx = np.empty_like(fixed)
            fx[perm] = fixed
            fixed = fx
    faces = [faces[i] for i in rng.permutation(len(faces))]
    faces = [f[s:] + f[:s] for f in faces for s in [int(rng.integers(len(f)))]]
    # placement: rotation, sometimes a mirror (clockwise input), scale, translation
    t = rng.uniform(0, 2 * np.pi)
    pts = pts @ np.array([[np.cos(t), np.sin(t)], [-np.sin(t), np.cos(t)]])
    if rng.random() < 0.1:
        pts[:, 0] = -pts[:, 0]
        notes.append("clockwise")
    scale = 1.0 if rng.random() < 0.5 else float(10.0 ** rng.uniform(-300, 300))
    pts = pts * scale
    if rng.random() < 0.5:
        ang = rng.uniform(0, 2 * np.pi)
        pts = pts + scale * 10.0 ** rng.uniform(-1, 3) * np.array([np.cos(ang), np.sin(ang)])
    if scale != 1.0:
        notes.append(f"scale {scale:.1e}")
    params = random_params(rng)
    return {
        "seed": seed,
        "index": index,
        "points": pts,
        "faces": faces,
        "fixed": fixed,
        "params": params,
        "notes": ", ".join(notes),
    }


def random_params(rng) -> dict:
    """Parameters in their valid ranges; exponents often one of NumPy's fast-path values."""
    u = rng.random()
    if u < 0.1:
        return EEGTParams.paper().as_dict()
    if u < 0.2:  # paper mode with shorter caps (its 5000 untangling iterations are slow)
        return EEGTParams.paper().with_(
            max_untangle_iterations=int(rng.integers(0, 600)),
            max_smooth_iterations=int(rng.integers(0, 300)),
        ).as_dict()

    def exponent():
        return float(rng.choice([0.0, 0.5, 1.0, 2.0])) if rng.random() < 0.4 else float(
            round(rng.uniform(0.0, 4.0), int(rng.integers(1, 17)))
        )

    return EEGTParams(
        a=float(rng.uniform(0.01, 0.6)),
        eta=exponent(),
        c=exponent(),
        inverted_weight=float(rng.uniform(0.5, 10.0)),
        tol=float(rng.choice([0.0, 1e-3, 10.0 ** rng.uniform(-6, -2)])),
        max_untangle_iterations=int(rng.integers(0, 400)),
        max_smooth_iterations=int(rng.integers(0, 200)),
        distance_refresh=int(rng.integers(1, 21)),
        untangle=str(rng.choice(UNTANGLE_METHODS)),
        stall_iterations=int(rng.integers(1, 81)),
        polish_iterations=int(rng.integers(0, 301)),
        lift_rounds=int(rng.integers(0, 11)),
        scaling=str(rng.choice(["edge", "area"])),
    ).as_dict()


# ---- running and checking --------------------------------------------------------------


def run_once(case: dict, backend: str) -> dict:
    """One run: the result's fields, a ValueError's message, or another exception."""
    t0 = time.perf_counter()
    try:
        res = untangle_and_smooth(
            case["points"],
            case["faces"],
            fixed=case["fixed"],
            params=EEGTParams(**case["params"]),
            backend=backend,
        )
    except ValueError as exc:
        return {"value_error": str(exc), "seconds": time.perf_counter() - t0}
    except Exception as exc:
        return {
            "exception": f"{type(exc).__name__}: {exc}",
            "traceback": traceback.format_exc(),
            "seconds": time.perf_counter() - t0,
        }
    return {
        "points": res.points,
        "moved": res.moved,
        "status": res.status,
        "before": res.before,
        "after": res.after,
        "counts": (res.untangle_iterations, res.smooth_iterations, res.global_iterations),
        "backend": res.backend,
        "seconds": time.perf_counter() - t0,
    }


def message_kind(msg: str) -> str:
    """A ValueError's message with numbers and quoted names replaced, for counting."""
    msg = msg.splitlines()[0] if msg else msg
    msg = re.sub(r"(?<![A-Za-z])'[^']*'(?![A-Za-z])", "'..'", msg)
    msg = re.sub(r"[-+]?\d+(\.\d+)?(e[-+]?\d+)?", "N", msg)
    return msg[:120]


def _finite_stats(s) -> bool:
    return all(math.isfinite(float(v)) for v in (s.n_inverted, s.q_min, s.q_avg))


def fixed_nodes(case: dict) -> np.ndarray:
    """Boundary, non-manifold, pinned and loose nodes, worked out here from the faces."""
    n = len(case["points"])
    used = np.zeros(n, dtype=bool)
    used[[v for f in case["faces"] for v in f]] = True
    out = boundary_nodes(n, case["faces"]) | ~used
    return out if case["fixed"] is None else out | np.asarray(case["fixed"], dtype=bool)


def check_run(case: dict, r: dict) -> list[tuple[str, str]]:
    """(invariant, detail) failures of one run."""
    fails = []
    if "exception" in r:
        return [("error", r["exception"].splitlines()[0][:200])]
    if "value_error" in r:
        if "\n" in r["value_error"].strip() or not r["value_error"].strip():
            fails.append(("error", f"ValueError message not one line: {r['value_error']!r}"))
        return fails
    pts = r["points"]
    if not np.isfinite(pts).all() or not (_finite_stats(r["before"]) and _finite_stats(r["after"])):
        fails.append(("nan", f"non-finite output (after {r['after']})"))
    p0 = np.asarray(case["points"], dtype=np.float64)
    fixed = fixed_nodes(case) | ~r["moved"]  # ours and the run's own idea of them
    if not np.array_equal(pts[fixed], p0[fixed]):
        bad = int(np.count_nonzero(np.any(pts[fixed] != p0[fixed], axis=1)))
        fails.append(("fixed", f"{bad} fixed nodes moved"))
    if (fixed_nodes(case) & r["moved"]).any():
        fails.append(("fixed", "the run counts a boundary or pinned node as free"))
    if r["status"] != "cancelled" and not (
        r["after"] == r["before"] or r["after"].better_than(r["before"])
    ):
        fails.append(("worse", f"{r['status']}: before {r['before']} after {r['after']}"))
    return fails


def same_run(a: dict, b: dict) -> str | None:
    """None when two runs agree bit for bit, else what differs."""
    if ("value_error" in a) != ("value_error" in b) or ("exception" in a) != ("exception" in b):
        return f"one raised: {a.get('value_error') or a.get('exception')!r} vs " + repr(
            b.get("value_error") or b.get("exception")
        )
    if "value_error" in a or "exception" in a:
        ma = a.get("value_error") or a.get("exception")
        mb = b.get("value_error") or b.get("exception")
        return None if ma == mb else f"messages differ: {ma!r} vs {mb!r}"
    if not np.array_equal(a["points"], b["points"]):
        d = np.abs(a["points"] - b["points"])
        rows = np.any(a["points"] != b["points"], axis=1)
        span = float(np.ptp(a["points"], axis=0).max()) or 1.0
        return (
            f"points differ on {int(rows.sum())} nodes, max {float(d.max()):.3e} "
            f"({float(d.max()) / span:.2e} of the size); status {a['status']}/{b['status']}, "
            f"counts {a['counts']}/{b['counts']}"
        )
    for key in ("status", "before", "after", "counts"):
        if a[key] != b[key]:
            return f"{key} differs: {a[key]} vs {b[key]}"
    return None


def scaled_run_differs(case: dict, backend: str, r: dict) -> str | None:
    """None when the case scaled by 2^k (k from the case, exact: no overflow, no subnormal)
    gives r's points times 2^k bit for bit, with r's status and counts."""
    p = np.asarray(case["points"], dtype=np.float64)
    top = float(np.abs(p).max())
    if top == 0.0:
        return None
    e = math.frexp(top)[1]
    smallest = float(np.abs(p[p != 0]).min()) if (p != 0).any() else top
    lo = max(-1000 - math.frexp(smallest)[1], -1020 - e)  # stay normal and finite
    hi = 1020 - e
    if lo > hi:
        return None
    k = int(np.random.default_rng([case["seed"], case["index"], 7]).integers(lo, hi + 1))
    scaled = dict(case, points=np.ldexp(p, k))
    rs = run_once(scaled, backend)
    if "points" not in r or "points" not in rs:
        a = r.get("value_error") or r.get("exception")
        b = rs.get("value_error") or rs.get("exception")
        return None if (a is None) == (b is None) and message_kind(a or "") == message_kind(
            b or "") else f"2^{k}: {a!r} vs {b!r}"
    want = np.ldexp(r["points"], k)
    if (r["status"], r["counts"]) != (rs["status"], rs["counts"]):
        return (f"2^{k}: status/counts {r['status']} {r['counts']} vs {rs['status']} "
                f"{rs['counts']}")
    if not np.array_equal(want, rs["points"]):
        rows = np.any(want != rs["points"], axis=1)
        rel = float(np.abs(want - rs["points"]).max()) / (float(np.ptp(want, axis=0).max()) or 1)
        return f"2^{k}: points differ on {int(rows.sum())} nodes ({rel:.2e} of the size)"
    return None


def save_case(case: dict, fails: list, out: Path) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    fs = as_faceset(case["faces"], len(case["points"]))
    path = out / f"case_{case['seed']}_{case['index']:06d}.npz"
    np.savez_compressed(
        path,
        points=np.asarray(case["points"], dtype=np.float64),
        offsets=fs.offsets,
        indices=fs.indices,
        fixed=np.zeros(0, bool) if case["fixed"] is None else case["fixed"],
        has_fixed=case["fixed"] is not None,
        params=json.dumps(case["params"]),
        meta=json.dumps(
            {"seed": case["seed"], "index": case["index"], "notes": case["notes"],
             "failures": fails}
        ),
    )
    return path


def load_case(path) -> dict:
    z = np.load(path, allow_pickle=False)
    offsets, indices = z["offsets"], z["indices"]
    meta = json.loads(str(z["meta"]))
    return {
        "seed": meta["seed"],
        "index": meta["index"],
        "points": z["points"],
        "faces": [indices[a:b].tolist() for a, b in pairwise(offsets)],
        "fixed": z["fixed"] if bool(z["has_fixed"]) else None,
        "params": json.loads(str(z["params"])),
        "notes": meta["notes"],
        "failures": meta.get("failures", []),
    }


def check_case(case: dict, backends: list[str], determinism: bool) -> dict:
    """Every invariant of one case on every backend."""
    runs = {b: run_once(case, b) for b in backends}
    fails: list[tuple[str, str, str]] = []  # (invariant, backend, detail)
    for b, r in runs.items():
        fails += [(inv, b, d) for inv, d in check_run(case, r)]
        if determinism:
            again = run_once(case, b)
            diff = same_run(r, again)
            if diff:
                fails.append(("determinism", b, diff))
            diff = scaled_run_differs(case, b, r)
            if diff:
                fails.append(("units", b, diff))
    if "numpy" in runs and "opencl" in runs:
        diff = same_run(runs["numpy"], runs["opencl"])
        if diff:
            fails.append(("parity", "opencl", diff))
    return {
        "index": case["index"],
        "fails": fails,
        "value_errors": {
            b: message_kind(r["value_error"]) for b, r in runs.items() if "value_error" in r
        },
        "seconds": {b: r["seconds"] for b, r in runs.items()},
        "n_nodes": len(case["points"]),
        "notes": case["notes"],
    }


def _worker(job) -> dict:
    seed, index, backends, determinism, out = job
    case = make_case(seed, index)
    try:
        res = check_case(case, backends, determinism)
    except Exception as exc:  # the fuzzer itself: report, keep going
        res = {"index": index, "fails": [("error", "fuzz", f"{type(exc).__name__}: {exc}")],
               "value_errors": {}, "seconds": {}, "n_nodes": len(case["points"]),
               "notes": case["notes"]}
    if res["fails"]:
        res["saved"] = str(save_case(case, [list(f) for f in res["fails"]], Path(out)))
    return res


def opencl_usable() -> str | None:
    """None when the OpenCL engine can run here, else why not."""
    try:
        from core.eegt import engine_opencl
    except ImportError as exc:
        return f"core.eegt.engine_opencl: {exc}"
    cls, why = engine_opencl.available()
    return None if cls is not None else why


def summarize(results: list[dict], backends: list[str], seconds: float) -> str:
    lines = [f"cases: {len(results)}   seconds: {seconds:.1f}", ""]
    count = defaultdict(Counter)
    for r in results:
        for inv, b, _ in {(f[0], f[1], "") for f in r["fails"]}:
            count[inv][b] += 1
    cols = [*backends, "fuzz"] if any("fuzz" in c for c in count.values()) else backends
    lines.append("| invariant | " + " | ".join(cols) + " |")
    lines.append("|---|" + "---|" * len(cols))
    for inv in INVARIANTS:
        cells = []
        for b in cols:
            if inv == "parity" and b != "opencl":
                cells.append("-")
            else:
                cells.append(str(count[inv][b]))
        lines.append(f"| {inv} | " + " | ".join(cells) + " |")
    run_s = {b: sum(r["seconds"].get(b, 0.0) for r in results) for b in backends}
    lines.append("| run seconds | " + " | ".join(f"{run_s[b]:.1f}" for b in backends) + " |")
    lines.append("")
    kinds = defaultdict(Counter)
    for r in results:
        for b, k in r["value_errors"].items():
            kinds[k][b] += 1
    if kinds:
        lines.append("| ValueError | " + " | ".join(backends) + " |")
        lines.append("|---|" + "---|" * len(backends))
        for k, c in sorted(kinds.items(), key=lambda kv: -sum(kv[1].values())):
            lines.append(f"| {k} | " + " | ".join(str(c[b]) for b in backends) + " |")
    return "\n".join(lines)


def replay(path: str, backends: list[str]) -> int:
    case = load_case(path)
    print(f"{path}: case {case['index']} of seed {case['seed']}: {case['notes']}")
    print(f"  {len(case['points'])} nodes, {len(case['faces'])} faces; params {case['params']}")
    for f in case["failures"]:
        print(f"  recorded: {f}")
    res = check_case(case, backends, determinism=True)
    for b in backends:
        r = run_once(case, b)
        if "points" in r:
            print(f"  {b}: {r['status']} {r['after']} counts {r['counts']} ({r['backend']})")
        else:
            print(f"  {b}: {r.get('value_error') or r.get('exception')}")
    for inv, b, d in res["fails"]:
        print(f"  FAIL {inv} [{b}]: {d}")
    if not res["fails"]:
        print("  all invariants hold")
    return 1 if res["fails"] else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=10000, help="number of cases")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--start", type=int, default=0, help="first case index")
    ap.add_argument("--case", type=int, default=None, help="run only this case index")
    ap.add_argument("--backends", default="numpy,opencl")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--det-every", type=int, default=10,
                    help="check determinism on every this many'th case (0: never)")
    ap.add_argument("--out", default=str(DEFAULT_OUT), help="folder for failing cases")
    ap.add_argument("--replay", default=None, help="re-run one saved case (.npz)")
    ap.add_argument("--verbose", action="store_true", help="print every failure as found")
    args = ap.parse_args(argv)
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    if "opencl" in backends:
        why = opencl_usable()
        if why:
            print(f"skipping the opencl backend: {why}")
            backends.remove("opencl")
    if args.replay:
        return replay(args.replay, backends)
    indices = [args.case] if args.case is not None else range(args.start, args.start + args.n)
    jobs = [
        (args.seed, i, backends, bool(args.det_every) and i % args.det_every == 0, args.out)
        for i in indices
    ]
    t0 = time.perf_counter()
    results = []
    if args.workers > 1 and len(jobs) > 1:
        with mp.get_context("spawn").Pool(args.workers) as pool:
            for k, r in enumerate(pool.imap_unordered(_worker, jobs, chunksize=4)):
                results.append(r)
                _progress(k + 1, len(jobs), r, t0, args.verbose)
    else:
        for k, job in enumerate(jobs):
            r = _worker(job)
            results.append(r)
            _progress(k + 1, len(jobs), r, t0, args.verbose)
    print()
    print(summarize(results, backends, time.perf_counter() - t0))
    failed = [r for r in results if r["fails"]]
    if failed:
        print(f"\n{len(failed)} failing cases saved under {args.out}/ (replay with --replay FILE);"
              " first few:")
        for r in sorted(failed, key=lambda r: r["index"])[:15]:
            for inv, b, d in r["fails"][:3]:
                print(f"  case {r['index']} ({r['n_nodes']} nodes; {r['notes']}): "
                      f"{inv} [{b}] {d[:160]}")
    return 1 if failed else 0


def _progress(k: int, total: int, r: dict, t0: float, verbose: bool) -> None:
    if verbose:
        for inv, b, d in r["fails"]:
            print(f"case {r['index']}: {inv} [{b}] {d[:200]}", flush=True)
    if k % 100 == 0 or k == total:
        print(f"  {k}/{total} cases, {time.perf_counter() - t0:.0f} s", file=sys.stderr,
              flush=True)


if __name__ == "__main__":
    sys.exit(main())
