"""Live Untangle's frame step on the installed extension (headless bpy, Edit Mode): the
drags the modal tools run per frame, and their restore."""

from __future__ import annotations

import numpy as np
import pytest

from .conftest import positions
from .uvtools import uv_values

pytestmark = pytest.mark.blender


def _grid(bpy, n: int = 24):
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=n, y_subdivisions=n, size=2.0)
    obj = bpy.context.active_object
    bpy.ops.object.mode_set(mode="EDIT")
    return obj


def _live(ext):
    return ext.operators.live


def _drag_uvs(bpy, ext, obj, path):
    """A UVDrag of the UV vertex nearest to the UV centre along ``path`` (UV offsets)."""
    drag_mod = _live(ext).drag
    params = ext.core.EEGTParams()
    drag = drag_mod.UVDrag(obj, (0.5, 0.5), params, radius=0.05)
    frames = [drag.step((0.5 + du, 0.5 + dv), budget=None) for du, dv in path]
    return drag, frames


def _edit_uv(bpy, obj) -> np.ndarray:
    bpy.ops.object.mode_set(mode="OBJECT")
    out = uv_values(obj)
    bpy.ops.object.mode_set(mode="EDIT")
    return out


def _edit_positions(bpy, obj) -> np.ndarray:
    bpy.ops.object.mode_set(mode="OBJECT")
    out = positions(obj)
    bpy.ops.object.mode_set(mode="EDIT")
    return out


def test_uv_drag_untangles_keeps_border_bits_and_restores_every_bit(bpy, ext):
    obj = _grid(bpy)
    before = _edit_uv(bpy, obj)
    path = [(0.03 * k, 0.02 * k) for k in range(1, 8)]
    drag, frames = _drag_uvs(bpy, ext, obj, path)
    for _ in range(40):
        frame = drag.step(None, budget=None)
        if frame.status != "tangled":
            break
    after = _edit_uv(bpy, obj)
    lay = drag.layout
    core = ext.core
    border = core.boundary_nodes(lay.n_nodes, lay.faces)
    on_border = border[lay.loop_node]
    assert frame.stats.n_inverted == 0
    assert np.array_equal(after[on_border], before[on_border])
    grabbed = lay.loop_node == drag.region.nodes[drag.region.grab][0]
    moved = after[grabbed].astype(np.float64) - before[grabbed]
    assert np.allclose(moved, [0.21, 0.14], atol=1e-6)
    assert np.count_nonzero(np.any(after != before, axis=1)) > 4 * grabbed.sum()
    assert frames[-1].stats.n_inverted >= 0 and len(frames) == 7
    drag.restore()
    assert _edit_uv(bpy, obj).tobytes() == before.tobytes()


def test_uv_drag_frame_is_the_core_frame_on_the_same_input(bpy, ext):
    """The values written are the core session's frame, rounded to float32."""
    obj = _grid(bpy, 12)
    drag, frames = _drag_uvs(bpy, ext, obj, [(0.04, 0.01)])
    reg = drag.region
    live = ext.core.run.live.LiveSession(reg.points, reg.faces, reg.grab, fixed=reg.fixed,
                                     params=ext.core.EEGTParams(),
                                     targets=drag.session.targets)
    cold = live.frame(drag.targets_for((0.54, 0.51)), budget=None)
    assert np.array_equal(cold.points, frames[0].points)
    written = _edit_uv(bpy, obj)
    lay = drag.layout
    lut = np.full(lay.n_nodes, -1)
    lut[reg.nodes] = np.arange(reg.nodes.size)
    expect = reg.to_uv(cold.points)[lut[lay.loop_node]].astype(np.float32)
    assert written.tobytes() == expect.tobytes()


def test_uv_drag_without_vertex_under_cursor_or_selection_is_refused(bpy, ext):
    obj = _grid(bpy, 6)
    bpy.ops.mesh.select_all(action="DESELECT")
    with pytest.raises(ValueError, match="no UV vertex under the cursor"):
        _live(ext).drag.UVDrag(obj, (5.0, 5.0), ext.core.EEGTParams(), radius=0.01)


def test_mesh_drag_moves_in_plane_keeps_boundary_and_restores(bpy, ext):
    obj = _grid(bpy, 20)
    before = _edit_positions(bpy, obj)
    centre = int(np.argmin(np.linalg.norm(before[:, :2], axis=1)))
    drag = _live(ext).drag.MeshDrag(obj, ext.core.EEGTParams(), grab=np.array([centre]))
    at0 = drag.job.points2d[drag.grab][0]
    for k in range(6):  # the first position is the press: the anchor of the offsets
        frame = drag.step(at0 + np.array([0.08, 0.05]) * k, budget=None)
    for _ in range(40):
        frame = drag.step(None, budget=None)
        if frame.status != "tangled":
            break
    after = _edit_positions(bpy, obj)
    rim = np.isclose(np.abs(before[:, :2]), 1.0).any(axis=1)
    assert frame.stats.n_inverted == 0
    assert np.array_equal(after[rim], before[rim])
    assert np.array_equal(after[:, 2], before[:, 2])
    end = drag.job.frame.to_3d((at0 + np.array([0.4, 0.25]))[None, :])[0]
    assert np.allclose(after[centre], end, atol=1e-6)
    assert np.linalg.norm(after[centre] - before[centre]) > 0.45
    drag.restore()
    assert _edit_positions(bpy, obj).tobytes() == before.tobytes()


def test_live_tools_registered_with_menus_and_panels(bpy, ext):
    assert hasattr(bpy.types, "UV_OT_eegt_live_untangle")
    assert hasattr(bpy.types, "MESH_OT_eegt_live_untangle")
    assert hasattr(bpy.types, "IMAGE_PT_eegt_live")
    assert _live(ext).ops_live.status_text(None).startswith("Live Untangle")
