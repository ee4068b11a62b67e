"""UV welding, islands and their orientation (core.uv.uv_layout)."""

from __future__ import annotations

import numpy as np
import pytest
from uvdata import grid_uv

from core.uv.uv_layout import components, corner_loops, island_faces, weld_uv


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


def ulp_grid(n: int = 11, step: float = 0.1, line: int = 2):
    """A grid whose UVs are the vertex xy times ``step`` (float32), stored as Blender 4.2-4.5's
    Grid primitive stores them: along the column and the row ``line`` (0.2 for 10 x 10
    subdivisions) the loops of the faces on their far side hold one float32 step more
    (0.20000002), except where they meet the grid's first row or column. The bumped loops
    (bool (L, 2)) come with it."""
    g = grid_uv(n)
    g.uv = (g.uv * np.float32(step)).astype(np.float32)
    quads = g.corner_verts.reshape(-1, 4)
    face_x, face_y = (np.repeat(g.co[quads[:, 0], k], 4) for k in (0, 1))
    x, y = g.co[g.corner_verts, 0], g.co[g.corner_verts, 1]
    bump = np.stack([(x == line) & (face_x >= line) & (y >= 1),
                     (y == line) & (face_y >= line) & (x >= 1)], axis=1)
    g.uv[bump] = np.nextafter(g.uv[bump], np.float32(np.inf))
    return g, bump


def test_weld_joins_loops_one_float32_step_apart_as_blender_does():
    g, bump = ulp_grid()
    assert set(g.uv[bump].tolist()) == {float(np.nextafter(np.float32(0.2), np.float32(1)))}
    exact = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv, limit=0.0)
    # what Blender 4.5.15's grid gives when welded by bit equality: two islands
    assert (exact.n_nodes, exact.n_islands) == (121 + 21, 2)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    assert (lay.n_nodes, lay.n_islands) == (121, 1)
    assert np.array_equal(lay.vertex[lay.loop_node], g.corner_verts)
    # a UV vertex sits at the value most of its loops hold (a tie: the lower one)
    clean = g.co[lay.vertex, :2].astype(np.float32) * np.float32(0.1)
    assert np.array_equal(lay.points, clean.astype(np.float64))
    assert lay.area[0] == pytest.approx(1.0)


def test_weld_tie_takes_the_lower_value_and_minus_zero_is_zero():
    g = grid_uv(3)
    uv = g.uv.copy()
    loops4 = np.flatnonzero(g.corner_verts == 4)
    assert loops4.size == 4
    uv[loops4] = (0.0, 1.0)
    uv[loops4[0]] = (-0.0, 1.0)
    for limit in (0.0, 1e-4):
        lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv, limit=limit)
        assert len(set(lay.loop_node[loops4].tolist())) == 1
    up = np.nextafter(np.float32(0.5), np.float32(1))
    uv[loops4] = (0.5, 1.0)
    uv[loops4[1:3], 0] = up  # two loops each: a tie
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    (node,) = set(lay.loop_node[loops4].tolist())
    assert lay.points[node].tolist() == [0.5, 1.0]
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv, limit=0.0)
    assert len(set(lay.loop_node[loops4].tolist())) == 2


def test_weld_limit_per_axis_chained_and_one_vertex_only():
    g = grid_uv(3)
    uv = g.uv.copy()
    loops4 = np.flatnonzero(g.corner_verts == 4)
    base = np.float32(0.5)
    uv[loops4] = (base, base)
    uv[loops4[1]] = (base + np.float32(9e-5), base + np.float32(9e-5))  # 1.27e-4 apart,
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)  # under 1e-4 per axis
    assert len(set(lay.loop_node[loops4].tolist())) == 1
    uv[loops4[2]] = (base + np.float32(1.7e-4), base)  # 1.7e-4 from the first, 8e-5 from
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)  # the second: chained
    assert len(set(lay.loop_node[loops4].tolist())) == 1
    uv[loops4[3]] = (base, base + np.float32(2.8e-4))  # 1.9e-4 in v from the nearest
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    assert len(set(lay.loop_node[loops4].tolist())) == 2
    assert lay.points[lay.loop_node[loops4[0]]].tolist() == [0.5, 0.5]  # 2 of 3 loops: ties
    uv[:] = (0.25, 0.75)  # every loop at one point: still one UV vertex per mesh vertex
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    assert lay.n_nodes == 9 and np.array_equal(lay.vertex[lay.loop_node], g.corner_verts)


def test_weld_does_not_depend_on_face_or_loop_order():
    g, _ = ulp_grid(7)
    g.uv *= np.float32(3)  # UV vertices 3e-1 apart
    rng = np.random.default_rng(11)
    uv = g.uv + rng.integers(-1, 2, g.uv.shape).astype(np.float32) * np.float32(3e-5)
    ref = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    assert ref.n_nodes == 49  # every near value of a vertex joined (6e-5 apart at most)
    perm = rng.permutation(g.n_faces)  # faces stored in shuffled order, loops rotated
    ls = np.empty_like(g.loop_start)
    ls[perm] = g.loop_start
    turn = rng.integers(0, 4, g.n_faces)
    src = (np.arange(4)[None, :] + turn[:, None]) % 4 + 4 * np.arange(g.n_faces)[:, None]
    dst = np.repeat(ls, 4).reshape(-1, 4) + np.arange(4)
    cv, uv2 = np.empty_like(g.corner_verts), np.empty_like(uv)
    cv[dst] = g.corner_verts[src]
    uv2[dst] = uv[src]
    lay = weld_uv(ls, g.loop_total, cv, uv2)
    assert lay.n_nodes == ref.n_nodes
    assert np.array_equal(lay.points[lay.loop_node[dst]], ref.points[ref.loop_node[src]])
    assert np.array_equal(lay.points, ref.points) and np.array_equal(lay.vertex, ref.vertex)


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
