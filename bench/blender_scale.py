"""The operator and the `eegt` command on a large mesh, in headless Blender (the bpy module).

Builds the extension zip, installs it into a sandboxed user folder, makes a mesh object of
`bench.scale`'s cached mesh and times (1) `mesh.eegt_untangle_smooth` from call to return
against the core's own seconds (so the difference is reading and writing the Blender mesh),
(2) the `eegt` command's run on a saved .blend (`cli.run`: .blend load, run, checked save),
both in this process, after one another; (3) with --fresh N, the command in N fresh
processes against the core (`untangle_and_smooth` on the same mesh) in N fresh processes,
alternating: each pays its own first-run costs (OpenCL start-up, fresh memory), as a
`blender -b` call or a Python script does. Prints markdown tables.

Run: `python -m bench.blender_scale [--faces 1000000] [--backend numpy] [--fresh 3]`.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_SANDBOX = tempfile.mkdtemp(prefix="eegt_bench_user_")
# The OpenCL driver keeps its compiled kernels under the user's cache, as it does for a user
# who ran the extension before; a sandboxed HOME alone would compile them again.
os.environ.setdefault("XDG_CACHE_HOME", str(Path.home() / ".cache"))
os.environ["HOME"] = os.environ["BLENDER_USER_RESOURCES"] = _SANDBOX


def install():
    """bpy with the built extension installed and enabled; the extension module."""
    import bpy

    sys.path.insert(0, str(ROOT / "scripts"))
    import build_extension

    zip_path = build_extension.build_pure(tempfile.mkdtemp(prefix="eegt_bench_dist_"))
    bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True)
    return bpy, sys.modules["bl_ext.user_default.eegt_blender"]


def mesh_object(bpy, kind: str, n: int):
    """A new mesh object holding `bench.scale`'s cached mesh (z = 0), selected and active."""
    import numpy as np

    from bench.scale import mesh_file

    data = np.load(mesh_file(kind, n))
    p, offsets, idx = data["points"], data["offsets"], data["indices"]
    me = bpy.data.meshes.new(f"{kind}_{n}")
    me.vertices.add(p.shape[0])
    co = np.zeros((p.shape[0], 3), dtype=np.float32)
    co[:, :2] = p
    me.vertices.foreach_set("co", co.ravel())
    me.loops.add(idx.size)
    me.loops.foreach_set("vertex_index", idx.astype(np.int32))
    me.polygons.add(offsets.size - 1)
    me.polygons.foreach_set("loop_start", offsets[:-1].astype(np.int32))
    me.update(calc_edges=True)
    obj = bpy.data.objects.new(me.name, me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    return obj


def command_child(blend: str, backend: str) -> None:
    """One `eegt` command run on `blend` in this fresh process; prints a JSON line."""
    _, ext = install()
    cli = sys.modules[f"{ext.__name__}.operators.cli"]
    out = str(Path(tempfile.mkdtemp(prefix="eegt_bench_cli_")) / "out.blend")
    t = time.perf_counter()
    code, rep = cli.run([blend, "-o", out, "--backend", backend, "--quiet"])
    total = time.perf_counter() - t
    print(json.dumps({"code": code, "total": total, "core": rep["objects"][0]["seconds"]}))


def fresh(args, blend: str) -> None:
    """The command and the core, each in fresh processes, alternating."""
    from bench.scale import mesh_file

    path = str(mesh_file(args.kind, args.faces))
    cmd, core = [], []
    for _ in range(args.fresh):
        out = subprocess.run(
            [sys.executable, "-m", "bench.scale", "--child", path, args.backend, "{}"],
            cwd=ROOT, check=True, capture_output=True, text=True).stdout
        core.append(json.loads(out.strip().splitlines()[-1])["seconds"])
        out = subprocess.run(
            [sys.executable, "-m", "bench.blender_scale", "--command-child", blend, args.backend],
            cwd=ROOT, check=True, capture_output=True, text=True).stdout
        cmd.append(json.loads(out.strip().splitlines()[-1]))
    a, b = statistics.median(r["total"] for r in cmd), statistics.median(core)
    cmd_s = ", ".join(f"{r['total']:.2f}" for r in cmd)
    core_s = ", ".join(f"{c:.2f}" for c in core)
    own = ", ".join(f"{r['core']:.2f}" for r in cmd)
    print(f"\nfresh processes, {args.backend}, medians of {args.fresh}, alternating\n")
    print("| run | seconds | median | against the core |")
    print("|---|---|---|---|")
    print(f"| core (`untangle_and_smooth`, Python) | {core_s} | {b:.2f} | |")
    print(f"| `eegt` command (.blend load, run, checked save) | {cmd_s} | {a:.2f} | "
          f"{100 * (a / b - 1):+.0f} % |")
    print(f"\n(the command's own core seconds: {own})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faces", type=int, default=1_000_000)
    ap.add_argument("--kind", choices=("tri", "quad"), default="tri")
    ap.add_argument("--backend", default="numpy", choices=("numpy", "auto", "opencl"))
    ap.add_argument("--fresh", type=int, default=0, metavar="N",
                    help="also time the command and the core in N fresh processes each")
    ap.add_argument("--command-child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.command_child:
        command_child(*args.command_child)
        return
    bpy, ext = install()
    cli = sys.modules[f"{ext.__name__}.operators.cli"]
    rows = []

    bpy.ops.wm.read_homefile(use_empty=True)
    obj = mesh_object(bpy, args.kind, args.faces)
    t = time.perf_counter()
    bpy.ops.mesh.eegt_untangle_smooth(backend=args.backend.upper())
    total = time.perf_counter() - t
    lr = obj.eegt_last_run
    rows.append(("operator (Object Mode, one undo step)", len(obj.data.polygons), total,
                 lr.seconds, lr.q_min_after, lr.q_avg_after, lr.inverted_after))

    work = Path(tempfile.mkdtemp(prefix="eegt_bench_cli_"))
    bpy.ops.wm.read_homefile(use_empty=True)
    obj = mesh_object(bpy, args.kind, args.faces)
    src, out = work / "in.blend", work / "out.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(src))
    t = time.perf_counter()
    code, rep = cli.run([str(src), "-o", str(out), "--backend", args.backend, "--quiet"])
    total = time.perf_counter() - t
    o = rep["objects"][0]
    rows.append((f"eegt command (exit {code}; incl. .blend load + save)", o["n_faces"], total,
                 o["seconds"], o["after"]["q_min"], o["after"]["q_avg"], o["after"]["n_inverted"]))
    t = time.perf_counter()
    bpy.ops.wm.open_mainfile(filepath=str(src))
    load = time.perf_counter() - t
    t = time.perf_counter()
    bpy.ops.wm.save_as_mainfile(filepath=str(work / "again.blend"))
    save = time.perf_counter() - t

    print(f"\nbackend {args.backend}; .blend load {load:.2f} s, save {save:.2f} s\n")
    print("| run | faces | total s | core s | overhead | q_min | q_avg | inverted |")
    print("|---|---|---|---|---|---|---|---|")
    for name, nf, tot, core, qmin, qavg, inv in rows:
        print(f"| {name} | {nf:,} | {tot:.2f} | {core:.2f} | {100 * (tot / core - 1):+.0f} % | "
              f"{qmin:.3f} | {qavg:.4f} | {inv} |")
    if args.fresh:
        fresh(args, str(src))


if __name__ == "__main__":
    main()
