"""Live Untangle with Target "Keep Shapes" (``choices.UV_TARGET`` "KEEP"): a UV drag pulls
each face towards its shape as laid out when the drag started (a face tangled then: a
neighbour's, else its 3D face's), made once at the press and sliced to the region's corners
as the "3D" targets are, instead of the regular polygon."""

from __future__ import annotations

import numpy as np
import pytest

from .test_uv_keep_target import GROWTH, H, graded_grid, graded_uv_grid
from .uvtools import uv_values

pytestmark = pytest.mark.blender

N = 12  # vertices per side of the clean graded grid


def _drag_mod(ext):
    return ext.operators.live.drag


def _edit_uv(bpy, obj) -> np.ndarray:
    bpy.ops.object.mode_set(mode="OBJECT")
    out = uv_values(obj)
    bpy.ops.object.mode_set(mode="EDIT")
    return out


def clean_graded_grid(bpy, pins: tuple[tuple[int, int], ...] = ()):
    """``graded_uv_grid`` of N vertices a side without its fold (cells 4:1 to 8.6:1), the UV
    vertices (i, j) of ``pins`` pinned. The object, in Edit Mode; its UVs."""
    obj, uv = graded_uv_grid(bpy, N, fold=False, pins=pins, name="Clean")
    bpy.ops.object.mode_set(mode="EDIT")
    return obj, uv


def _press_corners(drag) -> np.ndarray:
    """(c, 2) the region's corners as laid out at the press (island orientation)."""
    lay = drag.layout
    return lay.oriented_points(lay.orientation())[lay.faces.indices][drag.region.rows]


def _region_face_of_corner(drag) -> np.ndarray:
    """(c,) the region's face (local id) of each region corner."""
    f = drag.region.faces
    return np.repeat(np.arange(f.n_faces), np.diff(f.offsets))


@pytest.mark.parametrize("mirrored", [False, True])
def test_keep_targets_are_the_press_layout_made_once(bpy, ext, mirrored):
    """On a folded layout (also mirrored, u -> -u): every face untangled at the press is
    pulled towards its own corners as laid out then (in its island's orientation), bit for
    bit; the six tangled ones towards what ``core.uv.keep_shape_targets`` gives them (a
    neighbour's); every frame runs on exactly those targets (a session made with them gives
    the same bits frame after frame), not on targets remade from the moved UVs."""
    obj = graded_grid(bpy)  # vertex (4, 4) dragged across its neighbour: 6 faces tangled
    if mirrored:
        me = obj.data
        uv = uv_values(obj)
        uv[:, 0] *= -1.0
        me.attributes["UVMap"].data.foreach_set("vector", uv.ravel())
    bpy.ops.object.mode_set(mode="EDIT")
    uv0 = _edit_uv(bpy, obj)
    at = {lp.vertex_index: uv0[lp.index] for lp in obj.data.loops}
    grab = at[7 * 10 + 7].astype(np.float64)  # UV vertex (7, 7): away from the fold
    params = ext.core.EEGTParams()
    drag = _drag_mod(ext).UVDrag(obj, tuple(grab), params, radius=1e-4,
                                 target_shape="KEEP")
    reg, lay = drag.region, drag.layout
    assert reg.face_ids.size == 81 and np.allclose(lay.points[reg.nodes[reg.grab][0]], grab)
    assert (lay.orientation()[0] < 0) == mirrored and reg.mirrored.all() == mirrored
    shapes = drag.target_shapes
    press = _press_corners(drag)
    assert shapes.shape == press.shape == (4 * 81, 2)
    assert press.tobytes() == reg.points[reg.faces.indices].tobytes()  # the region's own
    faces = np.zeros(lay.faces.n_faces, bool)
    faces[reg.face_ids] = True
    tangled = ext.core.uv.tangled_faces(lay, lay.points, faces)
    assert tangled.sum() == 6
    own = ~tangled[reg.face_ids][_region_face_of_corner(drag)]
    assert shapes[own].tobytes() == press[own].tobytes()
    assert np.any(shapes[~own] != press[~own])  # the tangled faces took a neighbour's
    expect = ext.core.uv.keep_shape_targets(lay, lay.points, faces).targets[reg.rows]
    assert shapes.tobytes() == expect.tobytes()
    live = ext.core.run.live.LiveSession(reg.points, reg.faces, reg.grab, fixed=reg.fixed,
                                         params=params, targets=shapes.copy())
    step = np.array([0.01, 0.005])
    for k in (1, 2, 3, 4, 0, 0):  # a drag, then frames with the cursor still
        cursor = tuple(grab + k * step) if k else None
        frame = drag.step(cursor, budget=None)
        cold = live.frame(drag.targets_for(cursor) if k else None, budget=None)
        assert frame.points.tobytes() == cold.points.tobytes()
    moved = reg.points[reg.faces.indices] != frame.points[reg.faces.indices]
    assert moved[own].any()  # untangled faces moved: their targets stayed the press's
    assert drag.target_shapes.tobytes() == expect.tobytes()
    drag.restore()
    assert _edit_uv(bpy, obj).tobytes() == uv0.tobytes()


def test_keep_without_a_move_changes_nothing(bpy, ext):
    """A clean layout is at its own targets: frames with the cursor still (and at the
    press's place) leave every UV's bits."""
    obj, uv = clean_graded_grid(bpy)
    uv0 = _edit_uv(bpy, obj)
    at = tuple(uv[6 * N + 5])
    drag = _drag_mod(ext).UVDrag(obj, at, ext.core.EEGTParams(), radius=1e-4,
                                 target_shape="KEEP")
    for cursor in (at, None, None):
        frame = drag.step(cursor, budget=None)
        assert frame.stats.n_inverted == 0
    assert frame.stats.q_min > 0.999999
    assert _edit_uv(bpy, obj).tobytes() == uv0.tobytes()


def _aspect(p: np.ndarray) -> np.ndarray:
    """(F,) width / height of quads (corners (F, 4, 2) in grid order): mean of the two
    u-going edges over the mean of the two v-going edges."""
    e = np.roll(p, -1, axis=1) - p
    length = np.hypot(e[..., 0], e[..., 1])
    return (length[:, 0] + length[:, 2]) / (length[:, 1] + length[:, 3])


def _drag_and_rest(bpy, ext, target: str):
    """The clean graded grid, two UVs pinned; UV vertex (5, 6) dragged by 1.5 cells right
    and 4 cells up in 8 frames, then frames with the cursor still until the mesh settles.
    (UVs before, after, the drag)."""
    pins = ((3, 8), (8, 3))
    obj, uv = clean_graded_grid(bpy, pins)
    uv0 = _edit_uv(bpy, obj)
    start = uv[6 * N + 5]
    drag = _drag_mod(ext).UVDrag(obj, tuple(start), ext.core.EEGTParams(), radius=1e-4,
                                 target_shape=target)
    move = np.array([1.5 * 4.0 * H * GROWTH ** 5, 4.0 * H])
    for k in range(1, 9):
        frame = drag.step(tuple(start + move * k / 8), budget=None)
    for _ in range(60):
        frame = drag.step(None, budget=None)
        if frame.settled:
            break
    assert frame.stats.n_inverted == 0
    return uv0, _edit_uv(bpy, obj), drag, pins


def _measures(ext, obj, uv0, uv1, drag, pins):
    """The faces that moved: the median and 75th percentile of their |log| change of
    aspect; how many. Island border and pinned UVs keep their bits."""
    lay = drag.layout
    cv = np.array([lp.vertex_index for lp in obj.data.loops])
    border = ext.core.boundary_nodes(lay.n_nodes, lay.faces)[lay.loop_node]
    pinned = np.isin(cv, [j * N + i for i, j in pins])
    assert uv1[border | pinned].tobytes() == uv0[border | pinned].tobytes()
    assert border.sum() == 4 + 8 * (N - 2) and pinned.sum() == 8
    quads0 = uv0.astype(np.float64).reshape(-1, 4, 2)
    quads1 = uv1.astype(np.float64).reshape(-1, 4, 2)
    moved = np.any(quads1 != quads0, axis=(1, 2))
    change = np.abs(np.log(_aspect(quads1[moved]) / _aspect(quads0[moved])))
    return np.percentile(change, [50, 75]), int(moved.sum())


def test_keep_drag_keeps_the_layouts_aspect_better_than_regular(bpy, ext):
    """After a drag and a rest, the faces that moved keep their laid-out width : height
    (4:1 to 8.6:1) with target Keep Shapes; with Regular they are pulled towards squares.
    Island border and pinned UVs keep their bits either way."""
    keep = _drag_and_rest(bpy, ext, "KEEP")
    (k_median, k_75), k_moved = _measures(ext, bpy.data.objects["Clean"], *keep)
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.wm.read_homefile(use_empty=True)
    regular = _drag_and_rest(bpy, ext, "REGULAR")
    (r_median, r_75), r_moved = _measures(ext, bpy.data.objects["Clean"], *regular)
    assert k_moved == r_moved == (N - 1) ** 2  # the whole island moves (a little) either way
    # measured: Keep Shapes median 0.010, 75 % 0.172; Regular median 0.225, 75 % 0.410
    assert k_median < 0.02 and k_75 < 0.25
    assert r_median > 0.15 and r_75 > 0.3
    assert r_median > 10.0 * k_median
