"""The operator and the `eegt` command on a large mesh, in headless Blender (the bpy module).

Builds the extension zip, installs it into a sandboxed user folder, makes a mesh object of
`bench.scale`'s cached mesh and times (1) `mesh.eegt_untangle_smooth` from call to return
against the core's own seconds (so the difference is reading and writing the Blender mesh),
(2) the `eegt` command's run on a saved .blend (`cli.run`: .blend load, run, checked save),
both in this process, after one another; (3) with --fresh N, the command in N fresh
processes against the core in N fresh Python processes, alternating: each pays its own
first-run costs (OpenCL start-up, fresh memory), as a `blender -b` call or a Python script
does. The core's processes run `untangle_and_smooth` on exactly the command's input (the
mesh's float32 positions in the plane frame the command fits: the same 2D bits), so the two
do the same work. Prints markdown tables.

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
    cli = sys.modules[f"{ext.__name__}.operators.command.cli"]
    out = str(Path(tempfile.mkdtemp(prefix="eegt_bench_cli_")) / "out.blend")
    t = time.perf_counter()
    code, rep = cli.run([blend, "-o", out, "--backend", backend, "--quiet"])
    total = time.perf_counter() - t
    o = rep["objects"][0]
    print(json.dumps({"code": code, "total": total, "core": o["seconds"],
                      "global": o["global_iterations"]}))


def _secs(values) -> str:
    """Seconds as a comma list."""
    return ", ".join(f"{v:.2f}" for v in values)


def command_input(core, kind: str, n: int):
    """(2D points, faces) the command's core call gets for the cached mesh: its float32
    positions (z = 0, as `mesh_object` stores them) in the plane frame the command's mesh
    preparation fits (the same bits). `core`: the core package to build them with."""
    import numpy as np

    from bench.scale import mesh_file

    PlaneFrame, faces_from_csr = core.PlaneFrame, core.faces_from_csr
    data = np.load(mesh_file(kind, n))
    offsets = data["offsets"]
    fs = faces_from_csr(offsets[:-1], np.diff(offsets), data["indices"])
    p3 = np.zeros((data["points"].shape[0], 3), dtype=np.float32)
    p3[:, :2] = data["points"]
    p3 = p3.astype(np.float64)
    return PlaneFrame.fit(p3, fs, tol=1e-5).to_2d(p3), fs


def run_core(core, p2, fs, backend: str) -> dict:
    """One core call on the command's input: seconds, global iterations, quality."""
    import numpy as np

    t = time.perf_counter()
    res = core.untangle_and_smooth(p2, fs, fixed=np.zeros(p2.shape[0], dtype=bool), backend=backend)
    return {"seconds": time.perf_counter() - t, "global": res.global_iterations,
            "q_min": res.after.q_min, "q_avg": res.after.q_avg}


def core_child(kind: str, n: int, backend: str) -> None:
    """The core on the command's input in this fresh Python process (no bpy); prints a
    JSON line."""
    import core

    p2, fs = command_input(core, kind, n)
    print(json.dumps(run_core(core, p2, fs, backend)))


def fresh(args, blend: str) -> None:
    """The command and the core on the same input, each in fresh processes, alternating."""
    cmd, core = [], []
    for _ in range(args.fresh):
        out = subprocess.run(
            [sys.executable, "-m", "bench.blender_scale", "--core-child", args.kind,
             str(args.faces), args.backend],
            cwd=ROOT, check=True, capture_output=True, text=True).stdout
        core.append(json.loads(out.strip().splitlines()[-1]))
        out = subprocess.run(
            [sys.executable, "-m", "bench.blender_scale", "--command-child", blend, args.backend],
            cwd=ROOT, check=True, capture_output=True, text=True).stdout
        cmd.append(json.loads(out.strip().splitlines()[-1]))
    total = statistics.median(r["total"] for r in cmd)
    own = statistics.median(r["core"] for r in cmd)
    base = statistics.median(r["seconds"] for r in core)
    print(f"\nfresh processes, {args.backend}, medians of {args.fresh}, alternating "
          f"(global iterations: core {core[0]['global']}, command {cmd[0]['global']})\n")

    print("| run | seconds | median | against the core |")
    print("|---|---|---|---|")
    print(f"| core (`untangle_and_smooth` on the command's input, Python) | "
          f"{_secs(r['seconds'] for r in core)} | {base:.2f} | |")
    print(f"| `eegt` command (.blend load, run, checked save) | {_secs(r['total'] for r in cmd)} | "
          f"{total:.2f} | {100 * (total / base - 1):+.0f} % |")
    print(f"| the command's own core call | {_secs(r['core'] for r in cmd)} | {own:.2f} | "
          f"(the command is {100 * (total / own - 1):+.0f} % of it) |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faces", type=int, default=1_000_000)
    ap.add_argument("--kind", choices=("tri", "quad"), default="tri")
    ap.add_argument("--backend", default="numpy", choices=("numpy", "auto", "opencl"))
    ap.add_argument("--fresh", type=int, default=0, metavar="N",
                    help="also time the command and the core in N fresh processes each")
    ap.add_argument("--repeat", type=int, default=3, metavar="N",
                    help="in this process: the command and the core on its input N times each, "
                         "alternating (medians)")
    ap.add_argument("--fresh-only", action="store_true",
                    help="with --fresh: skip the in-process runs")
    ap.add_argument("--command-child", nargs=2, help=argparse.SUPPRESS)
    ap.add_argument("--core-child", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.command_child:
        command_child(*args.command_child)
        return
    if args.core_child:
        kind, n, backend = args.core_child
        core_child(kind, int(n), backend)
        return
    bpy, ext = install()
    cli = sys.modules[f"{ext.__name__}.operators.command.cli"]
    work = Path(tempfile.mkdtemp(prefix="eegt_bench_cli_"))
    src, out = work / "in.blend", work / "out.blend"
    bpy.ops.wm.read_homefile(use_empty=True)
    mesh_object(bpy, args.kind, args.faces)
    bpy.ops.wm.save_as_mainfile(filepath=str(src))
    if not (args.fresh and args.fresh_only):
        in_process(bpy, cli, args, src, out)
    if args.fresh:
        fresh(args, str(src))


def in_process(bpy, cli, args, src: Path, out: Path) -> None:
    """The operator, then the command, in this process; the .blend load and save alone."""
    rows = []
    bpy.ops.wm.read_homefile(use_empty=True)
    obj = mesh_object(bpy, args.kind, args.faces)
    t = time.perf_counter()
    bpy.ops.mesh.eegt_untangle_smooth(backend=args.backend.upper())
    total = time.perf_counter() - t
    lr = obj.eegt_last_run
    rows.append(("operator (Object Mode, one undo step)", len(obj.data.polygons), total,
                 lr.seconds, lr.q_min_after, lr.q_avg_after, lr.inverted_after))
    core_pkg = sys.modules[f"{cli.__package__.rsplit('.', 2)[0]}.core"]  # the extension's
    p2, fs = command_input(core_pkg, args.kind, args.faces)
    cmd, core = [], []
    for _ in range(args.repeat):
        t = time.perf_counter()
        code, rep = cli.run([str(src), "-o", str(out), "--backend", args.backend, "--quiet"])
        cmd.append((time.perf_counter() - t, rep["objects"][0]))
        core.append(run_core(core_pkg, p2, fs, args.backend))
    total = statistics.median(c[0] for c in cmd)
    own = statistics.median(c[1]["seconds"] for c in cmd)
    o = cmd[-1][1]
    rows.append((f"eegt command (exit {code}; incl. .blend load + save)", o["n_faces"], total,
                 own, o["after"]["q_min"], o["after"]["q_avg"], o["after"]["n_inverted"]))
    base = statistics.median(c["seconds"] for c in core)
    t = time.perf_counter()
    bpy.ops.wm.open_mainfile(filepath=str(src))
    load = time.perf_counter() - t
    t = time.perf_counter()
    bpy.ops.wm.save_as_mainfile(filepath=str(out.with_name("again.blend")))
    save = time.perf_counter() - t

    print(f"\nbackend {args.backend}; .blend load {load:.2f} s, save {save:.2f} s\n")
    print("| run | faces | total s | core s | overhead | q_min | q_avg | inverted |")
    print("|---|---|---|---|---|---|---|---|")
    for name, nf, tot, own_core, qmin, qavg, inv in rows:
        print(f"| {name} | {nf:,} | {tot:.2f} | {own_core:.2f} | "
              f"{100 * (tot / own_core - 1):+.0f} % | {qmin:.3f} | {qavg:.4f} | {inv} |")
    print(f"\nthe command against the core on its input, this process, alternating, medians of "
          f"{args.repeat}: command {_secs(c[0] for c in cmd)} s, core "
          f"{_secs(c['seconds'] for c in core)} s: {100 * (total / base - 1):+.0f} % "
          f"(global iterations {o['global_iterations']} / {core[-1]['global']})")


if __name__ == "__main__":
    main()
