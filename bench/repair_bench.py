"""The repair benchmark (docs/repair.md): solver meshes with boundary layers, deformed until
they fold (bench.repair_meshes), repaired by our region "folds" and by the foldover-free
peer, measured against the undeformed mesh.

Columns (one row each per case):
- `input`: the deformed mesh as given (what the deformation alone did);
- `keep`: ours, the solver-mesh default: EEGTParams(target="keep", region="folds");
- `keep-cl`: the same with backend "auto" (the region's optimizer on the OpenCL device when
  pyopencl finds one, as `--backend auto` does; skipped without one);
- `keep-fast`: `keep` without the lift's rounds (`lift_rounds=0`, the command's
  `--lift-rounds 0`): no rounds that raise the worst cell against the targets;
- `ref`: ours with the reference: EEGTParams(target="reference", region="folds"),
  reference_points = the undeformed mesh;
- `whole`: ours, today's whole-mesh default (target "regular", region "mesh"), only on
  cases up to --whole-max cells;
- `peer`: the foldover-free peer (bench.peer_invertible_maps, EEGT_PEER_UNTANGLER), rest
  shape = the undeformed mesh, quads cut in two for it and measured on the original faces,
  its process's wall time (files written and read included).

Measures per row: cells inverted; the first-layer height at the wall (per wall cell: its
area over its wall edge, twice that for a triangle) after / undeformed, median and worst
(largest |log|) over the wall cells more than AWAY rings from every folded cell of the
input, and the worst over all wall cells; per cell |log| of the area ratio and of the
aspect-ratio ratio (aspect: the square root of the ratio of the corners' second moments'
eigenvalues, 1 for a regular polygon) against the undeformed mesh, median and p95 (an
inverted or flat cell counts as infinite), and the floor under those p95s that the nodes a
run moved leave (`floors`: the input's values with every cell around a moved node counted 0:
no run that moves only those nodes does better); the mean ratio of each cell against its own
undeformed shape (1: similar to the cell as built, 0: inverted), worst cell and 1st
percentile; the share of nodes moved (any bit); our region's margin in rings; seconds
(wall clock, single process).

Run: `python -m bench.repair_bench` (the default table, about 10k cells), `--more` (other
angles, seeds and sizes, 10k-60k), `--scale` (the 200k-1M cases), `--testcases` (SU2's
regression test meshes, held out), `--unseen` (more of them, held out and run last),
`--only TEXT`, `--columns keep,ref,whole,peer`,
`--json FILE`.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import re
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from bench import repair_meshes as rm
from bench.peer_invertible_maps import PeerMissing, run_peer
from core import EEGTParams, FaceSet, mesh_stats, quality, untangle_and_smooth
from core.choices import global_stage_on_device
from core.metrics.face_quality import signed_face_areas as signed_areas
from core.metrics.targets import Targets, prepare_targets
from core.run.repair import touching

AWAY = 6  # wall cells this many rings or more from every folded cell: "away from the fold"
COLUMNS = ("keep", "keep-cl", "keep-fast", "ref", "whole", "peer")

__all__ = ["AWAY", "COLUMNS", "Row", "default_specs", "measure", "more_specs", "run_case",
           "scale_specs", "testcases_specs", "unseen_specs"]

S = rm.Spec


def default_specs() -> list[rm.Spec]:
    """The default table: every family at about 10k cells and the public SU2 tutorial
    meshes. Held out (set once, before any repair ran on them, never changed): the cases
    marked held_out."""
    return [
        S("cgrid", 10_000, "turn", {"angle": 15.0, "reach": 0.1}),  # structured C-grid, quads
        S("cgrid", 10_000, "flap", {"angle": -20.0, "reach": 0.05}),
        S("cgridtri", 10_000, "turn", {"angle": 15.0, "reach": 0.15}),
        S("ogrid", 10_000, "slide", {"dx": 0.1, "reach": 0.1}),  # structured O-grid, quads
        S("ogridtri", 10_000, "slide", {"dx": 0.1, "reach": 0.1}),
        S("gmshbl-naca", 10_000, "turn", {"angle": 15.0, "reach": 0.1}),  # gmsh hybrid
        S("gmshbl-naca", 10_000, "flap", {"angle": -20.0, "reach": 0.05}),
        S("gmshbl-cyl", 10_000, "slide", {"dx": 0.1, "reach": 0.1}),
        S("gmshbltri-naca", 10_000, "turn", {"angle": 25.0, "reach": 0.2}),  # gmsh triangles
        S("public", "n0012c", "turn", {"angle": 15.0, "reach": 0.1}),  # SU2 tutorials
        S("public", "n0012tri", "turn", {"angle": 15.0, "reach": 0.2}),
        S("public", "hydrofoil", "turn", {"angle": 25.0, "reach": 0.2}),
        S("public", "cylinder", "slide", {"dx": 0.2, "reach": 0.2}, held_out=True),
        S("public", "rae2822", "turn", {"angle": 15.0, "reach": 0.1}, held_out=True),
        S("ogrid", 20_000, "turn", {"angle": 20.0, "dx": 0.03, "reach": 0.06}, held_out=True),
    ]


def more_specs() -> list[rm.Spec]:
    """--more: other seeds, angles, sizes (20k-60k) and first cells."""
    return [
        S("cgrid", 10_000, "slide", {"dx": 0.1, "reach": 0.1}),
        S("cgrid", 40_000, "turn", {"angle": 25.0, "reach": 0.2}),
        S("cgrid", 20_000, "turn", {"angle": 12.0, "dy": 0.03, "reach": 0.12,
                                    "first": 1e-4}, held_out=True),
        S("ogrid", 40_000, "slide", {"dx": 0.15, "dy": 0.05, "reach": 0.12,
                                     "first": 1e-5}),
        S("gmshbl-naca", 40_000, "turn", {"angle": 20.0, "dy": 0.02, "reach": 0.15}),
        S("gmshbl-cyl", 20_000, "slide", {"dx": -0.08, "dy": 0.06, "reach": 0.1,
                                          "first": 1e-5}, held_out=True),
        S("gmshbltri-naca", 20_000, "flap", {"angle": -15.0, "reach": 0.04}, held_out=True),
        S("public", "n0012c", "flap", {"angle": -20.0, "reach": 0.05}),
        S("public", "rae2822", "flap", {"angle": -20.0, "reach": 0.05}, held_out=True),
    ]


def testcases_specs() -> list[rm.Spec]:
    """--testcases, all held out: SU2's regression test meshes (su2code/TestCases: a hybrid
    and a structured RANS NACA 64A010, a cylinder, a 60k-cell RANS NACA 4412), never tuned
    on. Their deformations follow one rule set before any repair ran on them: the wall
    turned about its quarter chord (the cylinder: its centre) by the smallest multiple of 5
    degrees, or slid by the smallest multiple of 0.05 chords (at most 1), that folds at
    least 1 % of the cells (at least 20), the blend reaching 0.5 chords."""
    return [
        S("public", "tc-n64a010hyb", "turn", {"angle": 35.0, "reach": 0.5}, held_out=True),
        S("public", "tc-n64a010hyb", "slide", {"dx": 0.55, "reach": 0.5}, held_out=True),
        S("public", "tc-n64a010turb", "turn", {"angle": 30.0, "reach": 0.5}, held_out=True),
        S("public", "tc-n64a010turb", "slide", {"dx": 0.4, "reach": 0.5}, held_out=True),
        S("public", "tc-cylinder", "turn", {"angle": 75.0, "reach": 0.5}, held_out=True),
        S("public", "tc-cylinder", "slide", {"dx": 0.35, "reach": 0.5}, held_out=True),
        S("public", "tc-naca4412", "turn", {"angle": 35.0, "reach": 0.5}, held_out=True),
        S("public", "tc-naca4412", "slide", {"dx": 0.4, "reach": 0.5}, held_out=True),
    ]


def unseen_specs() -> list[rm.Spec]:
    """--unseen, all held out and run last: seven more of SU2's test meshes (a square
    cylinder's hybrid RANS mesh, a pitching NACA 64A010's triangles, a laminar hybrid NACA
    0012, a coarse RANS C-mesh, a rounded flat plate, a transonic stator blade between
    periodic boundaries, a blunt body), deformed by `testcases_specs`' rule (a bluff body
    turns about its centre; the stator's chord is its leading to trailing edge, the plate's
    its length) and run only once the repair they check was final."""
    cases = [("un-square", 35.0, 0.3), ("un-n64a010tri", 30.0, 0.35),
             ("un-n0012hyb", 30.0, 0.4), ("un-n0012c113", 40.0, 0.35),
             ("un-plate", 30.0, 0.35), ("un-stator", 40.0, 0.3), ("un-blunt", 50.0, 0.75)]
    out = []
    for key, angle, dx in cases:
        out += [S("public", key, "turn", {"angle": angle, "reach": 0.5}, held_out=True),
                S("public", key, "slide", {"dx": dx, "reach": 0.5}, held_out=True)]
    return out


def scale_specs() -> list[rm.Spec]:
    """The large cases: a C-grid and an O-grid of 1M quads, a 200k gmsh hybrid mesh. The
    first two fold about 2 000 cells (the issue's range: a fold of some thousand cells in a
    mesh of 1M); the same walls moved further fold 43k-96k cells (the cost follows the
    fold: those cost what a whole mesh of 100k cells does)."""
    return [
        S("cgrid", 1_000_000, "turn", {"angle": 4.4, "reach": 0.1}),
        S("ogrid", 1_000_000, "slide", {"dx": 0.058, "reach": 0.1}),
        S("cgrid", 1_000_000, "turn", {"angle": 15.0, "reach": 0.1}),
        S("ogrid", 1_000_000, "slide", {"dx": 0.1, "reach": 0.1}),
        S("gmshbl-naca", 200_000, "turn", {"angle": 15.0, "reach": 0.1}),
    ]


# ------------------------------------------------------------------------------ measures


def aspects(p: np.ndarray, fs: FaceSet) -> np.ndarray:
    """(F,) aspect ratio: sqrt(l_max / l_min) of the corners' second moments about their
    mean (1 for a regular polygon, a / b for an a x b rectangle); inf when flat."""
    out = np.empty(fs.n_faces)
    for g in fs.groups:
        x, y = p[g.nodes, 0], p[g.nodes, 1]
        x, y = x - x.mean(axis=0), y - y.mean(axis=0)
        a, b, c = (x * x).mean(axis=0), (x * y).mean(axis=0), (y * y).mean(axis=0)
        tr, det = a + c, a * c - b * b
        disc = np.sqrt(np.maximum(0.25 * tr * tr - det, 0.0))
        lo, hi = 0.5 * tr - disc, 0.5 * tr + disc
        with np.errstate(divide="ignore", invalid="ignore"):
            out[g.ids] = np.where(lo > 0, np.sqrt(hi / np.where(lo > 0, lo, 1.0)), np.inf)
    return out


def abs_log_ratio(after: np.ndarray, before: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where((after > 0) & np.isfinite(after), np.abs(np.log(after / before)), np.inf)
    return r


def wall_cells(fs: FaceSet, wall: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(face ids, edge start, edge end) of the boundary edges with both nodes on the wall."""
    faces, a_all, b_all = [], [], []
    for g in fs.groups:
        a, b = g.nodes, np.roll(g.nodes, -1, axis=0)
        faces.append(np.broadcast_to(g.ids, a.shape).ravel())
        a_all.append(a.ravel())
        b_all.append(b.ravel())
    f, a, b = (np.concatenate(v) for v in (faces, a_all, b_all))
    n = int(max(a.max(), b.max())) + 1
    key = np.minimum(a, b) * n + np.maximum(a, b)
    _, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    on = (cnt[inv] == 1) & wall[a] & wall[b]
    return f[on], a[on], b[on]


def ring_distance(fs: FaceSet, n_nodes: int, seed: np.ndarray, up_to: int) -> np.ndarray:
    """(F,) rings of faces (sharing a node) from `seed` (0: in it), up_to + 1 beyond."""
    dist = np.where(seed, 0, up_to + 1)
    region = seed.copy()
    for r in range(1, up_to + 1):
        nodes = np.zeros(n_nodes, dtype=bool)
        for g in fs.groups:
            nodes[g.nodes[:, region[g.ids]]] = True
        for g in fs.groups:
            hit = nodes[g.nodes].any(axis=0) & ~region[g.ids]
            dist[g.ids[hit]] = r
            region[g.ids[hit]] = True
    return dist


@dataclass
class Geometry:
    """What the measures of a case need, computed once."""

    area0: np.ndarray
    aspect0: np.ndarray
    wall_faces: np.ndarray
    wall_len: np.ndarray
    wall_factor: np.ndarray  # 2 for a triangle, 1 otherwise
    away: np.ndarray  # (len(wall_faces),) bool
    folded: int
    built: Targets  # every cell's undeformed shape (the mean ratio's targets)
    area_in: np.ndarray  # the input's per-cell |log| area and aspect ratio against the
    aspect_in: np.ndarray  # undeformed mesh (what a run leaves where it moves nothing)


def geometry(case: rm.Case) -> Geometry:
    fs, ref = case.faces, case.reference
    f, a, b = wall_cells(fs, case.wall)
    counts = np.diff(fs.offsets)
    from core.run import folded_faces  # the core's own rule: a corner that does not turn left

    seed = folded_faces(case.points, fs, ~case.fixed)
    dist = ring_distance(fs, ref.shape[0], seed, AWAY)
    area0, aspect0 = signed_areas(ref, fs), aspects(ref, fs)
    return Geometry(area0, aspect0, f,
                    np.hypot(*(ref[a] - ref[b]).T), np.where(counts[f] == 3, 2.0, 1.0),
                    dist[f] >= AWAY, int(seed.sum()), prepare_targets(ref[fs.indices], fs),
                    abs_log_ratio(signed_areas(case.points, fs), area0),
                    abs_log_ratio(aspects(case.points, fs), aspect0))


@dataclass
class Row:
    case: str
    family: str
    column: str
    cells: int
    folded: int
    inverted: int | None = None
    layer_med: float = float("nan")
    layer_worst_away: float = float("nan")
    layer_worst_all: float = float("nan")
    area_med: float = float("nan")
    area_p95: float = float("nan")
    aspect_med: float = float("nan")
    aspect_p95: float = float("nan")
    area_floor: float = float("nan")  # `floors`: the p95s no run that moves only the nodes
    aspect_floor: float = float("nan")  # this one moved can beat
    built_min: float = float("nan")  # mean ratio against the undeformed cell: worst cell
    built_p1: float = float("nan")  # ... and 1st percentile
    moved: float = float("nan")
    rings: int | None = None
    seconds: float = float("nan")
    held_out: bool = False
    note: str = ""
    extra: dict = field(default_factory=dict)


def _worst(r: np.ndarray) -> float:
    """The ratio farthest from 1 (by |log|)."""
    if not r.size:
        return float("nan")
    lg = np.abs(np.log(np.where(r > 0, r, np.nan)))
    if np.isnan(lg).any():
        return float(r[np.isnan(lg)][0])
    return float(r[np.argmax(lg)])


def _percentiles(v: np.ndarray) -> tuple[float, float]:
    """Median and p95 (between two infinite values: infinite, not NaN)."""
    with np.errstate(invalid="ignore"):  # inf - inf between two infinite values
        out = np.percentile(v, [50, 95])
    return tuple(float(np.inf if x != x else x) for x in out)


def measure(case: rm.Case, geo: Geometry, pts: np.ndarray, row: Row) -> Row:
    fs = case.faces
    row.inverted = mesh_stats(pts, fs).n_inverted
    area = signed_areas(pts, fs)
    la = abs_log_ratio(area, geo.area0)
    lr = abs_log_ratio(aspects(pts, fs), geo.aspect0)
    row.area_med, row.area_p95 = _percentiles(la)
    row.aspect_med, row.aspect_p95 = _percentiles(lr)
    qb = quality(pts, fs, targets=geo.built)
    row.built_min, row.built_p1 = float(qb.min()), float(np.percentile(qb, 1))
    h = geo.wall_factor * area[geo.wall_faces] / geo.wall_len
    h0 = geo.wall_factor * geo.area0[geo.wall_faces] / geo.wall_len
    ratio = h / h0
    pick = ratio[geo.away] if geo.away.any() else ratio
    row.layer_med = float(np.median(pick)) if pick.size else float("nan")
    row.layer_worst_away = _worst(pick)
    row.layer_worst_all = _worst(ratio)
    moved = np.any(pts != case.points, axis=1)
    row.moved = float(moved.mean())
    row.area_floor, row.aspect_floor = floors(geo, fs, moved)
    return row


def floors(geo: Geometry, fs: FaceSet, moved: np.ndarray) -> tuple[float, float]:
    """(area, aspect) p95 floors of a run that moved the nodes `moved`: the p95 of the
    input's per-cell |log| ratios with every cell that has a moved node counted 0 (as if
    the run had made it its undeformed shape). Cells with no moved node keep the input's
    values whatever the run does, so no run that moves only these nodes gets below it: a
    repair whose margin is ours, whatever its targets and optimizer."""
    touched = touching(fs, moved)
    return tuple(_percentiles(np.where(touched, 0.0, v))[1] for v in (geo.area_in, geo.aspect_in))


# ------------------------------------------------------------------------------ runs

KEEP = EEGTParams(target="keep", region="folds")  # the solver-mesh default
PARAMS = {
    "keep": KEEP,
    "keep-cl": KEEP,
    "keep-fast": replace(KEEP, lift_rounds=0),
    "ref": EEGTParams(target="reference", region="folds"),
    "whole": EEGTParams(),
}
BACKENDS = {"keep-cl": "auto"}  # the others: "numpy"


def _ours_child(case: rm.Case, col: str, out) -> None:
    ref = case.reference if col == "ref" else None
    t0 = time.perf_counter()
    res = untangle_and_smooth(case.points, case.faces, fixed=case.fixed, params=PARAMS[col],
                              reference_points=ref, backend=BACKENDS.get(col, "numpy"))
    secs = time.perf_counter() - t0
    out.send((np.asarray(res.points, dtype=np.float64)[:, :2],
              np.asarray(res.moved, dtype=bool), res.status, res.message, secs, res.backend))
    out.close()


def _start_method() -> str:
    """How a run's process starts: forked (at once, nothing imported again), unless this
    process has loaded pyopencl: a forked child cannot use an OpenCL runtime its parent
    made (pocl's worker threads are not copied: the child waits for ever), so then it is
    spawned. The bench itself never runs OpenCL in its own process; a test session may."""
    return "spawn" if "pyopencl" in sys.modules else "fork"


def _ours(case: rm.Case, col: str, timeout: float):
    """(points, moved, status, message, seconds) of our run in a child process (one at a
    time: the bench stays single-process; `_start_method`), None when it runs past
    `timeout` seconds."""
    ctx = mp.get_context(_start_method())
    here, there = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_ours_child, args=(case, col, there))
    proc.start()
    there.close()
    try:
        got = here.recv() if here.poll(timeout) else None
    except EOFError:  # the run raised (its traceback is on stderr)
        got = "error"
    if got is None:
        proc.terminate()
    proc.join()
    return got


def run_case(case: rm.Case, columns: tuple[str, ...], whole_max: int = 20_000,
             timeout: float = 600.0, repeat: int = 1) -> list[Row]:
    """The input row and one row per column; a column's seconds are the median of `repeat`
    runs (a run past `timeout` is not repeated), its measures the first run's (a note says
    when another run's points differ)."""
    geo = geometry(case)
    base = dict(case=case.name, family=case.family, cells=case.n_faces, folded=geo.folded,
                held_out=case.held_out)
    rows = [measure(case, geo, case.points, Row(column="input", seconds=0.0, **base))]
    for col in columns:
        row = Row(column=col, **base)
        if col == "whole" and case.n_faces > whole_max:
            continue
        if col == "peer":
            try:
                t0 = time.perf_counter()
                first = run_peer(case.points, case.faces, case.reference, timeout=timeout)
                t_first = time.perf_counter() - t0
            except PeerMissing as exc:
                print(f"<!-- {exc} -->", file=sys.stderr)
                continue
            except subprocess.TimeoutExpired:
                row.note = f"over {timeout:.0f} s (stopped)"
                row.seconds = timeout
                rows.append(row)
                continue
            pts = first.points
            runs, lost = _repeats((t_first, pts), repeat, partial(_peer_again, case, timeout))
            row.seconds = float(np.median([t for t, _ in runs]))
            row.note = ("" if first.success else "peer: no SUCCESS") + _differ(runs) + \
                _lost(lost, repeat)
        else:
            got = _ours(case, col, timeout)
            if got is None or got == "error":
                row.note = "raised (see stderr)" if got else f"over {timeout:.0f} s (stopped)"
                row.seconds = float("nan") if got else timeout
                rows.append(row)
                continue
            pts, moved, status, message, first, backend = got
            runs, lost = _repeats((first, pts), repeat, partial(_ours_again, case, col, timeout))
            row.seconds = float(np.median([t for t, _ in runs]))
            if col in BACKENDS and not global_stage_on_device(backend):
                print(f"<!-- {col}: no OpenCL device ({backend}) -->", file=sys.stderr)
                continue
            m = re.search(r"\((\d+) rings around", message)
            row.rings = int(m.group(1)) if m else None
            row.note = "" if status in ("untangled", "valid") else f"{status}: {message[:160]}"
            if not np.array_equal(pts[~moved], case.points[~moved]):
                row.note += " nodes flagged unmoved changed!"
            row.note += _differ(runs) + _lost(lost, repeat)
        rows.append(measure(case, geo, np.asarray(pts, dtype=np.float64)[:, :2], row))
    return rows


Run = tuple[float, np.ndarray]  # (seconds, points) of one run


def _repeats(first: Run, repeat: int, again: Callable[[], Run | None]) -> tuple[list[Run], int]:
    """The first run and `repeat` - 1 more (`again`: None when a run stopped or raised), and
    how many of those were lost (left out of the median)."""
    more = [again() for _ in range(repeat - 1)]
    kept = [r for r in more if r is not None]
    return [first, *kept], len(more) - len(kept)


def _ours_again(case: rm.Case, col: str, timeout: float) -> Run | None:
    got = _ours(case, col, timeout)
    return None if got is None or got == "error" else (got[4], got[0])


def _peer_again(case: rm.Case, timeout: float) -> Run | None:
    t0 = time.perf_counter()
    try:
        res = run_peer(case.points, case.faces, case.reference, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None
    return time.perf_counter() - t0, res.points


def _lost(lost: int, repeat: int) -> str:
    """A note when some repeated runs stopped or raised ("" when none did)."""
    return f" {lost} of {repeat} runs stopped or raised (not in the median)" if lost else ""


def _differ(runs: list[tuple[float, np.ndarray]]) -> str:
    """A note when a repeated run's points differ from the first run's ("" when alike)."""
    same = all(np.array_equal(p, runs[0][1]) for _, p in runs[1:])
    return "" if same else f" {len(runs)} runs gave different points!"


# ------------------------------------------------------------------------------ tables


def _r(v: float) -> str:
    return "-" if v != v else f"{v:.4g}" if abs(v - 1) > 1e-4 or v == 1 else f"{v:.6f}"


def _g(v: float) -> str:
    return "-" if v != v else ("inf" if v == float("inf") else f"{v:.3g}")


HEAD = ("| case | cells | folded | column | inverted | 1st layer after/before: median, worst "
        f"(>= {AWAY} rings from the fold) | worst (all wall cells) | area abs log: median, p95 "
        "| aspect abs log: median, p95 | mean ratio vs undeformed: worst, 1st pct "
        "| nodes moved | rings | s |")


def table(rows: list[Row]) -> list[str]:
    out = [HEAD, "|" + "---|" * 13]
    for r in rows:
        name = r.case + (" (held out)" if r.held_out else "")
        inv = "-" if r.inverted is None else str(r.inverted)
        out.append(
            f"| {name} | {r.cells} | {r.folded} | {r.column} | {inv} | "
            f"{_r(r.layer_med)}, {_r(r.layer_worst_away)} | {_r(r.layer_worst_all)} | "
            f"{_g(r.area_med)}, {_g(r.area_p95)} | {_g(r.aspect_med)}, {_g(r.aspect_p95)} | "
            f"{_g(r.built_min)}, {_g(r.built_p1)} | {100 * r.moved:.1f} % | {'' if r.rings is None else r.rings} | "
            f"{r.seconds:.2f} |" + (f" {r.note}" if r.note else ""))
    return out


def family_of(row: Row) -> str:
    """The family of a row: the generator, or "public KEY" (the file's key in rm.PUBLIC)."""
    if row.family != "public":
        return row.family
    key = row.case.removeprefix("public-")
    return "public " + key[:key.rfind("-", 0, key.find("("))]


def _med(rows: list[Row], key: str) -> float:
    return float(np.median([getattr(r, key) for r in rows]))


def summary(rows: list[Row]) -> list[str]:
    """Medians per family and column (the targets of issue 37 are medians over families)."""
    cols = [c for c in ("input", *COLUMNS) if any(r.column == c for r in rows)]
    out = ["| family | cases | column | inverted (max) | 1st layer median | 1st layer worst "
           "away | area p95 | aspect p95 | vs undeformed: worst, 1st pct | nodes moved | s |",
           "|" + "---|" * 11]
    fams = sorted({family_of(r) for r in rows})
    for fam in fams:
        n_cases = len({r.case for r in rows if family_of(r) == fam})
        for c in cols:
            rs = [r for r in rows if family_of(r) == fam and r.column == c]
            if not rs:
                continue
            inv = [r.inverted for r in rs if r.inverted is not None]
            worst = _worst(np.array([r.layer_worst_away for r in rs]))
            out.append(f"| {fam} | {n_cases} | {c} | {max(inv) if inv else '-'} | "
                       f"{_r(_med(rs, 'layer_med'))} | {_r(worst)} | "
                       f"{_g(_med(rs, 'area_p95'))} | {_g(_med(rs, 'aspect_p95'))} | "
                       f"{_g(_med(rs, 'built_min'))}, {_g(_med(rs, 'built_p1'))} | "
                       f"{100 * _med(rs, 'moved'):.1f} % | {_med(rs, 'seconds'):.2f} |")
    return out


def floor_table(rows: list[Row], ours: str = "keep") -> list[str]:
    """Per case with a finished peer row: the area and aspect p95 of `ours`, the floor its
    moved nodes leave (`floors`) and the peer's; "(below)" marks a peer p95 under that
    floor, which no repair with our margin can reach."""
    out = ["| case | area p95: ours, floor, peer | aspect p95: ours, floor, peer |",
           "|---|---|---|"]
    by = {(r.case, r.column): r for r in rows}
    for case in dict.fromkeys(r.case for r in rows):
        us, peer = by.get((case, ours)), by.get((case, "peer"))
        if us is None or peer is None or peer.inverted is None:
            continue
        cells = []
        for p95, floor, theirs in ((us.area_p95, us.area_floor, peer.area_p95),
                                   (us.aspect_p95, us.aspect_floor, peer.aspect_p95)):
            mark = " (below)" if theirs < floor else ""
            cells.append(f"{_g(p95)}, {_g(floor)}, {_g(theirs)}{mark}")
        name = case + (" (held out)" if us.held_out else "")
        out.append(f"| {name} | {cells[0]} | {cells[1]} |")
    return out


PICTURE = S("public", "n0012c", "turn", {"angle": 15.0, "reach": 0.1})


def picture(path: Path, mirror: Path | None = None) -> None:
    """Before / after of a boundary layer repaired (docs/repair_boundary_layer.png): SU2's
    225 x 65 NACA 0012 C-mesh with its wall turned 15 degrees, near the trailing edge: the
    undeformed mesh, the deformed one (folded cells red) and the repair (target "keep",
    region "folds"; the cells it moved blue)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    case = rm.load(PICTURE, mirror)
    res = untangle_and_smooth(case.points, case.faces, fixed=case.fixed, params=PARAMS["keep"])
    fs = case.faces
    polys = [np.asarray(f) for f in fs.to_lists()]
    moved_faces = touching(fs, np.asarray(res.moved, dtype=bool))
    folded = signed_areas(case.points, fs) <= 0
    from core.run import folded_faces

    folded |= folded_faces(case.points, fs, ~case.fixed)
    box = np.array([[0.55, -0.16], [1.12, 0.2]])
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.4), dpi=80)
    for ax, pts, title, red, blue in (
            (axes[0], case.reference, "undeformed (SU2 tutorial C-mesh)", None, None),
            (axes[1], case.points, f"wall turned 15\u00b0: {int(folded.sum())} cells folded",
             folded, None),
            (axes[2], np.asarray(res.points)[:, :2],
             f"repaired in {res.seconds:.1f} s: {res.after.n_inverted} inverted", None,
             moved_faces)):
        cen = np.array([pts[f].mean(axis=0) for f in polys])
        near = np.all((cen > box[0] - 0.05) & (cen < box[1] + 0.05), axis=1)
        face = np.array(["none"] * len(polys), dtype=object)
        if red is not None:
            face[red] = "#e06666"
        if blue is not None:
            face[blue] = "#9fc5e8"
        ax.add_collection(PolyCollection([pts[f] for f, k in zip(polys, near) if k],
                                         facecolors=list(face[near]), edgecolors="k",
                                         linewidths=0.15))
        ax.set_xlim(box[:, 0])
        ax.set_ylim(box[:, 1])
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", action="store_true", help="the 200k-1M cases instead")
    ap.add_argument("--more", action="store_true", help="the other seeds, angles and sizes")
    ap.add_argument("--testcases", action="store_true",
                    help="SU2's regression test meshes instead (held out)")
    ap.add_argument("--unseen", action="store_true",
                    help="more of SU2's test meshes instead (held out, run last)")
    ap.add_argument("--only", default="", help="only cases whose name contains this")
    ap.add_argument("--columns", default=",".join(COLUMNS))
    ap.add_argument("--whole-max", type=int, default=20_000,
                    help="today's whole-mesh default only up to this many cells")
    ap.add_argument("--timeout", type=float, default=300.0,
                    help="a column still running after this many seconds is stopped")
    ap.add_argument("--repeat", type=int, default=1,
                    help="run each column this many times: its seconds are the median")
    ap.add_argument("--mirror", type=Path, default=None,
                    help="bare snapshots (OWNER+NAME/repo) for the public meshes not in "
                         "build/public_meshes (default /work/.mirror)")
    ap.add_argument("--json", type=Path, default=None, help="write every row here")
    ap.add_argument("--picture", type=Path, default=None,
                    help="draw the before / after picture there and stop")
    args = ap.parse_args(argv)
    if args.picture:
        picture(args.picture, args.mirror)
        return 0
    columns = tuple(c for c in args.columns.split(",") if c)
    bad = [c for c in columns if c not in COLUMNS]
    if bad:
        ap.error(f"unknown column {bad[0]!r} (choose from {', '.join(COLUMNS)})")
    specs = [s for s in (scale_specs() if args.scale else more_specs() if args.more
                       else testcases_specs() if args.testcases
                       else unseen_specs() if args.unseen else default_specs())
             if args.only in s.name]
    rows: list[Row] = []
    print(table([])[0])
    print(table([])[1], flush=True)
    for spec in specs:
        try:
            case = rm.load(spec, args.mirror)
        except (FileNotFoundError, ValueError) as exc:
            print(f"<!-- {spec.name} skipped: {exc} -->", flush=True)
            continue
        got = run_case(case, columns, args.whole_max, args.timeout, max(args.repeat, 1))
        rows += got
        for line in table(got)[2:]:
            print(line, flush=True)
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps([r.__dict__ for r in rows], indent=1))
    print()
    print("\n".join(summary(rows)))
    if any(r.column == "peer" for r in rows):
        print()
        print("\n".join(floor_table(rows)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
