"""Run inside Blender (background, factory start-up): a Grid of 24 x 24 quads with its own
UVs (one square island) and three interior UV vertices pinned, saved selected and active as
"Live". Args after --: OUTPUT.blend"""
import sys

import bpy
import numpy as np

out = sys.argv[sys.argv.index("--") + 1]
for ob in list(bpy.data.objects):
    bpy.data.objects.remove(ob)
bpy.ops.mesh.primitive_grid_add(x_subdivisions=25, y_subdivisions=25, size=2.0)
ob = bpy.context.active_object
ob.name = "Live"
me = ob.data
cv = np.empty(len(me.loops), np.int64)
me.loops.foreach_get("vertex_index", cv)
pins = np.isin(cv, [25 * 6 + 6, 25 * 18 + 7, 25 * 8 + 19])
me.uv_layers.active.pin.foreach_set("value", pins)
bpy.context.view_layer.objects.active = ob
ob.select_set(True)
bpy.ops.wm.save_as_mainfile(filepath=out)
print("saved", out, len(me.polygons), "faces,", int(pins.sum()), "pinned UVs")
