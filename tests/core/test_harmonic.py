"""The global stage's harmonic start (core.run.harmonic) and the pipeline's restart from it:
interior nodes at the mean of their neighbours, everything else bit-identical, and a
half-turn fold that outlasts the budget from the input untangles from the harmonic map."""

from __future__ import annotations

import numpy as np
from meshdata import spun_hole

import core.optimize.stages as stages
from core import EEGTParams, untangle_and_smooth
from core.mesh.faces import as_faceset
from core.mesh.topology import pinched_faces
from core.metrics.face_quality import folded_area
from core.run import pipeline
from core.run.harmonic import harmonic_positions


def tri_grid(k: int) -> tuple[np.ndarray, np.ndarray]:
    """A (k+1) x (k+1) node grid of the unit square, each cell cut along one diagonal."""
    x, y = np.meshgrid(np.linspace(0.0, 1.0, k + 1), np.linspace(0.0, 1.0, k + 1))
    pts = np.column_stack([x.ravel(), y.ravel()])
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    a = (i * (k + 1) + j).ravel()
    b, c, d = a + 1, a + k + 2, a + k + 1
    return pts, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def test_harmonic_start_puts_a_shaken_grid_back_on_the_grid():
    """On a diagonal-cut grid every interior node is the mean of its six neighbours, so the
    harmonic map of the square's boundary is the grid itself."""
    pts, faces = tri_grid(12)
    fs = as_faceset(faces, len(pts))
    interior = (pts > 0.0).all(axis=1) & (pts < 1.0).all(axis=1)
    shaken = pts.copy()
    shaken[interior] += np.random.default_rng(0).normal(0.0, 0.05, (interior.sum(), 2))
    shaken[0] = [-0.0, -0.0]  # held rows keep their bits, signed zeros included
    out = harmonic_positions(shaken, fs, np.ones(len(pts), dtype=bool))
    assert np.abs(out[interior] - pts[interior]).max() < 1e-8
    assert np.array_equal(out[~interior].view(np.int64), shaken[~interior].view(np.int64))


def test_harmonic_start_holds_pinned_and_boundary_nodes_and_moves_only_the_movable():
    pts, faces = tri_grid(8)
    fs = as_faceset(faces, len(pts))
    movable = np.ones(len(pts), dtype=bool)
    pinned = 40  # an interior node held by the caller
    movable[pinned] = False
    shaken = pts + np.random.default_rng(1).normal(0.0, 0.03, pts.shape)
    out = harmonic_positions(shaken, fs, movable)
    boundary = ~((pts > 0.0).all(axis=1) & (pts < 1.0).all(axis=1))
    held = boundary.copy()
    held[pinned] = True
    assert np.array_equal(out[held], shaken[held])
    # every moved node is the mean of its edge neighbours
    edges = {tuple(sorted((int(f[k]), int(f[(k + 1) % 3])))) for f in faces for k in range(3)}
    nbrs: dict[int, list[int]] = {}
    for u, v in edges:
        nbrs.setdefault(u, []).append(v)
        nbrs.setdefault(v, []).append(u)
    for node in np.flatnonzero(~held):
        assert np.abs(out[node] - out[nbrs[int(node)]].mean(axis=0)).max() < 1e-8
    assert np.abs(out[~held] - shaken[~held]).max() > 1e-3  # they did move
    nothing = harmonic_positions(shaken, fs, np.zeros(len(pts), dtype=bool))
    assert np.array_equal(nothing, shaken) and nothing is not shaken


def test_half_turn_that_outlasts_the_budget_untangles_from_the_harmonic_start(monkeypatch):
    """A hole spun three quarters of a turn: with 200 untangling iterations the run from the
    input stays folded; the restart from the harmonic map of the interior untangles."""
    pts, groups = spun_hole(8, 48, 270, True)
    prm = EEGTParams(max_untangle_iterations=200, polish_iterations=50)
    res = untangle_and_smooth(pts, groups[3], params=prm)
    assert res.status == "untangled" and res.after.n_inverted == 0 < res.before.n_inverted
    assert res.after.q_min > 0.05
    assert res.global_iterations > 250  # the input's stage ran out, then the restart
    monkeypatch.setattr(pipeline, "harmonic_positions", lambda p, fs, free, tick=None: p.copy())
    again = untangle_and_smooth(pts, groups[3], params=prm)  # restarted from the input
    assert again.status == "failed" and again.after.n_inverted > 0


def pinched_square():
    """A unit square cut into two quads through its centre node E, which only they use:
    their angles at E add up to a full turn, so one of them is always inverted."""
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.45, 0.55]])
    return pts, np.array([[0, 1, 2, 4], [2, 3, 0, 4]])


def test_pinched_faces_are_the_faces_at_an_inner_node_of_two_faces():
    _, quads = pinched_square()
    assert pinched_faces(as_faceset(quads, 5), 5).tolist() == [True, True]
    grid_pts, tris = tri_grid(3)
    assert not pinched_faces(as_faceset(tris, len(grid_pts)), len(grid_pts)).any()


def test_no_harmonic_restart_when_only_pinched_faces_stay_inverted(monkeypatch):
    """The restart cannot undo a pinched pair: a run left with only those skips it."""
    def never(*_a, **_k):
        raise AssertionError("harmonic restart for a pinched pair")

    monkeypatch.setattr(pipeline, "harmonic_positions", never)
    pts, quads = pinched_square()
    res = untangle_and_smooth(pts, quads, params=EEGTParams(max_untangle_iterations=100))
    assert res.status == "failed" and res.after.n_inverted == 1


def test_restart_that_does_not_help_keeps_the_first_stages_best(monkeypatch):
    """A restart that ends worse than the stage before it leaves that stage's result: the
    same points as a run without the restart, never the restart's start or end. Here the
    first stage improves on the input without finishing, and the restart is made to fail:
    it starts from the free nodes shuffled among themselves and its optimizer returns the
    start as it is."""
    pts, groups = spun_hole(12, 64, 100, False)
    prm = EEGTParams(max_untangle_iterations=600, polish_iterations=20)
    monkeypatch.setattr(pipeline._Run, "_restart_may_help", lambda self: False)
    without = untangle_and_smooth(pts, groups[4], params=prm)
    assert without.status == "failed" and 0 < without.after.n_inverted < 64  # improved

    def shuffled(p, _fs, free, tick=None):
        out = p.copy()
        ids = np.flatnonzero(free)
        out[ids] = p[np.random.default_rng(0).permutation(ids)]
        return out

    real = pipeline.untangle_global
    calls = []

    def first_only(start, *a, **k):
        calls.append(1)
        if len(calls) == 1:
            return real(start, *a, **k)
        return start.copy(), {"iterations": 5, "status": "failed"}

    monkeypatch.setattr(pipeline._Run, "_restart_may_help", lambda self: True)
    monkeypatch.setattr(pipeline, "harmonic_positions", shuffled)
    monkeypatch.setattr(pipeline, "untangle_global", first_only)
    with_restart = untangle_and_smooth(pts, groups[4], params=prm)
    assert len(calls) == 2 and with_restart.global_iterations == without.global_iterations + 5
    assert with_restart.after == without.after
    assert np.array_equal(with_restart.points, without.points)


def test_harmonic_solve_ticks_and_a_stop_there_cancels_the_run(monkeypatch):
    """The solve reports progress (a million nodes take thousands of iterations) and a stop
    answered there cancels the run: the input comes back unchanged."""
    import core.run.harmonic as harmonic

    monkeypatch.setattr(harmonic, "HARMONIC_TICK", 2)
    pts, faces = tri_grid(12)
    shaken = pts + np.random.default_rng(3).normal(0.0, 0.02, pts.shape)
    ticks = []
    harmonic_positions(shaken, as_faceset(faces, len(pts)), np.ones(len(pts), dtype=bool),
                       tick=lambda: ticks.append(1))
    assert len(ticks) >= 2

    in_solve = []
    real_tick = pipeline._Run._harmonic_tick

    def marked(self):
        in_solve.append(1)
        real_tick(self)

    def progress(_it, _phase, _stats):
        return not in_solve  # False (stop) once the harmonic solve reports

    monkeypatch.setattr(pipeline._Run, "_harmonic_tick", marked)
    spun, groups = spun_hole(8, 48, 270, True)
    res = untangle_and_smooth(spun, groups[3], progress=progress,
                              params=EEGTParams(max_untangle_iterations=200, polish_iterations=50))
    assert in_solve and res.status == "cancelled"
    assert np.array_equal(res.points, spun)


def scrambled_grid() -> tuple[np.ndarray, np.ndarray]:
    """A 16 x 16 diagonal-cut grid whose interior nodes were thrown up to a quarter of the
    square away (224 of 512 faces inverted): EEGT cannot do the bulk of it, and the harmonic
    map of its boundary is the grid itself."""
    pts, faces = tri_grid(16)
    interior = (pts > 0.0).all(axis=1) & (pts < 1.0).all(axis=1)
    p = pts.copy()
    p[interior] += np.random.default_rng(2).uniform(-0.25, 0.25, (interior.sum(), 2))
    p[interior] = np.clip(p[interior], 0.01, 0.99)
    return p, faces


def whole_mesh_starts(monkeypatch) -> list[bool]:
    """Records, in order, whether each whole-mesh stage of a run started from the harmonic
    map (True) or from the input (False)."""
    starts: list[bool] = []
    real = pipeline._Run._whole_from

    def spy(self, harmonic: bool):
        starts.append(harmonic)
        return real(self, harmonic)

    monkeypatch.setattr(pipeline._Run, "_whole_from", spy)
    return starts


def test_eegt_local_hands_a_fold_eegt_cannot_do_to_the_harmonic_start_first(monkeypatch):
    """'eegt+local' whose EEGT leaves the bulk (a moved boundary, not scattered folds) starts
    the whole-mesh stage from the harmonic map when that leaves less fold to undo than the
    input, and untangles in far fewer iterations than the stage from the input."""
    pts, faces = scrambled_grid()
    starts = whole_mesh_starts(monkeypatch)
    first = untangle_and_smooth(pts, faces, params=EEGTParams(untangle="eegt+local"))
    assert starts == [True]
    assert first.status == "untangled" and first.before.n_inverted == 224
    assert first.after.q_min > 0.85
    starts.clear()
    monkeypatch.setattr(pipeline._Run, "_harmonic_folds_less", lambda self: False)
    from_input = untangle_and_smooth(pts, faces, params=EEGTParams(untangle="eegt+local"))
    assert starts == [False] and from_input.status == "untangled"
    assert 2 * first.global_iterations < from_input.global_iterations


def test_harmonic_first_falls_back_to_the_input_when_it_stays_tangled(monkeypatch):
    """The stage from the harmonic map made to fail (it hands back its start with the free
    nodes shuffled among themselves): the input's stage runs next and untangles."""
    pts, faces = scrambled_grid()
    real = pipeline.untangle_global
    calls = []

    def first_fails(start, groups, free, *a, **k):
        calls.append(1)
        if len(calls) == 1:
            out = start.copy()
            ids = np.flatnonzero(free)
            out[ids] = start[np.random.default_rng(0).permutation(ids)]
            return out, {"iterations": 5, "status": "failed"}
        return real(start, groups, free, *a, **k)

    starts = whole_mesh_starts(monkeypatch)
    monkeypatch.setattr(pipeline, "untangle_global", first_fails)
    res = untangle_and_smooth(pts, faces, params=EEGTParams(untangle="eegt+local"))
    assert starts == [True, False] and res.status == "untangled"


def test_input_goes_first_unless_eegt_local_and_the_harmonic_map_folds_less(monkeypatch):
    """'global' never makes the harmonic map before its stage from the input has failed;
    'eegt+local' never makes it when EEGT untangles, and keeps the input first when the
    harmonic map leaves more folded area (here a harmonic map made to fold the grid: its
    free nodes shuffled among themselves)."""
    starts = whole_mesh_starts(monkeypatch)
    pts, faces = scrambled_grid()

    def never(*_a, **_k):
        raise AssertionError("harmonic map made")

    real_harmonic = pipeline.harmonic_positions
    monkeypatch.setattr(pipeline, "harmonic_positions", never)
    res = untangle_and_smooth(pts, faces, params=EEGTParams(untangle="global"))
    assert starts == [False] and res.status == "untangled"

    starts.clear()
    light = tri_grid(16)[0]
    inner = (light > 0.0).all(axis=1) & (light < 1.0).all(axis=1)
    light[inner] += np.random.default_rng(0).uniform(-0.05, 0.05, (inner.sum(), 2))
    res = untangle_and_smooth(light, faces, params=EEGTParams(untangle="eegt+local"))
    assert res.before.n_inverted > 0 and res.status == "untangled" and starts == []

    def folding(points, fs, free, **kw):
        out = real_harmonic(points, fs, free, **kw)
        ids = np.flatnonzero(free)
        out[ids] = out[np.random.default_rng(1).permutation(ids)]
        return out

    monkeypatch.setattr(pipeline, "harmonic_positions", folding)
    shuffled = folding(pts, as_faceset(faces, len(pts)), (pts > 0.0).all(1) & (pts < 1.0).all(1))
    assert folded_area(shuffled, faces).sum() > folded_area(pts, faces).sum()
    res = untangle_and_smooth(pts, faces, params=EEGTParams(untangle="eegt+local"))
    assert starts == [False] and res.status == "untangled"


def test_harmonic_map_with_more_inverted_faces_but_less_fold_goes_first(monkeypatch):
    """A hole spun three quarters of a turn folds its innermost ring over (48 faces, each
    turned far); the harmonic map spreads the turn (240 faces inverted, each barely): less
    fold to undo, so 'eegt+local' starts there, and untangles in under half the iterations
    of the start from the input. (A count of inverted faces would pick the input: on graded
    meshes, whose harmonic map inverts many slivers by a hair, that cost 40x the time.)"""
    monkeypatch.setattr(stages, "SETTLE_FLOOR", 0.0)  # untangling work only (no settle)
    spun, groups = spun_hole(8, 48, 270, True)
    fs = as_faceset(groups[3], len(spun))
    free = np.hypot(*spun.T) > 1.0 + 1e-9
    free &= np.hypot(*spun.T) < 2.0 - 1e-9
    harmonic = harmonic_positions(spun, fs, free)
    in_input, in_harmonic = folded_area(spun, fs), folded_area(harmonic, fs)
    assert np.count_nonzero(in_input) == 48 and np.count_nonzero(in_harmonic) == 240
    assert in_harmonic.sum() < 0.8 * in_input.sum()
    starts = whole_mesh_starts(monkeypatch)
    first = untangle_and_smooth(spun, groups[3], params=EEGTParams(untangle="eegt+local"))
    assert starts == [True] and first.status == "untangled" and first.before.n_inverted == 48
    starts.clear()
    monkeypatch.setattr(pipeline._Run, "_harmonic_folds_less", lambda self: False)
    from_input = untangle_and_smooth(spun, groups[3], params=EEGTParams(untangle="eegt+local"))
    assert starts == [False] and from_input.status == "untangled"
    assert 2 * first.global_iterations < from_input.global_iterations
