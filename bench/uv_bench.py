"""Untangle & Smooth UVs side by side with Blender's Minimize Stretch, on scripted assets.

Run: ``python -m bench.uv_bench [--repeat 3] [--quick] [--docs]`` (headless PyPI bpy; the
extension is built and installed into a sandboxed user folder first).

For every asset x tangle of ``bench.uv_assets`` (a few UVs pinned): the input, then each
method from that same input, the whole UV map selected (UV Sync Selection), in Edit Mode:
``uv.eegt_untangle_smooth`` (3D targets, defaults) and ``uv.minimize_stretch`` with 100 and
1000 iterations (its own default is 0: run until the user stops it interactively, which does
nothing when called from a script; 100 is its slider's end). Measured by one code for all:
flipped and inverted faces (in their island's orientation), overlapping faces (inside an
island), distortion against 3D (mean ratio of each UV face against its 3D face's shape:
1 = similar; mean and worst), whether pins and island borders kept their bits, and the
median wall time of ``--repeat`` runs (each from the same input).

``--docs`` rewrites the block between the markers in docs/uv.md.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- uv-bench:begin -->", "<!-- uv-bench:end -->"
METHODS = ("EEGT", "Minimize Stretch 100", "Minimize Stretch 1000")


def install(bpy) -> None:
    sys.path.insert(0, str(ROOT / "scripts"))
    import build_extension

    zip_path = build_extension.build_pure(tempfile.mkdtemp(prefix="eegt_uvbench_"))
    assert bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True) == {"FINISHED"}


def measure(obj, uv, border_loops, pins) -> dict:
    """Counts and distortion of the UV values ``uv`` of ``obj`` (its 3D shapes as targets)."""
    from bench import uv_assets
    from core import faces_from_csr
    from core.metrics.targets import face_shapes_2d
    from core.uv.uv_layout import weld_uv
    from core.uv.uv_untangle import measure as uv_measure

    me = obj.data
    ls, lt, cv = uv_assets.mesh_csr(obj)
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    lay = weld_uv(ls, lt, cv, uv)
    targets = face_shapes_2d(co.reshape(-1, 3).astype(np.float64), faces_from_csr(ls, lt, cv))
    m = uv_measure(lay, lay.points, np.ones(len(ls), bool), targets)
    return {"flipped": m.flipped, "inverted": m.inverted, "overlapping": m.overlapping,
            "mean": m.distortion_mean, "worst": m.distortion_worst}


def run_case(bpy, kind: str, tangle: str, repeat: int, methods: tuple[str, ...]) -> list[dict]:
    from bench import uv_assets

    bpy.ops.wm.read_homefile(use_empty=True)
    kw = {"levels": 2} if kind == "monkey" else {}
    obj = uv_assets.make_asset(bpy, kind, **kw)
    uv_assets.tangle(bpy, obj, tangle)
    pins = uv_assets.pin_some(obj, fraction=0.01)
    uv0 = uv_assets.read_uv(obj).copy()
    lay0 = uv_assets.layout(obj, uv0)
    from core import boundary_nodes
    border = boundary_nodes(lay0.n_nodes, lay0.faces)[lay0.loop_node]
    rows = [{"asset": kind, "tangle": tangle, "faces": len(obj.data.polygons),
             "method": "input", **measure(obj, uv0, border, pins), "seconds": None,
             "pins": 0, "n_pins": int(pins.sum()), "borders": 0.0}]
    bpy.context.scene.tool_settings.use_uv_select_sync = True
    for method in methods:
        times, out = [], None
        for _ in range(repeat):
            uv_assets.write_uv(obj, uv0)
            bpy.ops.object.mode_set(mode="EDIT")
            bpy.ops.mesh.select_all(action="SELECT")
            t = time.perf_counter()
            if method == "EEGT":
                res = bpy.ops.uv.eegt_untangle_smooth()
            else:
                res = bpy.ops.uv.minimize_stretch(iterations=int(method.split()[-1]))
            times.append(time.perf_counter() - t)
            bpy.ops.object.mode_set(mode="OBJECT")
            assert res == {"FINISHED"} or method == "EEGT", (method, res)
            got = uv_assets.read_uv(obj).copy()
            assert out is None or np.array_equal(out, got) or method != "EEGT", \
                "EEGT is deterministic"
            out = got
        rows.append({"asset": kind, "tangle": tangle, "faces": len(obj.data.polygons),
                     "method": method, **measure(obj, out, border, pins),
                     "seconds": statistics.median(times),
                     "pins": int(np.count_nonzero(np.any(out[pins] != uv0[pins], axis=1))),
                     "n_pins": int(pins.sum()),
                     "borders": float(np.abs(out[border] - uv0[border]).max())})
    return rows


def table(rows: list[dict]) -> list[str]:
    out = ["| asset | tangle | faces | method | flipped | inverted | overlapping | "
           "distortion mean | worst | time (s) | pinned UVs moved | border moved by |",
           "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        sec = "" if r["seconds"] is None else f"{r['seconds']:.2f}"
        if r["method"] == "input":
            kept = f"(of {r['n_pins']}) | "
        else:
            border = "0 (bits)" if r["borders"] == 0 else f"{r['borders']:.0e}"
            kept = f"{r['pins']} | {border}"
        name = f"**{r['method']}**" if r["method"] == "EEGT" else r["method"]
        out.append(f"| {r['asset']} | {r['tangle']} | {r['faces']} | {name} | {r['flipped']} | "
                   f"{r['inverted']} | {r['overlapping']} | {r['mean']:.3f} | "
                   f"{r['worst']:.3f} | {sec} | {kept} |")
    return out


def update_docs(block: list[str], path: Path) -> None:
    text = path.read_text()
    a, b = text.index(BEGIN) + len(BEGIN), text.index(END)
    path.write_text(text[:a] + "\n" + "\n".join(block) + "\n" + text[b:])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per method (median)")
    ap.add_argument("--quick", action="store_true", help="sphere only, one run")
    ap.add_argument("--docs", action="store_true", help="rewrite docs/uv.md's table")
    args = ap.parse_args()
    sandbox = tempfile.mkdtemp(prefix="eegt_uvbench_user_")
    os.environ["HOME"] = sandbox  # before bpy is imported
    os.environ["BLENDER_USER_RESOURCES"] = sandbox
    import bpy

    from bench import uv_assets

    install(bpy)
    kinds = ("sphere",) if args.quick else tuple(uv_assets.ASSETS)
    repeat = 1 if args.quick else args.repeat
    rows: list[dict] = []
    for kind in kinds:
        for tangle in uv_assets.TANGLES:
            rows += run_case(bpy, kind, tangle, repeat, METHODS)
            print("\n".join(table(rows)[-len(METHODS) - 1:]), flush=True)
    block = [f"Measured by `python -m bench.uv_bench{' --quick' if args.quick else ''}` "
             f"(Blender {bpy.app.version_string} as the PyPI bpy module, "
             f"{os.cpu_count()} CPU cores shared, NumPy backend, median of {repeat} "
             "runs).", "", *table(rows)]
    print("\n".join(block))
    if args.docs:
        update_docs(block, ROOT / "docs" / "uv.md")
        print("updated docs/uv.md")
    ours = [r for r in rows if r["method"] == "EEGT"]
    return 0 if all(r["inverted"] == 0 and r["pins"] == 0 and r["borders"] == 0
                    for r in ours) else 1


if __name__ == "__main__":
    sys.exit(main())
