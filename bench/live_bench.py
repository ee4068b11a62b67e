"""Live Untangle's per-frame work in headless Blender (the bpy module), docs/live.md.

Installs the built extension (sandboxed, as ``bench.blender_scale``), makes a Grid of about
5 000 and 50 000 quads (one UV island) in Edit Mode and runs the UV tool's drag as its modal
does on each timer tick: the cursor's UV for this tick (a pixel -> UV map standing in for the
UV editor's view, which headless Blender has not), the core frame warm from the last one
under ``core.run.live.FRAME_BUDGET``, the changed UVs written into the edit mesh. The redraw
request (``area.tag_redraw``) only flags the area: there is no area headless, so it is not
timed. Prints a markdown table: updates per second (frames over their summed wall time),
median and worst frame, and the worst frame's split into core and writes.

Run: ``python -m bench.live_bench [--faces 5000 50000] [--frames 40]``.
"""

from __future__ import annotations

import argparse
import statistics
import time

from bench.blender_scale import install


def grid(bpy, faces: int):
    """A Grid primitive of about ``faces`` quads in Edit Mode (its UVs: one island)."""
    n = max(2, round(faces ** 0.5)) + 1
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=n, y_subdivisions=n, size=2.0)
    obj = bpy.context.active_object
    bpy.ops.object.mode_set(mode="EDIT")
    return obj, (n - 1) ** 2


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faces", type=int, nargs="+", default=[5000, 50000])
    ap.add_argument("--frames", type=int, default=40)
    args = ap.parse_args()
    bpy, ext = install()
    print("| faces | drag set-up s | updates/s | median frame s | worst frame s "
          "(core + writes) | iterations/frame | inverted at end |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for f in args.faces:
        r = run(bpy, ext, f, args.frames)
        print(f"| {r['faces']} | {r['setup']:.3f} | {r['rate']:.1f} | {r['median']:.3f} | "
              f"{r['worst']:.3f} ({r['core']:.3f} + {r['write']:.3f}) | {r['iters']:.0f} | "
              f"{r['inverted']} |")


if __name__ == "__main__":
    main()
