"""Live Untangle on drags as people make them (issue 39, bench/live_bench.py's
``human_drag`` on Blender's own unwraps): the pinned UVs and the island border keep their
bits through an escalated drag, and restore is exact. (That every fold opens at rest is
not held here yet: see docs/live.md, "Status".)"""

from __future__ import annotations

import numpy as np

from bench.live_bench import island_drag, monkey


def _uv(bpy, obj) -> np.ndarray:
    """(L, 2) float32 UVs as Blender stores them (read in Object Mode, back to Edit Mode)."""
    bpy.ops.object.mode_set(mode="OBJECT")
    me = obj.data
    buf = np.empty(len(me.loops) * 2, np.float32)
    me.attributes[me.uv_layers.active.name].data.foreach_get("vector", buf)
    bpy.ops.object.mode_set(mode="EDIT")
    return buf.reshape(-1, 2)


def test_drag_keeps_pins_bits_and_ends_valid(bpy, ext):
    """Pinned UVs (Keep Pinned UVs) near the path stay bit-identical."""
    obj = monkey(bpy, "unwrap", levels=1)
    live = ext.operators.live.drag
    drag, path, _ = island_drag(ext, live, obj, 3)
    lay, reg = drag.layout, drag.region
    drag.restore()
    # pin the region's free UVs nearest to the path's middle (not the grabbed one)
    mid = np.asarray(path[len(path) // 2])
    d = np.hypot(*(reg.points - mid).T)
    d[reg.grab] = np.inf
    d[reg.fixed] = np.inf
    pinned_nodes = reg.nodes[np.argsort(d)[:2]]
    import bmesh

    pins = np.isin(lay.loop_node, pinned_nodes)
    bm = bmesh.from_edit_mesh(obj.data)
    layer = bm.loops.layers.uv.active
    for f in bm.faces:
        for lp in f.loops:
            if pins[lp.index]:
                lp[layer].pin_uv = True
    bmesh.update_edit_mesh(obj.data)
    before = _uv(bpy, obj)
    g = reg.nodes[reg.grab[0]]
    drag = live.UVDrag(obj, tuple(lay.points[g]), ext.core.EEGTParams(), grab=np.array([g]))
    for at in path:
        drag.step(tuple(at), budget=None)
    after = _uv(bpy, obj)
    assert np.array_equal(after[pins], before[pins])
    border = ext.core.boundary_nodes(lay.n_nodes, lay.faces)[lay.loop_node]
    assert np.array_equal(after[border], before[border])
    drag.restore()
    assert _uv(bpy, obj).tobytes() == before.tobytes()
