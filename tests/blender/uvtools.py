"""Helpers of the UV tests: assets (bench.uv_assets), UV reads, selections made by Blender."""

from __future__ import annotations

import numpy as np

from bench import uv_assets


def uv_values(obj, name: str | None = None) -> np.ndarray:
    """(L, 2) float32 copy of a UV map (default: the active one)."""
    me = obj.data
    layer = me.uv_layers[name] if name else me.uv_layers.active
    buf = np.empty(len(me.loops) * 2, np.float32)
    me.attributes[layer.name].data.foreach_get("vector", buf)
    return buf.reshape(-1, 2)


def corner_verts(obj) -> np.ndarray:
    me = obj.data
    cv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", cv)
    return cv


def loop_faces(obj) -> np.ndarray:
    """Face of every loop."""
    me = obj.data
    ls = np.empty(len(me.polygons), np.int64)
    lt = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("loop_start", ls)
    me.polygons.foreach_get("loop_total", lt)
    out = np.empty(len(me.loops), np.int64)
    out[np.repeat(ls, lt) + np.arange(lt.sum()) - np.repeat(np.cumsum(lt) - lt, lt)] = \
        np.repeat(np.arange(len(ls)), lt)
    return out


def uv_vertex_groups(obj, uv: np.ndarray) -> np.ndarray:
    """(L,) UV vertex of every loop, computed here from scratch: loops of one mesh vertex
    with bit-equal UVs (after -0 -> +0)."""
    cv = corner_verts(obj)
    bits = (uv + np.float32(0)).view(np.uint32).astype(np.int64)
    keys = np.stack([cv, bits[:, 0], bits[:, 1]], axis=1)
    return np.unique(keys, axis=0, return_inverse=True)[1].reshape(-1)


def tangled(bpy, kind: str = "sphere", tangle: str = "jitter", **kw):
    """An unwrapped asset with a tangled active UV map, Object Mode, selected and active."""
    obj = uv_assets.make_asset(bpy, kind, **kw)
    uv_assets.tangle(bpy, obj, tangle)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return obj


def set_mesh_selection(obj, faces: np.ndarray) -> None:
    """Select exactly ``faces`` (and their vertices and edges) in the mesh (Object Mode)."""
    me = obj.data
    cv = corner_verts(obj)
    vsel = np.zeros(len(me.vertices), bool)
    vsel[cv[faces[loop_faces(obj)]]] = True
    ev = np.empty(2 * len(me.edges), np.int64)
    me.edges.foreach_get("vertices", ev)
    me.polygons.foreach_set("select", faces)
    me.vertices.foreach_set("select", vsel)
    me.edges.foreach_set("select", vsel[ev.reshape(-1, 2)].all(axis=1))


def uv_select_by_blender(bpy, obj, faces: np.ndarray) -> None:
    """In Edit Mode, UV Sync Selection off: select the UVs of ``faces`` with Blender's own
    operators (pin exactly their loops, Select Pinned, restore the pins)."""
    me = obj.data
    bpy.ops.object.mode_set(mode="OBJECT")
    layer = me.uv_layers.active  # looked up in Object Mode: a mode switch reallocates it
    if hasattr(layer, "pin_ensure"):
        layer.pin_ensure()
    old = np.zeros(len(me.loops), bool)
    layer.pin.foreach_get("value", old)
    layer.pin.foreach_set("value", faces[loop_faces(obj)])
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.uv.select_all(action="DESELECT")
    assert bpy.ops.uv.select_pinned() == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    layer = me.uv_layers.active
    if hasattr(layer, "pin_ensure"):
        layer.pin_ensure()
    layer.pin.foreach_set("value", old)
    bpy.ops.object.mode_set(mode="EDIT")
