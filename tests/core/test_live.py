"""Live untangling's warm-started frames (core.run.live): same bits as a cold run, drags."""

from __future__ import annotations

import numpy as np
import pytest
from uvdata import grid_uv, jitter_interior

from bench.meshgen import jittered_square
from core import EEGTParams, boundary_nodes, mesh_stats, untangle_and_smooth
from core.run.live import LiveSession, live_params, uv_region
from core.uv.uv_layout import weld_uv


def _centre_nodes(p: np.ndarray, k: int = 1) -> np.ndarray:
    return np.argsort(((p - 0.5) ** 2).sum(axis=1), kind="stable")[:k]


def _cold(p, fs, pins, params, k):
    return untangle_and_smooth(p, fs, fixed=pins, params=live_params(params, k))


@pytest.mark.parametrize("jitter", [0.0, 0.45])
def test_frames_equal_cold_runs_bit_for_bit(jitter):
    """Three frames along a drag, each against a cold untangle_and_smooth on that frame's
    input: the first builds the engine, later ones restart it with the moved pin."""
    p, fs = jittered_square(3000, jitter=jitter, seed=3)
    grab = _centre_nodes(p)
    prm = EEGTParams()
    live = LiveSession(p, fs, grab, params=prm)
    pins = np.zeros(p.shape[0], dtype=bool)
    pins[grab] = True
    start = p.copy()
    for step, k in ((0.01, 60), (0.02, 4), (0.03, 40)):
        target = p[grab] + [step, -0.5 * step]
        given = start.copy()
        given[grab] = target
        frame = live.frame(target, iterations=k, budget=None)
        cold = _cold(given, fs, pins, prm, k)
        assert cold.status in ("valid", "untangled")
        assert np.array_equal(frame.points, cold.points)
        assert frame.stats == cold.after
        assert (frame.untangle_iterations, frame.smooth_iterations) == \
            (cold.untangle_iterations, cold.smooth_iterations)
        assert frame.untangle_iterations + frame.smooth_iterations > 0
        start = frame.points


def test_frames_with_targets_and_a_grabbed_group_equal_cold_runs():
    """Several grabbed nodes and per-corner targets: still the cold run's bits."""
    p, fs = jittered_square(1200, jitter=0.3, seed=5)
    grab = _centre_nodes(p, 4)
    rng = np.random.default_rng(1)
    tg = (p[fs.indices] * [1.5, 1.0]) + rng.uniform(0, 1e-3, (fs.n_corners, 2))
    prm = EEGTParams(a=0.3)
    pins = np.zeros(p.shape[0], dtype=bool)
    pins[grab] = True
    live = LiveSession(p, fs, grab, params=prm, targets=tg)
    start = p.copy()
    for shift in (0.02, 0.05):
        target = p[grab] + shift
        given = start.copy()
        given[grab] = target
        frame = live.frame(target, iterations=5, budget=None)
        cold = untangle_and_smooth(given, fs, fixed=pins, params=live_params(prm, 5),
                                   targets=tg)
        assert np.array_equal(frame.points, cold.points)
        start = frame.points


def test_drag_across_untangles_and_keeps_border_and_pins_bits():
    """A centre node dragged ten cells away in 10 steps folds its fan over the mesh with
    EEGT alone (``escalate=False``: the fold stays); the escalated frames (the foldover-free
    stage on the region, resumed from frame to frame, from the drag's start carried along)
    end with no inverted face once the cursor rests; the border and the grabbed node hold
    their bits."""
    p, fs = jittered_square(2000, jitter=0.0)
    grab = _centre_nodes(p)
    border = boundary_nodes(p.shape[0], fs)
    end = p[grab][0] + [0.3, 0.2]
    path = [p[grab] + t * (end - p[grab][0]) for t in np.linspace(0.1, 1.0, 10)]
    eegt = LiveSession(p, fs, grab, escalate=False)
    assert max(eegt.frame(at, budget=None).stats.n_inverted for at in path) > 0
    live = LiveSession(p, fs, grab, pull_after=None)  # the escalation alone
    for at in path:
        frame = live.frame(at, budget=None)
    for _ in range(30):
        if frame.status != "tangled":
            break
        frame = live.frame(None, budget=None)
    assert frame.status in ("valid", "untangled")
    assert frame.stats.n_inverted == 0
    assert mesh_stats(frame.points, fs).n_inverted == 0
    assert np.array_equal(frame.points[border], p[border])
    assert np.array_equal(frame.points[grab], path[-1])
    assert live.finishing(frame) == "keep"


def test_time_budget_zero_runs_one_iteration_per_frame():
    p, fs = jittered_square(800, jitter=0.45, seed=2)
    live = LiveSession(p, fs, _centre_nodes(p))
    frame = live.frame(None, iterations=50, budget=0.0)
    assert frame.untangle_iterations + frame.smooth_iterations == 1


def test_session_refuses_bad_input_in_one_line():
    p, fs = jittered_square(200, jitter=0.0)
    with pytest.raises(ValueError, match="node ids"):
        LiveSession(p, fs, [p.shape[0]])
    live = LiveSession(p, fs, _centre_nodes(p))
    with pytest.raises(ValueError, match="finite"):
        live.frame([[np.nan, 0.0]])
    every = np.ones(p.shape[0], dtype=bool)
    with pytest.raises(ValueError, match="nothing to optimize"):
        LiveSession(p, fs, [0], fixed=every)


def _two_islands(mirror_right: bool = False):
    g = grid_uv(9, seam_x=4.0)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    free = ~boundary_nodes(lay.n_nodes, lay.faces)
    uv = jitter_interior(g.uv, lay.loop_node, free, 0.3, 4)
    if mirror_right:
        right = np.repeat(g.co[g.corner_verts.reshape(-1, 4)[:, 0], 0] >= 4.0, 4)
        uv[right, 0] = -uv[right, 0]
    return weld_uv(g.loop_start, g.loop_total, g.corner_verts, uv)


@pytest.mark.parametrize("mirror", [False, True])
def test_uv_region_is_the_grabbed_island_with_its_border_fixed(mirror):
    lay = _two_islands(mirror)
    inner = np.flatnonzero(~boundary_nodes(lay.n_nodes, lay.faces)
                           & (lay.node_island == 1))
    grab = inner[:1]
    reg = uv_region(lay, grab)
    assert np.array_equal(np.sort(reg.face_ids), np.flatnonzero(lay.island == 1))
    assert reg.nodes[reg.grab][0] == grab[0]
    assert np.array_equal(reg.fixed, np.zeros(reg.nodes.size, bool))
    assert reg.mirrored.all() == mirror
    assert np.array_equal(reg.to_uv(reg.points), lay.points[reg.nodes])
    live = LiveSession(reg.points, reg.faces, reg.grab, fixed=reg.fixed)
    frame = live.frame(reg.points[reg.grab] + [0.4, 0.3], budget=None)
    assert frame.stats.n_inverted == 0
    border = boundary_nodes(reg.nodes.size, reg.faces)
    assert np.array_equal(reg.to_uv(frame.points)[border], lay.points[reg.nodes][border])


def test_uv_region_selection_scope_fixes_the_selection_border_and_pins():
    lay = _two_islands()
    sel = (lay.island == 0) & (np.arange(lay.faces.n_faces) % 7 != 0)
    inner = np.flatnonzero(~boundary_nodes(lay.n_nodes, lay.faces) & (lay.node_island == 0))
    pins = np.zeros(lay.n_nodes, bool)
    pins[inner[-1]] = True
    reg = uv_region(lay, inner[:1], selected=sel, scope="selection", pins=pins)
    assert np.array_equal(reg.face_ids, np.flatnonzero(sel))
    outside = np.zeros(lay.n_nodes, bool)
    outside[lay.faces.indices[np.repeat(~sel, lay.faces.counts)]] = True
    assert np.array_equal(reg.fixed, (outside | pins)[reg.nodes])
    with pytest.raises(ValueError, match="grab"):
        uv_region(lay, [], selected=sel)
