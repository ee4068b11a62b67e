"""The rules a live drag follows around its frames (core.run.live): the cursor's bound, the
float32 guard on what is written, a selection dragged whole, every loop of a UV vertex."""

from __future__ import annotations

import numpy as np
import pytest
from uvdata import grid_uv

from bench.meshgen import jittered_square
from core.run.live import (
    CURSOR_REACH,
    LiveSession,
    clamp_cursor,
    cursor_bounds,
    storable_float32,
    uv_region,
    uv_vertex_corners,
)
from core.uv.uv_layout import weld_uv

F32_MAX = float(np.finfo(np.float32).max)


def test_cursor_bounds_are_the_box_grown_by_cursor_reach_times_its_longer_side():
    pts = np.array([[0.25, 0.5], [0.75, 0.625], [0.5, 0.5]])
    b = cursor_bounds(pts)
    assert np.array_equal(b, [[0.25 - CURSOR_REACH * 0.5, 0.5 - CURSOR_REACH * 0.5],
                              [0.75 + CURSOR_REACH * 0.5, 0.625 + CURSOR_REACH * 0.5]])
    assert np.array_equal(cursor_bounds(np.array([[2.0, 3.0]])),
                          [[2.0 - CURSOR_REACH, 3.0 - CURSOR_REACH],
                           [2.0 + CURSOR_REACH, 3.0 + CURSOR_REACH]])
    huge = cursor_bounds(np.array([[-3e38, 0.0], [3e38, 1.0]]))
    assert np.array_equal(huge, [[-F32_MAX, -F32_MAX], [F32_MAX, F32_MAX]])


def test_clamp_cursor_keeps_places_inside_clamps_far_and_infinite_ones_drops_nan():
    b = cursor_bounds(np.array([[0.0, 0.0], [1.0, 1.0]]))
    assert np.array_equal(clamp_cursor((0.3, 7.0), b), [0.3, 7.0])
    assert np.array_equal(clamp_cursor((1e300, -1e300), b), [1.0 + CURSOR_REACH, -CURSOR_REACH])
    assert np.array_equal(clamp_cursor((-np.inf, np.inf), b), [-CURSOR_REACH, 1.0 + CURSOR_REACH])
    assert clamp_cursor((np.nan, 0.0), b) is None
    assert clamp_cursor(None, b) is None


def test_storable_float32_refuses_what_would_be_stored_as_inf_or_nan():
    ok = storable_float32(np.array([[F32_MAX, -1.5]]))
    assert ok.dtype == np.float32 and np.isfinite(ok).all()
    for bad in (1e39, -1e300, np.inf, np.nan):
        with pytest.raises(ValueError, match="float32"):
            storable_float32(np.array([[0.0, bad]]))


def test_session_whose_every_node_is_grabbed_translates_them_and_runs_no_iteration():
    p, fs = jittered_square(100, jitter=0.0)
    every = np.arange(p.shape[0])
    live = LiveSession(p, fs, every)
    assert live.rigid
    moved = p + np.array([0.25, -0.125])
    frame = live.frame(moved, budget=None)
    assert np.array_equal(frame.points, moved)
    assert frame.untangle_iterations == frame.smooth_iterations == 0
    assert frame.stats.n_inverted == 0 and frame.status == "valid"
    again = live.frame(None, budget=None)
    assert np.array_equal(again.points, moved)
    with pytest.raises(ValueError, match="nothing to optimize"):
        LiveSession(p, fs, every[:-1], fixed=np.ones(p.shape[0], bool))


def test_uv_vertex_corners_are_every_loop_of_the_uv_vertices_selected_faces_or_not():
    g = grid_uv(6, seam_x=3.0)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    sel = g.face_centres()[:, 0] < 1.5  # the first column of faces
    node = int(lay.loop_node[np.flatnonzero((g.uv == [1.0, 2.0]).all(axis=1))[0]])
    reg = uv_region(lay, [node], selected=sel, scope="selection")
    faces, pick, local = uv_vertex_corners(lay, reg.nodes)
    every = np.concatenate([np.arange(lay.faces.offsets[f], lay.faces.offsets[f + 1])
                            for f in faces])
    assert np.array_equal(faces, np.unique(np.repeat(np.arange(lay.faces.n_faces),
                                                     lay.faces.counts)[every[pick]]))
    loops = lay.corner_loop[every[pick]]
    assert np.array_equal(np.sort(loops), np.flatnonzero(np.isin(lay.loop_node, reg.nodes)))
    assert np.array_equal(reg.nodes[local], lay.loop_node[loops])
    mine = loops[reg.nodes[local] == node]
    assert mine.size == 4 and np.count_nonzero(sel[mine // 4]) == 2  # 2 outside the selection
    seam = int(lay.loop_node[np.flatnonzero((g.uv == [3.0, 2.0]).all(axis=1))[0]])
    faces, pick, local = uv_vertex_corners(lay, np.array([seam]))
    assert faces.size == 2 and pick.size == 2 and (local == 0).all()  # the other island's
    # loops of that mesh vertex are another UV vertex
