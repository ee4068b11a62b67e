"""Run inside Blender: read one object's UV map and mesh from a .blend with foreach_get, for
the e2e UV checks (bl_uv_check.py and e2e_uv_seams.py's check script)."""
import bpy
import numpy as np


def read(path, name):
    """(UVs (L, 2) float32, pinned loops (L,), positions (N, 3) float32, corner vertices (L,),
    faces as lists of loop indices) of object ``name`` in the .blend at ``path``."""
    bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
    me = bpy.data.objects[name].data
    n = len(me.loops)
    uv = np.empty(2 * n, np.float32)
    me.attributes[me.uv_layers.active.name].data.foreach_get("vector", uv)
    pins = np.zeros(n, bool)
    if len(me.uv_layers.active.pin) == n:
        me.uv_layers.active.pin.foreach_get("value", pins)
    co = np.empty(3 * len(me.vertices), np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    cv = np.empty(n, np.int64)
    me.loops.foreach_get("vertex_index", cv)
    faces = [list(range(p.loop_start, p.loop_start + p.loop_total)) for p in me.polygons]
    return uv.reshape(-1, 2), pins, co.reshape(-1, 3), cv, faces
