"""A user's batch script, run as: blender -b --python-exit-code 1 --python bl_batch.py --
OUTDIR IN1.obj IN2.obj ...  For each file: import, run the operator on it, check the result with
our own meshcheck, export OBJ to OUTDIR. Raises (exit code 1) if any mesh stays tangled."""
import os
import sys

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import meshcheck


def mesh_arrays(me):
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    faces = [np.array(p.vertices) for p in me.polygons]
    return co.reshape(-1, 3).astype(np.float64), faces


args = sys.argv[sys.argv.index("--") + 1:]
outdir, inputs = args[0], args[1:]
bad = []
for path in inputs:
    bpy.ops.wm.read_homefile(use_empty=True)  # keeps the enabled extension
    bpy.ops.wm.obj_import(filepath=path)
    ob = bpy.context.selected_objects[0]
    bpy.context.view_layer.objects.active = ob
    before = meshcheck.stats(*mesh_arrays(ob.data))
    res = bpy.ops.mesh.eegt_untangle_smooth()
    after = meshcheck.stats(*mesh_arrays(ob.data))
    print(f"BATCH {os.path.basename(path)}: {res}, inverted {before['n_inverted']} -> "
          f"{after['n_inverted']}, q_avg {before['q_avg']:.3f} -> {after['q_avg']:.3f}")
    if after["n_inverted"] or not after["finite"]:
        bad.append(os.path.basename(path))
    bpy.ops.wm.obj_export(filepath=os.path.join(outdir, os.path.basename(path)),
                          export_selected_objects=True, export_normals=False, export_uv=False,
                          export_materials=False)
if bad:
    raise RuntimeError(f"still tangled after EEGT: {bad}")
print("BATCH OK", len(inputs), "files")
