"""`make demo`: the main job end to end in a sandboxed headless Blender (PyPI bpy).

Builds the extension zip with Blender's builder, installs it into a temporary user
directory, imports a bundled tangled mesh (OBJ), runs `mesh.eegt_untangle_smooth` on it,
saves out/demo.blend, writes before/after PNGs (inverted faces red) and prints the stats.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default="tri_two_holes", help="tests/data mesh name")
    ap.add_argument("--out", default="out", help="output folder")
    args = ap.parse_args()
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    sandbox = tempfile.mkdtemp(prefix="eegt_demo_user_")
    os.environ["HOME"] = sandbox  # before bpy is imported: user prefs and extensions go here
    os.environ["BLENDER_USER_RESOURCES"] = sandbox
    import bpy
    import numpy as np

    sys.path.insert(0, str(ROOT / "scripts"))
    import build_extension

    from bench.plot import before_after_png
    from core import mesh_stats
    from core.mesh.obj_io import read_obj

    zip_path = build_extension.build_pure(str(out))
    print(f"built {zip_path}")
    assert bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True
    ) == {"FINISHED"}
    bpy.ops.wm.read_homefile(use_empty=True)
    src = ROOT / "tests" / "data" / f"{args.mesh}.obj"
    bpy.ops.wm.obj_import(filepath=str(src), forward_axis="Y", up_axis="Z")
    obj = bpy.context.selected_objects[0]
    bpy.context.view_layer.objects.active = obj
    mesh = obj.data

    def positions() -> np.ndarray:
        buf = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.attributes["position"].data.foreach_get("vector", buf)
        return buf.reshape(-1, 3).astype(np.float64)

    _, faces = read_obj(src)  # same face order as the OBJ importer keeps
    before = positions()
    t = time.perf_counter()
    result = bpy.ops.mesh.eegt_untangle_smooth()
    seconds = time.perf_counter() - t
    after = positions()
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "demo.blend"))
    s0, s1 = mesh_stats(before[:, :2], faces), mesh_stats(after[:, :2], faces)
    before_after_png(out / "demo_before_after.png", before[:, :2], after[:, :2], faces, args.mesh)
    print(f"\noperator: {result}, {seconds:.2f} s in Blender {bpy.app.version_string}")
    print(f"\n| {args.mesh} | inverted | q_min | q_avg |\n|---|---|---|---|")
    print(f"| before | {s0.n_inverted} | {s0.q_min:.4f} | {s0.q_avg:.4f} |")
    print(f"| after | {s1.n_inverted} | {s1.q_min:.4f} | {s1.q_avg:.4f} |")
    print(f"\nwrote {out / 'demo.blend'} and {out / 'demo_before_after.png'}")
    return 0 if result == {"FINISHED"} and s1.n_inverted == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
