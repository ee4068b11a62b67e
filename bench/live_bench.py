"""Live Untangle's per-frame work in headless Blender (the bpy module), docs/live.md.

Installs the built extension (sandboxed, as ``bench.blender_scale``) and runs the UV tool's
drag as its modal does on each timer tick: the cursor's UV for this tick, the core frame
warm from the last one under ``core.run.live.FRAME_BUDGET``, the changed UVs written into
the edit mesh. The redraw request (``area.tag_redraw``) only flags the area: there is no
area headless, so it is not timed.

Two parts. ``grid``: a Grid of about 5 000 and 50 000 quads (one UV island), 40 frames of a
3-pixel-a-tick drag. ``drags``: drags as people do (``human_drag``) on unwraps made by
Blender's own Smart UV Project and Unwrap (``UNWRAPS``: Suzanne subdivided twice, a torus of
50 176 faces, a subdivided cylinder, a noisy surface), several seeds: an interior UV vertex
of the largest island dragged across 20-50 % of the island's width in 40 frames, then the
cursor still until the frames stop (at most ``REST`` s); held out, never in the default run
(``HELD_OUT_UNWRAPS``): a UV sphere's Unwrap, an ico sphere's Smart UV. Prints markdown
tables with medians over the seeds: updates per second during the drag, the time from the cursor's stop until
no face is inverted ("open"), the inverted faces at the end (an independent count:
``inverted_faces``) and how far the layout holds the grabbed vertex back from the cursor at
the end (``LiveFrame.held_back``, as a share of the drag's length: 0 when it is on the
cursor).

Run: ``python -m bench.live_bench [--faces 5000 50000] [--frames 40] [--seeds 3]
[--first-seed 1] [--part grid drags] [--unwraps NAME ...]``.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

REST = 5.0  # seconds of rest frames a drag gets at most


def grid(bpy, faces: int):
    """A Grid primitive of about ``faces`` quads in Edit Mode (its UVs: one island)."""
    n = max(2, round(faces ** 0.5)) + 1
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=n, y_subdivisions=n, size=2.0)
    obj = bpy.context.active_object
    bpy.ops.object.mode_set(mode="EDIT")
    return obj, (n - 1) ** 2


def _subsurf(bpy, obj, levels: int) -> None:
    mod = obj.modifiers.new("Subdivision", "SUBSURF")
    mod.levels = levels
    bpy.ops.object.modifier_apply(modifier=mod.name)


def _unwrap(bpy, obj, how: str) -> None:
    """Blender's own unwrap of every face (``smart``: Smart UV Project; ``unwrap``: Unwrap,
    angle based, along the seams marked), left in Edit Mode."""
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    if how == "smart":
        bpy.ops.uv.smart_project()
    else:
        bpy.ops.uv.unwrap(method="ANGLE_BASED", margin=0.02)


def _seams(obj, cut: Callable[[np.ndarray], np.ndarray]) -> None:
    """Mark as seams the edges whose two vertices ``cut`` (of the (N, 3) positions) holds."""
    me = obj.data
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    on = cut(co.reshape(-1, 3).astype(np.float64))
    ev = np.empty(len(me.edges) * 2, np.int64)
    me.edges.foreach_get("vertices", ev)
    me.edges.foreach_set("use_seam", on[ev.reshape(-1, 2)].all(axis=1))


def monkey(bpy, how: str = "smart", levels: int = 2):
    """Suzanne subdivided ``levels`` times (2: 7 872 faces), unwrapped (Unwrap: cut at x=0)."""
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.active_object
    _subsurf(bpy, obj, levels)
    if how == "unwrap":
        _seams(obj, lambda co: np.abs(co[:, 0]) < 1e-5)
    _unwrap(bpy, obj, how)
    return obj


def torus(bpy, how: str = "unwrap", n: int = 224):
    """A torus of n x n quads (224: 50 176), Unwrap cut along a meridian and the outer
    equator (one island), or Smart UV Project."""
    bpy.ops.mesh.primitive_torus_add(major_segments=n, minor_segments=n)
    obj = bpy.context.active_object
    if how == "unwrap":
        _seams(obj, lambda co: ((np.abs(co[:, 1]) < 1e-6) & (co[:, 0] > 0))
               | ((np.hypot(co[:, 0], co[:, 1]) > 1.0) & (np.abs(co[:, 2]) < 1e-6)))
    _unwrap(bpy, obj, how)
    return obj


def cylinder(bpy, how: str = "smart", vertices: int = 48, cuts: int = 20):
    """An open cylinder subdivided with ``cuts`` cuts (48, 20: 21 168 quads)."""
    bpy.ops.mesh.primitive_cylinder_add(vertices=vertices, end_fill_type="NOTHING")
    obj = bpy.context.active_object
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.mesh.subdivide(number_cuts=cuts)
    bpy.ops.object.mode_set(mode="OBJECT")
    if how == "unwrap":
        _seams(obj, lambda co: (np.abs(co[:, 1]) < 1e-6) & (co[:, 0] > 0))
    _unwrap(bpy, obj, how)
    return obj


def noisy(bpy, how: str = "unwrap", n: int = 90, seed: int = 2):
    """A grid of n x n quads with sculpt-like bumps and noise (90: 8 100), unwrapped."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=n, y_subdivisions=n, size=2)
    obj = bpy.context.active_object
    me = obj.data
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3).astype(np.float64)
    rng = np.random.default_rng(seed)
    x, y = co[:, 0], co[:, 1]
    z = 0.3 * np.sin(3 * x + 1) * np.cos(2.5 * y) + 0.15 * np.sin(7 * x * y)
    for _ in range(6):
        c, s, h = rng.uniform(-1, 1, 2), rng.uniform(0.1, 0.4), rng.uniform(-0.3, 0.3)
        z += h * np.exp(-((x - c[0]) ** 2 + (y - c[1]) ** 2) / s ** 2)
    co[:, 2] = z + 0.01 * rng.standard_normal(z.size)
    me.vertices.foreach_set("co", co.astype(np.float32).ravel())
    me.update()
    _unwrap(bpy, obj, how)
    return obj


def uv_sphere(bpy, how: str = "unwrap", segments: int = 96, rings: int = 48):
    """A UV sphere subdivided once (96 x 48: 18 240 faces), Unwrap cut along a meridian (one
    island), or Smart UV Project."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings)
    obj = bpy.context.active_object
    _subsurf(bpy, obj, 1)
    if how == "unwrap":
        _seams(obj, lambda co: (np.abs(co[:, 1]) < 1e-6) & (co[:, 0] > 0))
    _unwrap(bpy, obj, how)
    return obj


def ico_sphere(bpy, how: str = "smart", subdivisions: int = 5):
    """An ico sphere (5: 5 120 triangles), Smart UV Project."""
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=subdivisions)
    obj = bpy.context.active_object
    _unwrap(bpy, obj, how)
    return obj


UNWRAPS: dict[str, Callable[..., Any]] = {
    "suzanne-smart": lambda bpy: monkey(bpy, "smart"),
    "suzanne-unwrap": lambda bpy: monkey(bpy, "unwrap"),
    "noisy-unwrap": lambda bpy: noisy(bpy, "unwrap"),
    "cylinder-smart": lambda bpy: cylinder(bpy, "smart"),
    "cylinder-unwrap": lambda bpy: cylinder(bpy, "unwrap"),
    "torus-unwrap": lambda bpy: torus(bpy, "unwrap"),
}
# held out: never in the default run, never tuned on (``--unwraps uvsphere-unwrap ico-smart``)
HELD_OUT_UNWRAPS: dict[str, Callable[..., Any]] = {
    "uvsphere-unwrap": lambda bpy: uv_sphere(bpy, "unwrap"),
    "ico-smart": lambda bpy: ico_sphere(bpy, "smart"),
}
EVERY_UNWRAP = {**UNWRAPS, **HELD_OUT_UNWRAPS}  # what --unwraps can name


def inverted_faces(uv: np.ndarray, faces: list[np.ndarray]) -> np.ndarray:
    """(F,) bool, independent of the project's code: a face whose signed area or one of
    whose corner dets is not positive (``uv`` (n, 2) positions, ``faces`` node arrays)."""
    out = np.zeros(len(faces), dtype=bool)
    for k, f in enumerate(faces):
        p = uv[f]
        e1, e0 = np.roll(p, -1, axis=0) - p, np.roll(p, 1, axis=0) - p
        det = e1[:, 0] * e0[:, 1] - e1[:, 1] * e0[:, 0]
        area = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
        out[k] = bool((det <= 0.0).any() or area <= 0.0)
    return out


def human_drag(points: np.ndarray, fs, interior: np.ndarray, border: np.ndarray, seed: int,
               share: tuple[float, float] = (0.2, 0.5)) -> tuple[int, np.ndarray, float]:
    """A drag as a person makes one on an island (``points`` (n, 2), faces ``fs``, the
    ``interior`` nodes that may be grabbed, ``border`` (n,) bool its border): a node at random moved by ``share`` of the
    island's width in a random direction, to a place inside the island at least three mean
    edges (and 3 % of the width) from its border. Returns (node, end point, share)."""
    rng = np.random.default_rng(seed)
    width = float(np.max(points.max(axis=0) - points.min(axis=0)))
    border = points[border]
    e = points[fs.indices] - points[np.roll(fs.indices, 1)]
    margin = max(0.03 * width, 3.0 * float(np.hypot(e[:, 0], e[:, 1]).mean()))
    for _ in range(500):
        node = int(rng.choice(interior))
        f = float(rng.uniform(*share))
        a = rng.uniform(0.0, 2.0 * np.pi)
        end = points[node] + f * width * np.array([np.cos(a), np.sin(a)])
        if np.min(np.hypot(*(border - end).T)) > margin and _covered(points, fs, end):
            return node, end, f
    raise ValueError("no drag of that length fits in the island")


def _covered(points: np.ndarray, fs, at: np.ndarray) -> bool:
    """Whether ``at`` lies inside a face of the (valid) island."""
    for g in fs.groups:
        x, y = points[g.nodes, 0] - at[0], points[g.nodes, 1] - at[1]
        cross = x * np.roll(y, -1, axis=0) - np.roll(x, -1, axis=0) * y
        if (cross > 0).all(axis=0).any():
            return True
    return False


def island_drag(ext, drag_mod, obj, seed: int, params=None):
    """A ``UVDrag`` of a human drag (``human_drag``) on the largest island of ``obj``'s
    active UV map (Edit Mode): (drag, path of 40 cursor UVs, the region's faces as lists)."""
    bpy_obj = obj
    lay = _layout(ext, bpy_obj)
    big = np.argmax(np.bincount(lay.island, minlength=lay.n_islands))
    core = ext.core
    inner = np.flatnonzero(~core.boundary_nodes(lay.n_nodes, lay.faces)
                           & (lay.node_island == big) & (lay.orientation()[lay.node_island] > 0))
    reg = core.run.live.uv_region(lay, inner[:1])
    local = np.full(lay.n_nodes, -1)
    local[reg.nodes] = np.arange(reg.nodes.size)
    node, end, share = human_drag(reg.points, reg.faces, local[inner],
                                  core.boundary_nodes(reg.nodes.size, reg.faces), seed)
    g = int(reg.nodes[node])
    start = lay.points[g]
    drag = drag_mod.UVDrag(bpy_obj, tuple(start), params or core.EEGTParams(),
                           grab=np.array([g]))
    path = [start + (end - reg.points[node]) * k / 40 for k in range(1, 41)]
    return drag, path, share


def _layout(ext, obj):
    """The welded UV map of ``obj`` (Edit Mode: read through Object Mode)."""
    import bpy

    bpy.ops.object.mode_set(mode="OBJECT")
    me = obj.data
    ls = np.empty(len(me.polygons), np.int64)
    lt = np.empty(len(me.polygons), np.int64)
    cv = np.empty(len(me.loops), np.int64)
    uv = np.empty(len(me.loops) * 2, np.float32)
    me.polygons.foreach_get("loop_start", ls)
    me.polygons.foreach_get("loop_total", lt)
    me.loops.foreach_get("vertex_index", cv)
    me.attributes[me.uv_layers.active.name].data.foreach_get("vector", uv)
    bpy.ops.object.mode_set(mode="EDIT")
    return ext.core.uv.weld_uv(ls, lt, cv, uv.reshape(-1, 2))


def run_drag(ext, drag, path, budget, rest: float = REST) -> dict:
    """The drag along ``path`` a frame a tick, then rest frames until the frames stop (no
    fold left, the grabbed vertices at the cursor, smoothing done) or ``rest`` s."""
    walls = []
    for at in path:
        t = time.perf_counter()
        drag.step(tuple(at), budget=budget)
        walls.append(time.perf_counter() - t)
    t0 = time.perf_counter()
    opened = None
    frames = 0
    while time.perf_counter() - t0 < rest:
        frame = drag.step(None, budget=budget)
        frames += 1
        if opened is None and frame.status != "tangled":
            opened = time.perf_counter() - t0
        if opened is not None and frame.settled:
            break
    return {"rate": len(path) / sum(walls), "median": statistics.median(walls),
            "worst": max(walls), "open": opened, "rest_frames": frames, "frame": drag.frame}


def run(bpy, ext, faces: int, frames: int) -> dict:
    obj, n_faces = grid(bpy, faces)
    drag_mod, live = ext.operators.live.drag, ext.core.run.live
    t0 = time.perf_counter()
    drag = drag_mod.UVDrag(obj, (0.5, 0.5), ext.core.EEGTParams(), radius=0.01)
    setup = time.perf_counter() - t0
    walls, splits, iters = [], [], []
    for k in range(frames):
        t = time.perf_counter()
        px = 400.0 + 3.0 * k  # the cursor's pixel, 3 px a tick, in a 1000 px wide view
        cursor = (px / 1000.0 + 0.1, 0.5 + 1.5 * k / 1000.0)
        frame = drag.step(cursor, budget=live.FRAME_BUDGET)
        walls.append(time.perf_counter() - t)
        splits.append((drag.times.core, drag.times.write))
        iters.append(frame.untangle_iterations + frame.smooth_iterations)
    worst = max(range(frames), key=walls.__getitem__)
    drag.restore()
    bpy.ops.object.mode_set(mode="OBJECT")
    return {"faces": n_faces, "setup": setup, "rate": frames / sum(walls),
            "median": statistics.median(walls), "worst": walls[worst],
            "core": splits[worst][0], "write": splits[worst][1],
            "iters": statistics.median(iters), "inverted": frame.stats.n_inverted}


def drags(bpy, ext, name: str, seeds: int, escalate: bool = True, first: int = 1) -> dict:
    """The human drags of ``seeds`` seeds from ``first`` on the unwrap ``name``: medians
    over the seeds."""
    live = ext.core.run.live
    rows = []
    for seed in range(first, first + seeds):
        bpy.ops.wm.read_homefile(use_empty=True)
        obj = EVERY_UNWRAP[name](bpy)
        drag, path, share = island_drag(ext, ext.operators.live.drag, obj, seed)
        if not escalate:
            drag.session.repair = None
        r = run_drag(ext, drag, path, live.FRAME_BUDGET)
        reg = drag.region
        faces = [reg.faces.indices[a:b] for a, b in zip(reg.faces.offsets[:-1],
                                                         reg.faces.offsets[1:])]
        r["inverted"] = int(inverted_faces(r["frame"].points, faces).sum())
        way = float(np.hypot(*(np.asarray(path[-1]) - path[0]))) * len(path) / (len(path) - 1)
        r["held"] = r["frame"].held_back / way  # the share of the drag the layout held back
        r["faces"], r["share"] = reg.faces.n_faces, share
        r["mesh"] = len(obj.data.polygons)
        drag.restore()
        bpy.ops.object.mode_set(mode="OBJECT")
        rows.append(r)
    opened = [r["open"] for r in rows if r["open"] is not None]
    return {"name": name, "mesh": rows[0]["mesh"], "faces": rows[0]["faces"],
            "rate": statistics.median(r["rate"] for r in rows),
            "worst": max(r["worst"] for r in rows),
            "open": statistics.median(opened) if len(opened) == len(rows) else None,
            "open_max": max(opened) if opened else None,
            "inverted": max(r["inverted"] for r in rows), "seeds": len(rows),
            "held": statistics.median(r["held"] for r in rows),
            "held_max": max(r["held"] for r in rows)}


def main() -> None:
    from bench.blender_scale import install

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faces", type=int, nargs="+", default=[5000, 50000])
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=1,
                    help="the drags' first seed (1-3 are the table's; later ones held out)")
    ap.add_argument("--part", nargs="+", default=["grid", "drags"])
    ap.add_argument("--unwraps", nargs="+", default=list(UNWRAPS),
                    choices=list(EVERY_UNWRAP))
    ap.add_argument("--eegt-only", action="store_true", help="no escalation (as before)")
    args = ap.parse_args()
    bpy, ext = install()
    if "grid" in args.part:
        print("| faces | drag set-up s | updates/s | median frame s | worst frame s "
              "(core + writes) | iterations/frame | inverted at end |")
        print("|---:|---:|---:|---:|---:|---:|---:|")
        for f in args.faces:
            r = run(bpy, ext, f, args.frames)
            print(f"| {r['faces']} | {r['setup']:.3f} | {r['rate']:.1f} | {r['median']:.3f} | "
                  f"{r['worst']:.3f} ({r['core']:.3f} + {r['write']:.3f}) | {r['iters']:.0f} | "
                  f"{r['inverted']} |")
    if "drags" in args.part:
        print("\n| unwrap | mesh faces | island faces | seeds | updates/s (median) | worst "
              "frame s | open after s (median, worst) | inverted at end (worst) | "
              "held back (share of the drag: median, worst) |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for name in args.unwraps:
            r = drags(bpy, ext, name, args.seeds, escalate=not args.eegt_only,
                      first=args.first_seed)
            op = "never" if r["open"] is None else f"{r['open']:.2f}, {r['open_max']:.2f}"
            print(f"| {r['name']} | {r['mesh']} | {r['faces']} | {r['seeds']} | "
                  f"{r['rate']:.1f} | {r['worst']:.3f} | {op} | {r['inverted']} | "
                  f"{r['held']:.2f}, {r['held_max']:.2f} |", flush=True)


if __name__ == "__main__":
    main()
