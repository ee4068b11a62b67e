"""Live Untangle on drags as people make them (issue 39, bench/live_bench.py's
``human_drag`` on Blender's own unwraps): the pinned UVs and the island border keep their
bits through an escalated drag, restore is exact, and at rest (the rest's pull) no face
of the map is left inverted."""

from __future__ import annotations

import numpy as np
import pytest

from bench.live_bench import island_drag, monkey

from .uvtools import face_signed_areas, loop_faces


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


@pytest.mark.parametrize(("how", "levels", "seed"), [("smart", 2, 1), ("smart", 2, 2),
                                                    ("smart", 2, 6),  # past the border
                                                    ("unwrap", 1, 1), ("unwrap", 1, 2)])
def test_drag_then_rest_leaves_no_face_flipped(bpy, ext, how, levels, seed):
    """A human drag on Suzanne's Smart UV / Unwrap, then the cursor still (the rest's pull
    without its wait, frames without a time budget): no face of the map has its UV area's
    sign changed from the unwrap's (signed areas of the written loops, counted here), the
    island border keeps its bits, and the grabbed vertex is at the cursor or held back
    (``held_back``) as far as the written UV shows."""
    obj = monkey(bpy, how, levels=levels)
    live = ext.operators.live.drag
    drag, path, _ = island_drag(ext, live, obj, seed)
    drag.session.pull_after = 0.0
    before = _uv(bpy, obj)
    face = loop_faces(obj)
    area0 = face_signed_areas(before, face)
    for at in path:
        frame = drag.step(tuple(at), budget=None)
    for _ in range(300):
        frame = drag.step(None, budget=None)
        if frame.settled:
            break
    after = _uv(bpy, obj)
    area1 = face_signed_areas(after, face)
    assert (area0 != 0.0).all()
    assert not (np.sign(area1) != np.sign(area0)).any()
    lay = drag.layout
    border = ext.core.boundary_nodes(lay.n_nodes, lay.faces)[lay.loop_node]
    assert np.array_equal(after[border], before[border])
    g = drag.region.nodes[drag.region.grab[0]]
    cursor = drag.targets_for(tuple(path[-1]))[0]  # region coordinates: UV unless mirrored
    if drag.region.mirrored[drag.region.grab[0]]:
        cursor[0] = -cursor[0]
    got = after[lay.loop_node == g].astype(np.float64)
    assert np.allclose(np.hypot(*(got - cursor).T), frame.held_back, rtol=0, atol=1e-6)
    drag.restore()
