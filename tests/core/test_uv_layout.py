"""UV welding, islands and their orientation (core.uv_layout)."""

from __future__ import annotations

import numpy as np
import pytest
from uvdata import grid_uv

from core.uv_layout import components, corner_loops, island_faces, weld_uv


def test_weld_one_island_shares_every_vertex():
    g = grid_uv(5)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    assert lay.n_nodes == 25 and lay.n_islands == 1
    assert lay.area[0] == pytest.approx(16.0)
    assert np.array_equal(lay.vertex[lay.loop_node], g.corner_verts)
    assert np.array_equal(lay.points[lay.loop_node], g.uv.astype(np.float64))


def test_weld_seam_splits_vertices_into_two_uv_vertices():
    g = grid_uv(5, seam_x=2.0)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    assert lay.n_islands == 2
    assert lay.n_nodes == 25 + 5  # the 5 vertices on x = 2 have a UV on each side
    assert sorted(lay.area.tolist()) == [8.0, 8.0]
    seam = np.flatnonzero(np.bincount(lay.vertex, minlength=25) == 2)
    assert np.array_equal(np.sort(g.co[seam, 0]), np.full(5, 2.0))


def test_weld_equal_values_only_minus_zero_is_zero():
    g = grid_uv(3)
    uv = g.uv.copy()
    v0 = np.flatnonzero(g.corner_verts == 0)  # vertex 0 is used by one loop: use vertex 4
    loops4 = np.flatnonzero(g.corner_verts == 4)
    assert v0.size == 1 and loops4.size == 4
    uv[loops4] = (0.0, 1.0)
    uv[loops4[0]] = (-0.0, 1.0)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    assert len(set(lay.loop_node[loops4].tolist())) == 1
    uv[loops4[1], 0] = np.nextafter(np.float32(0), np.float32(1))  # one float32 step off
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    assert len(set(lay.loop_node[loops4].tolist())) == 2


def test_weld_refuses_nan_and_wrong_sizes():
    g = grid_uv(3)
    uv = g.uv.copy()
    uv[5, 1] = np.nan
    with pytest.raises(ValueError, match="1 UVs are NaN or infinite"):
        weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    with pytest.raises(ValueError, match="values for"):
        weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv[:-1])


def test_orientation_mirrored_and_zero_area_islands():
    g = grid_uv(6, seam_x=3.0)
    uv = g.uv.copy()
    right = np.repeat(g.co[g.corner_verts.reshape(-1, 4)[:, 0], 0] >= 3.0, 4)
    uv[right, 0] = -uv[right, 0]  # mirrored island
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    side = lay.orientation()
    assert sorted(side.tolist()) == [-1, 1]
    p = lay.oriented_points(side)
    assert (np.abs(p) == np.abs(lay.points)).all()  # exact reflection
    uv[right] = (0.25, 0.5)  # collapsed to a point
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    assert sorted(lay.orientation().tolist()) == [0, 1]
    uv[right, 1] = uv[right, 0] * 3  # on a line
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    assert sorted(lay.orientation().tolist()) == [0, 1]


def test_faces_in_any_loop_order():
    g = grid_uv(4, seam_x=1.0)
    perm = np.random.default_rng(3).permutation(g.n_faces)  # faces stored in shuffled order
    ls = np.empty_like(g.loop_start)
    ls[perm] = g.loop_start
    cv = np.empty_like(g.corner_verts)
    uv = np.empty_like(g.uv)
    cv[np.repeat(ls, 4) + np.tile(np.arange(4), g.n_faces)] = g.corner_verts
    uv[np.repeat(ls, 4) + np.tile(np.arange(4), g.n_faces)] = g.uv
    loops = corner_loops(ls, g.loop_total)
    assert np.array_equal(cv[loops], g.corner_verts)
    lay = weld_uv(ls, g.loop_total, cv, uv)
    ref = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    assert lay.n_nodes == ref.n_nodes and lay.n_islands == 2
    assert np.allclose(np.sort(lay.area), np.sort(ref.area))


def test_components_match_a_breadth_first_search():
    rng = np.random.default_rng(7)
    n = 400
    a = rng.integers(0, n, 300)
    b = rng.integers(0, n, 300)
    lab = components(n, a, b)
    adj = [[] for _ in range(n)]
    for x, y in zip(a.tolist(), b.tolist()):
        adj[x].append(y)
        adj[y].append(x)
    ref = -np.ones(n, int)
    k = 0
    for s in range(n):
        if ref[s] >= 0:
            continue
        stack = [s]
        ref[s] = k
        while stack:
            x = stack.pop()
            for y in adj[x]:
                if ref[y] < 0:
                    ref[y] = k
                    stack.append(y)
        k += 1
    assert lab.max() + 1 == k
    assert np.array_equal(lab, ref)  # both number components by their smallest member


def test_island_faces_keeps_corner_rows():
    g = grid_uv(4)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    ids = np.array([4, 1, 7])
    sub, nodes, rows = island_faces(lay.faces, ids)
    assert np.array_equal(nodes[sub.indices], lay.faces.indices[rows])
    assert rows.tolist() == [16, 17, 18, 19, 4, 5, 6, 7, 28, 29, 30, 31]
