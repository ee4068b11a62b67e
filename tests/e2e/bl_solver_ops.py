"""In Blender: File > Import > Solver mesh, the Untangle & Smooth operator, File > Export >
Solver mesh, as a user's script: blender -b --python bl_solver_ops.py -- IN OUT MOVED.txt
Writes the vertices the operator moved (float32 positions that changed, one index a line) to
MOVED.txt and prints "SOLVER-OPS {json}" (operator results, inverted before/after by
meshcheck)."""
import json
import os
import sys

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import meshcheck


def positions(me):
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


src, dst, moved_txt = sys.argv[sys.argv.index("--") + 1:][:3]
bpy.ops.wm.read_homefile(use_empty=True)  # keeps the enabled extension
imported = bpy.ops.eegt.import_solver_mesh(filepath=src)
ob = bpy.context.active_object
faces = [np.array(p.vertices) for p in ob.data.polygons]
before = positions(ob.data)
smoothed = bpy.ops.mesh.eegt_untangle_smooth()
after = positions(ob.data)
moved = np.flatnonzero((before != after).any(axis=1))
with open(moved_txt, "w") as fh:
    fh.write("".join(f"{i}\n" for i in moved))
exported = bpy.ops.eegt.export_solver_mesh(filepath=dst)
print("SOLVER-OPS " + json.dumps({
    "import": sorted(imported), "untangle": sorted(smoothed), "export": sorted(exported),
    "vertex_groups": sorted(g.name for g in ob.vertex_groups),
    "inverted": [meshcheck.stats(before.astype(np.float64), faces)["n_inverted"],
                 meshcheck.stats(after.astype(np.float64), faces)["n_inverted"]],
    "moved": int(moved.size)}), flush=True)
