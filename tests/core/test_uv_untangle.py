"""Untangling UV maps island by island (core.uv.uv_untangle)."""

from __future__ import annotations

import numpy as np
import pytest
from uvdata import grid_uv, jitter_interior

import core.optimize.stages as stages
from core import EEGTParams, boundary_nodes
from core.uv.uv_layout import weld_uv
from core.uv.uv_untangle import flipped_faces, measure, untangle_uv


def tangled(n=9, seam_x=4.0, amount=0.7, seed=0, mirror_right=False, warp=False):
    """A grid UV map with a seam (two islands), interior UVs jittered (flipped faces);
    ``warp`` bends it first (curved borders: the optimum is no longer the grid)."""
    g = grid_uv(n, seam_x=seam_x)
    if warp:
        u, v = g.uv[:, 0].astype(np.float64), g.uv[:, 1].astype(np.float64)
        g.uv = np.stack([u + 0.04 * v * v, v + 0.02 * (u % 10.0) ** 2], 1).astype(np.float32)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    free = ~boundary_nodes(lay.n_nodes, lay.faces)
    uv = jitter_interior(g.uv, lay.loop_node, free, amount, seed)
    if mirror_right:  # the same tangle, its right island mirrored (exact)
        right = np.repeat(g.co[g.corner_verts.reshape(-1, 4)[:, 0], 0] >= seam_x, 4)
        uv[right, 0] = -uv[right, 0]
    return g, weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)


def test_both_islands_untangled_borders_and_seam_sides_exact():
    g, lay = tangled()
    sel = np.ones(g.n_faces, bool)
    before = measure(lay, lay.points, sel)
    assert before.inverted >= 6 and before.overlapping > 0
    res = untangle_uv(lay, sel)
    after = measure(lay, res.points, sel)
    assert res.status == "untangled"
    assert (after.flipped, after.inverted, after.overlapping) == (0, 0, 0)
    assert after.distortion_mean > before.distortion_mean
    bnd = boundary_nodes(lay.n_nodes, lay.faces)
    assert np.array_equal(res.points[bnd], lay.points[bnd])  # island borders and seams
    assert not res.moved[bnd].any() and res.moved[~bnd].all()
    assert (res.points.astype(np.float32) == res.points).all()  # storable bits
    assert [r.status for r in res.islands] == ["untangled", "untangled"]


def test_mirrored_island_gives_the_mirror_of_the_same_result():
    g, lay = tangled(warp=True)
    _, mir = tangled(mirror_right=True, warp=True)
    assert sorted(mir.orientation().tolist()) == [-1, 1]
    sel = np.ones(g.n_faces, bool)
    params = EEGTParams(max_smooth_iterations=5)
    a = untangle_uv(lay, sel, params=params)
    b = untangle_uv(mir, sel, params=params)
    right = lay.points[:, 0] >= 4.0 + 10.0
    assert right.any()
    assert np.array_equal(b.points[right] * [-1.0, 1.0], a.points[right])  # bit for bit
    assert np.array_equal(b.points[~right], a.points[~right])
    assert measure(mir, b.points, sel).inverted == 0
    assert (np.abs(a.points - np.round(a.points)) > 1e-3).any()  # a non-trivial result
    assert flipped_faces(mir, mir.points).sum() == flipped_faces(lay, lay.points).sum() > 0
    assert [r.mirrored for r in b.islands] == [False, True]
    assert "1 mirrored island(s)" in b.notes


def test_pins_and_selection_border_stay_exact():
    g, lay = tangled()
    cen = g.face_centres()
    sel = cen[:, 1] > 3.0
    pins = np.zeros(lay.n_nodes, bool)
    pins[np.flatnonzero(~boundary_nodes(lay.n_nodes, lay.faces))[::7]] = True
    res = untangle_uv(lay, sel, fixed=pins)
    outside = np.zeros(lay.n_nodes, bool)
    outside[lay.faces.indices[np.repeat(~sel, 4)]] = True
    assert np.array_equal(res.points[outside | pins], lay.points[outside | pins])
    assert res.moved.any() and not res.moved[outside | pins].any()
    before, after = measure(lay, lay.points, sel), measure(lay, res.points, sel)
    assert after.inverted < before.inverted


def test_zero_area_island_skipped_all_zero_refused():
    g = grid_uv(7, seam_x=3.0)
    uv = g.uv.copy()
    right = np.repeat(g.co[g.corner_verts.reshape(-1, 4)[:, 0], 0] >= 3.0, 4)
    uv[right] = (0.5, 0.5)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    res = untangle_uv(lay, np.ones(g.n_faces, bool))
    assert [r.status for r in res.islands] == ["valid", "skipped"]
    assert any("without UV area" in n for n in res.notes)
    assert not res.moved[lay.node_island == lay.island[np.flatnonzero(right[::4])[0]]].any()
    with pytest.raises(ValueError, match="no UV area"):
        untangle_uv(lay, right[::4])
    with pytest.raises(ValueError, match="no UV faces selected"):
        untangle_uv(lay, np.zeros(g.n_faces, bool))


def test_everything_fixed_is_refused():
    g, lay = tangled()
    with pytest.raises(ValueError, match=r"nothing to move: every UV vertex is fixed .*grow"):
        untangle_uv(lay, np.ones(g.n_faces, bool), fixed=np.ones(lay.n_nodes, bool))


def test_valid_optimal_map_unchanged_and_rejected_result_kept_out():
    g = grid_uv(6, seam_x=2.0)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    res = untangle_uv(lay, np.ones(g.n_faces, bool))
    assert res.status == "valid" and not res.moved.any()
    assert np.array_equal(res.points, lay.points)
    _, lay = tangled()
    res = untangle_uv(lay, np.ones(lay.faces.n_faces, bool), accept=lambda a, b: False)
    assert not res.moved.any() and res.status == "failed"
    assert all("no improvement once stored" in r.message for r in res.islands)


def test_cancel_leaves_everything():
    _, lay = tangled()
    res = untangle_uv(lay, np.ones(lay.faces.n_faces, bool),
                      progress=lambda it, phase, s: it < 2)
    assert res.status == "cancelled" and not res.moved.any()
    assert np.array_equal(res.points, lay.points)


def test_progress_names_the_island():
    _, lay = tangled()
    phases = []
    untangle_uv(lay, np.ones(lay.faces.n_faces, bool),
                params=EEGTParams(max_smooth_iterations=3),
                progress=lambda it, phase, s: phases.append(phase))
    assert phases[0].startswith("island 1/2 ") and phases[-1].startswith("island 2/2 ")


def _local_fold(n=14):
    """A grid UV map (curved borders) with one interior UV vertex dragged over its
    neighbours: a local fold in a big island."""
    g = grid_uv(n)
    u, v = g.uv[:, 0].astype(np.float64), g.uv[:, 1].astype(np.float64)
    g.uv = np.stack([u + 0.03 * v * v, v + 0.02 * u * u], 1).astype(np.float32)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    p = lay.points.copy()
    mid = int(np.flatnonzero(lay.vertex == (n // 2) * n + n // 2)[0])
    p[mid] += (1.6, 0.3)
    uv = p[lay.loop_node].astype(np.float32)
    return g, weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)


def test_scope_tangles_moves_only_around_the_fold(monkeypatch):
    """The fold is untangled in a region first (42 of 169 faces); the whole island then runs
    once more and is kept only when it raises both qualities: here, without the lift's last
    whole-mesh run (SETTLE_FLOOR 0), it does not, and the rest keeps its bits; with it, it
    does, and the message says so."""
    g, lay = _local_fold()
    sel = np.ones(g.n_faces, bool)
    before = measure(lay, lay.points, sel)
    assert before.inverted >= 2
    phases = []
    monkeypatch.setattr(stages, "SETTLE_FLOOR", 0.0)
    res = untangle_uv(lay, sel, progress=lambda it, ph, s: phases.append(ph))
    after = measure(lay, res.points, sel)
    assert res.status == "untangled" and after.inverted == 0 and after.overlapping == 0
    assert 0 < res.moved.sum() < 0.25 * lay.n_nodes  # the rest keeps its bits
    assert " of 169 faces) " in phases[0]
    assert "smoothed whole" not in res.islands[0].message
    monkeypatch.undo()
    both = untangle_uv(lay, sel)
    assert both.islands[0].message.endswith("(untangled in a region, then smoothed whole)")
    assert measure(lay, both.points, sel).inverted == 0
    whole = untangle_uv(lay, sel, scope="selection")
    assert whole.moved.sum() > 0.5 * lay.n_nodes
    assert measure(lay, whole.points, sel).inverted == 0
    with pytest.raises(ValueError, match="scope must be one of tangles, selection"):
        untangle_uv(lay, sel, scope="everything")


def test_scope_tangles_grows_until_it_untangles():
    # an inner disc turned 150 degrees; seeded with its inverted faces only (not the
    # overlapping ones), one ring around them is too thin to untwist: the region grows
    n = 20
    g = grid_uv(n)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    c = np.array([(n - 1) / 2, (n - 1) / 2])
    d = lay.points - c
    disc = np.linalg.norm(d, axis=1) < 5.0
    t = np.radians(150.0)
    rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    p = lay.points.copy()
    p[disc] = c + d[disc] @ rot.T
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, p[lay.loop_node].astype(np.float32))
    sel = np.ones(g.n_faces, bool)
    assert measure(lay, lay.points, sel).inverted > 10
    phases = []
    res = untangle_uv(lay, sel, rings=1, tangled=flipped_faces(lay, lay.points, corners=True),
                      progress=lambda it, ph, s: phases.append(ph))
    tries = list(dict.fromkeys(ph.split(")")[0] for ph in phases if "faces)" in ph))
    assert tries == ["island 1/1 (108 of 361 faces"]  # the next ring count covers > 3/4:
    assert "faces)" not in phases[-1]  # the whole island ran after it
    assert res.status == "untangled" and measure(lay, res.points, sel).inverted == 0


def test_one_ulp_seams_do_not_fix_vertices():
    # Blender 4.2-4.5's Grid primitive stores UVs one float32 step apart along a row and a
    # column; welded by bit equality they are cuts whose vertices cannot move
    from test_uv_layout import ulp_grid
    g, _ = ulp_grid()
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    free = ~boundary_nodes(lay.n_nodes, lay.faces)
    assert lay.n_nodes == 121 and free.sum() == 81
    uv = jitter_interior(g.uv, lay.loop_node, free, 0.09, seed=0)
    sel = np.ones(g.n_faces, bool)
    cut = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv, limit=0.0)
    assert cut.n_nodes == 137  # 16 cut vertices left after the jitter
    res = untangle_uv(cut, sel)  # welded bit for bit: the cuts stay, so do inverted faces
    assert (measure(cut, cut.points, sel).inverted, measure(cut, res.points, sel).inverted) \
        == (43, 1)
    assert res.status == "failed"
    assert res.message == "1 face stays inverted: the engine could not untangle it"
    # the cut fixes node 14's neighbours in faces 2 and 12: held at once with that reason
    assert ("node 14 is held: with the other vertices of its faces that touch it fixed, no "
            "position of it makes them valid (faces 2, 12 cannot all be valid at once)"
            ) in res.islands[0].message
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    assert lay.n_nodes == 121
    res = untangle_uv(lay, sel)
    after = measure(lay, res.points, sel)
    assert measure(lay, lay.points, sel).inverted == 43
    assert res.status == "untangled" and (after.inverted, after.overlapping) == (0, 0)
    assert res.moved.sum() == 81 and not res.moved[~free].any()
    assert res.message == ""


def test_pinned_inverted_faces_fail_and_say_why():
    g, lay = tangled()
    sel = np.ones(g.n_faces, bool)
    bad = flipped_faces(lay, lay.points, corners=True)
    assert np.flatnonzero(bad)[:2].tolist() == [10, 11]  # island 0, next to each other
    # faces 10 and 11 are concave quads (valid once their concave corner is pinned: kept as
    # given, core.metrics.kept); UV vertex 23 moved across edge 12-13 crosses both
    uv = lay.points[lay.loop_node].astype(np.float32)
    uv[lay.loop_node == 23] = (2.9, 0.6)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)
    assert np.flatnonzero(flipped_faces(lay, lay.points, corners=True))[:2].tolist() == [10, 11]
    pins = np.zeros(lay.n_nodes, bool)
    pins[[12, 13, 22, 23]] = True  # face 10's corners; face 11's others are on the border
    assert np.array_equal(lay.faces.indices[40:48], [12, 13, 23, 22, 13, 14, 24, 23])
    res = untangle_uv(lay, sel, fixed=pins)
    after = measure(lay, res.points, sel)
    assert after.inverted == 2
    assert np.flatnonzero(flipped_faces(lay, res.points, corners=True)).tolist() == [10, 11]
    assert res.status == "failed"
    assert res.message == ("2 faces stay inverted: every corner of them is pinned or on an "
                           "island border")
    assert [(r.status, r.inverted_left, r.stuck) for r in res.islands] == [
        ("failed", 2, 2), ("untangled", 0, 0)]
    # an island with nothing free at all is not left out of the verdict either (its three
    # concave quads are kept as given: every corner pinned)
    pins = lay.node_island == 0
    res = untangle_uv(lay, sel, fixed=pins)
    assert [r.status for r in res.islands] == ["failed", "untangled"]
    assert res.status == "failed" and res.islands[0].n_free == 0
    assert res.message == ("2 faces stay inverted: every corner of them is pinned or on an "
                           "island border")
    assert measure(lay, res.points, sel, fixed=pins).inverted == 2
    assert measure(lay, res.points, sel).inverted == 5  # pins unknown: every corner counts
    assert res.n_kept == 3 and "3 faces kept as given" in res.notes[-1]


def test_a_face_that_could_move_but_stays_inverted_fails():
    _, lay = tangled()
    res = untangle_uv(lay, np.ones(lay.faces.n_faces, bool), accept=lambda a, b: False)
    assert res.status == "failed" and not res.moved.any()
    assert res.message == "12 faces stay inverted: the engine could not untangle them"
