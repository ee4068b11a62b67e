"""Live Untangle's frame step on the installed extension (headless bpy, Edit Mode): the
drags the modal tools run per frame, and their restore."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from .conftest import positions
from .uvtools import (
    corner_verts,
    face_signed_areas,
    loop_faces,
    one_ulp_apart,
    set_mesh_selection,
    uv_values,
)

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


def _set_uv(bpy, obj, uv: np.ndarray) -> None:
    """Write every value of the active UV map (float32 (L, 2)), back in Edit Mode."""
    bpy.ops.object.mode_set(mode="OBJECT")
    me = obj.data
    me.attributes[me.uv_layers.active.name].data.foreach_set(
        "vector", np.ascontiguousarray(uv, np.float32).ravel())
    bpy.ops.object.mode_set(mode="EDIT")


def _layout(ext, obj, uv: np.ndarray):
    """The extension's welded UV map of ``obj`` with the values ``uv``."""
    me = obj.data
    ls = np.empty(len(me.polygons), np.int64)
    lt = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("loop_start", ls)
    me.polygons.foreach_get("loop_total", lt)
    return ext.core.uv.weld_uv(ls, lt, corner_verts(obj), uv)


def _select_faces(bpy, obj, faces: np.ndarray) -> None:
    """Select exactly ``faces`` in the mesh (UV Sync Selection shows them), in Edit Mode."""
    bpy.ops.object.mode_set(mode="OBJECT")
    set_mesh_selection(obj, faces)
    bpy.ops.object.mode_set(mode="EDIT")


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
    """The values written are the core session's frame, rounded to float32 (on a map with one
    value per UV vertex: see the next test for loops a float32 step apart)."""
    obj = _grid(bpy, 12)
    lay0 = _layout(ext, obj, _edit_uv(bpy, obj))
    _set_uv(bpy, obj, lay0.points[lay0.loop_node])  # 4.2-4.5's Grid: some a step apart
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


def test_uv_drag_writes_one_value_to_each_moved_uv_vertex_and_keeps_unmoved_split_loops(
        bpy, ext):
    """Loops of one UV vertex a float32 step apart (as 4.2-4.5's Grid primitive stores some):
    every loop of a UV vertex the frame moved gets the frame's value; loops of UV vertices
    it did not move keep their own bits, as Untangle & Smooth UVs keeps them."""
    obj = _grid(bpy, 12)
    lay0 = _layout(ext, obj, _edit_uv(bpy, obj))
    before = one_ulp_apart(lay0.points[lay0.loop_node].astype(np.float32), lay0.loop_node, 5)
    _set_uv(bpy, obj, before)
    drag, frames = _drag_uvs(bpy, ext, obj, [(0.04, 0.01)])
    written = _edit_uv(bpy, obj)
    reg, lay = drag.region, drag.layout
    lut = np.full(lay.n_nodes, -1)
    lut[reg.nodes] = np.arange(reg.nodes.size)
    local = lut[lay.loop_node]
    moved = np.any(frames[0].points != reg.points, axis=1)[local]
    split = np.any(before != lay.points[lay.loop_node].astype(np.float32), axis=1)
    assert (moved & split).sum() > 10 and (~moved & split).sum() > 10
    frame_uv = reg.to_uv(frames[0].points)[local].astype(np.float32)
    assert written[moved].tobytes() == frame_uv[moved].tobytes()
    assert written[~moved].tobytes() == before[~moved].tobytes()


def _left_half(obj, uv: np.ndarray) -> np.ndarray:
    """(F,) bool: faces whose UV centre has u < 0.5."""
    lf = loop_faces(obj)
    u = np.bincount(lf, uv[:, 0].astype(np.float64)) / np.bincount(lf)
    return u < 0.5


def test_uv_drag_selection_scope_moves_every_loop_of_the_grabbed_uv_vertex(bpy, ext):
    """Scope Selection, the grabbed UV vertex on the selection's border: its loops in the
    unselected faces move with it (no tear); the unselected faces' other UVs stay."""
    obj = _grid(bpy, 12)
    before = _edit_uv(bpy, obj)
    lay0 = _layout(ext, obj, before)
    sel = _left_half(obj, before)
    _select_faces(bpy, obj, sel)
    drag = _live(ext).drag.UVDrag(obj, (0.5, 0.5), ext.core.EEGTParams(), radius=0.01,
                                  scope="selection")
    for k in range(1, 5):
        drag.step((0.5 - 0.01 * k, 0.5 + 0.0075 * k), budget=None)
    after = _edit_uv(bpy, obj)
    node = drag.region.nodes[drag.region.grab][0]
    assert np.allclose(lay0.points[node], [0.5, 0.5], rtol=0, atol=1e-7)
    mine = np.flatnonzero(lay0.loop_node == node)
    outside = ~sel[loop_faces(obj)]
    assert outside[mine].sum() == 2 and (~outside[mine]).sum() == 2
    target = lay0.points[node] + (np.array([0.46, 0.53]) - np.array([0.5, 0.5]))
    assert np.array_equal(after[mine], np.repeat(target[None].astype(np.float32), 4, axis=0))
    selected_nodes = np.zeros(lay0.n_nodes, bool)
    selected_nodes[lay0.loop_node[~outside]] = True
    rest = outside & ~selected_nodes[lay0.loop_node]
    assert np.array_equal(after[rest], before[rest])


def test_uv_drag_selection_scope_without_vertex_under_cursor_moves_the_selection_rigidly(
        bpy, ext):
    """Scope Selection, nothing under the cursor: every UV vertex of the selected faces
    moves by the cursor's offset (all their loops, unselected faces' too); the rest stays."""
    obj = _grid(bpy, 12)
    before = _edit_uv(bpy, obj)
    lay0 = _layout(ext, obj, before)
    sel = _left_half(obj, before)
    _select_faces(bpy, obj, sel)
    drag = _live(ext).drag.UVDrag(obj, (5.0, 5.0), ext.core.EEGTParams(), radius=0.01,
                                  scope="selection")
    frame = drag.step((5.1, 4.95), budget=None)
    after = _edit_uv(bpy, obj)
    grabbed = np.zeros(lay0.n_nodes, bool)
    grabbed[lay0.loop_node[sel[loop_faces(obj)]]] = True
    moving = grabbed[lay0.loop_node]
    offset = np.array([5.1, 4.95]) - np.array([5.0, 5.0])
    expect = (lay0.points[lay0.loop_node[moving]] + offset).astype(np.float32)
    assert after[moving].tobytes() == expect.tobytes()
    assert after[~moving].tobytes() == before[~moving].tobytes()
    # the 13 UV vertices on u = 0.5: 11 in two unselected faces each, the 2 ends in one
    assert (moving & ~sel[loop_faces(obj)]).sum() == 2 * 11 + 2
    assert frame.stats.n_inverted == 0
    drag.restore()
    assert _edit_uv(bpy, obj).tobytes() == before.tobytes()
    with pytest.raises(ValueError, match="outside the faces that move"):  # an unselected UV
        _live(ext).drag.UVDrag(obj, (0.75, 0.5), ext.core.EEGTParams(), radius=0.01,
                               scope="selection")


def test_uv_drag_cursor_at_1e300_is_clamped_and_writes_only_finite_uvs(bpy, ext):
    """A cursor at +-1e300 (or NaN) writes no inf or NaN and warns nothing: the grabbed
    vertex stops at the bound (the region's box grown by CURSOR_REACH times its side)."""
    obj = _grid(bpy, 12)
    params = ext.core.EEGTParams()
    drag = _live(ext).drag.UVDrag(obj, (0.5, 0.5), params, radius=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for cursor in [(1e300, -1e300), (np.nan, 0.5), (-1e300, 1e300)]:
            drag.step(cursor, iterations=3, budget=None)
            uv = _edit_uv(bpy, obj)
            assert np.isfinite(uv).all()
    node = drag.region.nodes[drag.region.grab][0]
    mine = drag.layout.loop_node == node
    reach = ext.core.run.live.CURSOR_REACH
    pts = drag.layout.points[drag.region.nodes]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    side = float((hi - lo).max())
    corner = np.array([lo[0] - reach * side, hi[1] + reach * side])
    expect = (np.array([0.5, 0.5]) + (corner - np.array([0.5, 0.5]))).astype(np.float32)
    assert np.array_equal(uv[mine], np.repeat(expect[None], mine.sum(), axis=0))


def test_mesh_drag_cursor_at_1e39_is_clamped_and_writes_only_finite_positions(bpy, ext):
    """A 3D View cursor at 1e39 in the mesh's plane writes no inf: the grabbed vertex stops at
    the bound (the mesh's box in its plane grown by CURSOR_REACH times its side)."""
    obj = _grid(bpy, 10)
    before = _edit_positions(bpy, obj)
    centre = int(np.argmin(np.linalg.norm(before[:, :2], axis=1)))
    drag = _live(ext).drag.MeshDrag(obj, ext.core.EEGTParams(), grab=np.array([centre]))
    at0 = drag.job.points2d[drag.grab][0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        drag.step(at0, iterations=3, budget=None)
        for at in [at0 + 1e39, np.array([np.nan, 0.0]), at0 - 1e39]:
            drag.step(at, iterations=3, budget=None)
            assert np.isfinite(_edit_positions(bpy, obj)).all()
    after = _edit_positions(bpy, obj)
    reach = ext.core.run.live.CURSOR_REACH
    pts = drag.job.points2d
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    side = float((hi - lo).max())
    target = at0 + ((lo - reach * side) - at0)
    expect = drag.job.frame.to_3d(target[None, :])[0].astype(np.float32)
    assert np.array_equal(after[centre], expect)


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


def _check_valid_border_kept_grab_inside(bpy, ext, obj, drag, before: np.ndarray) -> None:
    """The drag out of the grid's island written back: no face of the map inverted (signed
    areas of the written loops), every border loop bit-identical, the grabbed UV vertex
    back inside the island (the cursor was at v 1.12)."""
    after = _edit_uv(bpy, obj).astype(np.float64)
    assert (face_signed_areas(after, loop_faces(obj)) > 0.0).all()
    lay = drag.layout
    on_border = ext.core.boundary_nodes(lay.n_nodes, lay.faces)[lay.loop_node]
    assert np.array_equal(after[on_border], before[on_border])
    grabbed = lay.loop_node == drag.region.nodes[drag.region.grab][0]
    assert (after[grabbed, 1] < 1.0).all()


def test_uv_drag_release_that_cannot_open_the_fold_lets_the_grabbed_vertex_go(bpy, ext):
    """A UV vertex dragged out of its island, the rest's pull off: with it held at the
    cursor the fold cannot open (a release would put every value back); the session's
    one-shot repair with the vertex let go, written by the drag, leaves no face of the map
    inverted (signed areas of the written loops) and every border loop bit-identical."""
    obj = _grid(bpy)
    before = _edit_uv(bpy, obj)
    drag = _live(ext).drag.UVDrag(obj, (0.5, 0.9), ext.core.EEGTParams(), radius=0.05)
    drag.session.pull_after = None
    frame = drag.step((0.5, 1.12), budget=None)
    for _ in range(100):
        if drag.session.finishing(frame) != "go on":
            break
        frame = drag.step(None, budget=None)
    assert drag.session.finishing(frame) == "restore"
    kept = drag.session.released(frame.points)
    assert kept is not None
    drag.write_points(kept)
    _check_valid_border_kept_grab_inside(bpy, ext, obj, drag, before)


def test_uv_drag_resting_out_of_its_island_is_pulled_back_valid(bpy, ext):
    """The same drag out of the island with the rest's pull (the default): the frames at
    rest (a release's finishing frames) end with the vertex held inside the island, the
    header's ``held_back`` its distance from the cursor; the written map has no face
    inverted and every border loop bit-identical, and a release keeps it."""
    obj = _grid(bpy)
    before = _edit_uv(bpy, obj)
    drag = _live(ext).drag.UVDrag(obj, (0.5, 0.9), ext.core.EEGTParams(), radius=0.05)
    drag.session.pull_after = 0.0
    frame = drag.step((0.5, 1.12), budget=None)
    for _ in range(400):
        if frame.status != "tangled" and not frame.pull_iterations:
            break
        frame = drag.step(None, budget=None)
    assert drag.session.finishing(frame) == "keep"
    assert frame.held_back > 0.1
    _check_valid_border_kept_grab_inside(bpy, ext, obj, drag, before)
