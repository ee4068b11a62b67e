"""What a live drag keeps between frames (core.run.live_reuse): each piece the same bits as
measuring again, and frames after a far grab still equal cold runs."""

from __future__ import annotations

import numpy as np

from bench.meshgen import jittered_square
from core import EEGTParams, mesh_stats, untangle_and_smooth
from core.eegt.distance import NearestBoundary
from core.eegt.engine_numpy import NumpyEngine
from core.mesh.topology import free_nodes
from core.metrics.targets import prepare_targets
from core.run.live import LiveSession, live_params
from core.run.live_reuse import AnchorSearch, GivenQuality, StillDistances


def _brute(bx, by, qx, qy):
    d = (bx[:, None] - qx[None, :]) ** 2 + (by[:, None] - qy[None, :]) ** 2
    return np.sqrt(d.min(axis=0))


def test_still_distances_measure_only_moved_centroids_and_equal_a_fresh_query():
    rng = np.random.default_rng(0)
    bx, by = rng.uniform(0, 1, 300), rng.uniform(0, 1, 300)
    qx, qy = rng.uniform(-0.2, 1.2, 5000), rng.uniform(-0.2, 1.2, 5000)
    tree = NearestBoundary(bx, by, qx, qy)
    kept = StillDistances(tree)
    kept.query(qx, qy)
    assert kept.measured == 5000
    moved = rng.choice(5000, 37, replace=False)
    qx2, qy2 = qx.copy(), qy.copy()
    qx2[moved] += rng.normal(0, 0.3, 37)
    got = kept.query(qx2, qy2).copy()
    assert kept.measured == 37
    assert np.array_equal(got, tree.query(qx2, qy2))
    assert np.array_equal(got, _brute(bx, by, qx2, qy2))


def test_anchor_search_equals_the_distance_to_still_and_grabbed_nodes_together():
    rng = np.random.default_rng(1)
    bx, by = rng.uniform(0, 1, 400), rng.uniform(0, 1, 400)
    qx, qy = rng.uniform(0, 1, 4000), rng.uniform(0, 1, 4000)
    gx, gy = np.array([0.5, 0.52, 3.0]), np.array([0.5, 0.49, -2.0])  # one far outside
    still = StillDistances(NearestBoundary(bx, by, qx, qy))
    got = AnchorSearch(still, gx, gy).query(qx, qy)
    want = _brute(np.r_[bx, gx], np.r_[by, gy], qx, qy)
    assert np.array_equal(got, want)
    assert (got < still.query(qx, qy)).sum() > 10  # the grabbed nodes are nearest somewhere


def test_given_quality_measures_moved_faces_and_equals_mesh_stats():
    p, fs = jittered_square(2000, jitter=0.3, seed=4)
    rng = np.random.default_rng(2)
    tg = p[fs.indices] * [1.3, 1.0]
    kept = GivenQuality(fs, prepare_targets(tg, fs))
    assert kept.stats(p) == mesh_stats(p, fs, tg)
    for n_moved in (1, 50, 0):
        p = p.copy()
        ids = rng.choice(p.shape[0], n_moved, replace=False)
        p[ids] += rng.normal(0, 0.02, (n_moved, 2))
        assert kept.stats(p) == mesh_stats(p, fs, tg)


def test_restart_keeping_quality_equals_a_fresh_engine():
    p, fs = jittered_square(1500, jitter=0.3, seed=6)
    free = free_nodes(p.shape[0], fs, np.zeros(p.shape[0], bool))
    prm = live_params(EEGTParams(), 5)
    engine = NumpyEngine(p, fs, free, prm)
    engine.step("untangle")
    moved = engine.points()
    moved[np.flatnonzero(free)[:20]] += 0.003
    kept = engine.restarted(moved, keep_quality=True)
    fresh = NumpyEngine(moved, fs, free, prm)
    for a, b in zip(kept.q, fresh.q):
        assert np.array_equal(a, b)
    assert kept.stats() == fresh.stats()


def test_frames_after_a_far_grab_equal_cold_runs_bit_for_bit():
    """A centre node jumps five cells then one more; then a grabbed border node is pulled
    out of the mesh's box (a new normalisation: the still nodes' distances are measured
    again). Each frame untangles and equals the cold run on its input bit for bit."""
    p, fs = jittered_square(3000, jitter=0.2, seed=8)
    centre = int(np.argmin(((p - 0.5) ** 2).sum(axis=1)))
    side = int(np.argmin(((p - [1.0, 0.5]) ** 2).sum(axis=1)))
    grab = np.array([centre, side])
    pins = np.zeros(p.shape[0], dtype=bool)
    pins[grab] = True
    prm = EEGTParams()
    live = LiveSession(p, fs, grab, params=prm)
    start = p.copy()
    for move in ([[0.13, 0.05], [0.0, 0.0]], [[0.16, 0.07], [0.0, 0.0]],
                 [[0.16, 0.07], [0.05, 0.01]]):
        target = p[grab] + move
        given = start.copy()
        given[grab] = target
        frame = live.frame(target, iterations=400, budget=None)
        cold = untangle_and_smooth(given, fs, fixed=pins, params=live_params(prm, 400))
        assert frame.status == cold.status != "tangled"
        assert frame.untangle_iterations + frame.smooth_iterations > 0
        assert np.array_equal(frame.points, cold.points)
        assert frame.stats == cold.after
        assert (frame.untangle_iterations, frame.smooth_iterations) == \
            (cold.untangle_iterations, cold.smooth_iterations)
        start = frame.points
    assert frame.points[side, 0] == p[side, 0] + 0.05  # out of the box the frames began in
