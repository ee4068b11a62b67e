"""The guarded line search's step limit: trial steps past the first det root are skipped
without changing a single iterate (they would be rejected), so runs keep their bits and
spend fewer energy evaluations."""

from __future__ import annotations

import numpy as np
import pytest
from meshdata import load2d

from core.mesh.faces import as_faceset
from core.optimize import GlobalOptions, lift_min_quality, untangle_global
from core.optimize import energy as energy_mod
from core.optimize import solver as solver_mod
from core.optimize.energy import FoldoverEnergy, LiftEnergy, _corner_limit
from core.optimize.solver import lbfgs
from core.optimize.stages import EPS_MIN
from core.optimize.state import LIMIT_MARGIN, TRIALS, State, folded_trial, skipped_trials
from core.run.pipeline import free_nodes


def test_skipped_trials_halves_down_to_the_first_step_under_the_limit():
    assert skipped_trials(1.0, 0.3) == (0.25, 2)
    assert skipped_trials(1.0, 2.0) == (1.0, 0)
    assert skipped_trials(1.0, np.inf) == (1.0, 0)
    assert skipped_trials(1.0, 0.0)[1] == TRIALS  # nothing positive: every trial skipped
    assert skipped_trials(0.5, 0.5 / (1.0 + LIMIT_MARGIN)) == (0.5, 0)  # within the margin
    assert skipped_trials(1.0, np.nan) == (1.0, 0)


def dets_along(c, f, w00, w01, w11, t):
    """Corner dets at the point c + t f, computed as `_jac` does from positions."""
    p = c + t * f
    e1x, e1y, e2x, e2y = p[0] - p[4], p[1] - p[5], p[2] - p[4], p[3] - p[5]
    j00, j10 = e1x * w00, e1y * w00
    j01, j11 = e1x * w01 + e2x * w11, e1y * w01 + e2y * w11
    return j00 * j11 - j01 * j10


def jac_at(c, w00, w01, w11):
    """([j00, j10, j01, j11], det J) of corners at positions c, as `_jac` computes them."""
    e1x, e1y, e2x, e2y = c[0] - c[4], c[1] - c[5], c[2] - c[4], c[3] - c[5]
    j = np.stack([e1x * w00, e1y * w00, e1x * w01 + e2x * w11, e1y * w01 + e2y * w11])
    return j, j[0] * j[3] - j[2] * j[1]


@pytest.mark.parametrize("seed", range(6))
def test_every_skipped_step_has_a_non_positive_det(seed):
    """Random valid corners and directions: at each step the limit skips, some corner's det
    computed from the moved positions is <= 0, so the line search would have rejected it."""
    rng = np.random.default_rng(seed)
    m = 2000
    ang = rng.uniform(0.3, 2.8, m)
    c = np.zeros((6, m))
    c[0], c[1] = rng.uniform(0.5, 2.0, m), 0.0  # x1, y1 on the x axis: det > 0
    r = rng.uniform(0.5, 2.0, m)
    c[2], c[3] = r * np.cos(ang), r * np.sin(ang)
    c += rng.normal(0, 5.0, (2, m))[[0, 1, 0, 1, 0, 1]]  # move each corner somewhere
    f = rng.normal(0, rng.uniform(0.05, 3.0), (6, m))
    w00, w01, w11 = (np.full(m, 1.0), np.full(m, -0.577), np.full(m, 1.155))
    assert np.all(dets_along(c, f, w00, w01, w11, 0.0) > 0)
    s0 = 1.0
    limit = _corner_limit(*jac_at(c, w00, w01, w11), f, w00, w01, w11, s0)
    _, skip = skipped_trials(s0, limit)
    assert skip > 0  # the case is built to need it
    for k in range(skip):
        s = s0 * 0.5**k
        assert dets_along(c, f, w00, w01, w11, s).min() <= 0.0, (k, s, limit)
    # the limit is a root: some corner's det changes sign there
    below = dets_along(c, f, w00, w01, w11, limit * (1 - 1e-4))
    above = dets_along(c, f, w00, w01, w11, limit * (1 + 1e-4))
    assert np.any((below > 0.0) & (above <= 0.0))


def count_calls(monkeypatch, cls, name):
    """A list that gets an entry at every call of cls.<name> (the method still runs)."""
    calls = []
    original = getattr(cls, name)

    def counted(self, *a, **k):
        calls.append(1)
        return original(self, *a, **k)

    monkeypatch.setattr(cls, name, counted)
    return calls


@pytest.mark.parametrize("name", ["tri_two_holes", "mixed_quad_tri", "quad_hole"])
def test_lift_same_bits_with_and_without_the_limit_and_fewer_evaluations(name, monkeypatch):
    p, f = load2d(name)
    fs = as_faceset(f, len(p))
    groups, free = fs.by_arity(), free_nodes(len(p), fs)
    start, _ = untangle_global(p, groups, free, GlobalOptions(polish_iter=0))  # just valid
    en = LiftEnergy(start, groups, free)
    assert en.n_inverted(start[:, 0], start[:, 1]) == 0
    en.qc = float(en.element_quality(start[:, 0], start[:, 1]).min())  # the lift's first floor
    st = State(start, free)
    v0 = st.pack(st.x, st.y)
    calls = count_calls(monkeypatch, LiftEnergy, "evaluate")
    v_with, it_with = lbfgs(en, st, v0, EPS_MIN, max_it=150, guard=True)
    n_with = len(calls)
    monkeypatch.setattr(FoldoverEnergy, "step_limit", lambda *a: np.inf)
    calls.clear()
    v_without, it_without = lbfgs(en, st, v0, EPS_MIN, max_it=150, guard=True)
    assert it_with == it_without
    assert np.array_equal(v_with, v_without)
    assert n_with <= len(calls)
    if name == "tri_two_holes":  # its unit steps fold corners: the limit saves trials there
        assert n_with < len(calls), (n_with, len(calls))


def test_folded_trial_is_an_infinite_energy_or_a_guarded_non_positive_det():
    assert folded_trial(np.inf, 0.5, True) and folded_trial(np.nan, 0.5, False)
    assert folded_trial(1.0, 0.0, True) and folded_trial(1.0, -1e-9, True)
    assert not folded_trial(1.0, -1e-9, False)  # unguarded: dets may be negative
    assert not folded_trial(1.0, 1e-9, True)  # only sufficient decrease missed


def test_limit_only_after_folded_trials_same_bits_as_after_every_rejection(monkeypatch):
    """The limit is computed after an iteration with a trial rejected for a det <= 0, not
    after one whose trials only missed sufficient decrease (it skips only trials of the
    first kind): the same points and iterations as computing it after every rejected
    trial, and fewer limits."""
    p, f = load2d("tri_two_holes")
    fs = as_faceset(f, len(p))
    groups, free = fs.by_arity(), free_nodes(len(p), fs)
    start, _ = untangle_global(p, groups, free, GlobalOptions(polish_iter=0))
    en = LiftEnergy(start, groups, free)
    en.qc = float(en.element_quality(start[:, 0], start[:, 1]).min())
    st = State(start, free)
    v0 = st.pack(st.x, st.y)
    limits = count_calls(monkeypatch, FoldoverEnergy, "step_limit")
    v_folded, it_folded = lbfgs(en, st, v0, EPS_MIN, max_it=150, guard=True)
    n_folded = len(limits)
    monkeypatch.setattr(solver_mod, "folded_trial", lambda *a: True)
    limits.clear()
    v_every, it_every = lbfgs(en, st, v0, EPS_MIN, max_it=150, guard=True)
    assert it_folded == it_every
    assert np.array_equal(v_folded, v_every)
    assert 0 < n_folded < len(limits), (n_folded, len(limits))


def test_repair_computes_a_twentieth_of_the_limits_same_points(monkeypatch):
    """A repair ("folds", target "keep") of an O-grid of triangles with its cylinder slid:
    its lift's trials mostly miss sufficient decrease, after which a limit skips nothing;
    the same points and iterations as with a limit after every rejection, and under a
    twentieth of the limits."""
    from bench.repair_meshes import Spec, make
    from core import EEGTParams, untangle_and_smooth

    c = make(Spec("ogridtri", 1000, "slide", {"dx": 0.2, "reach": 0.2}))
    limits = count_calls(monkeypatch, FoldoverEnergy, "step_limit")
    params = EEGTParams(region="folds", target="keep")
    folded = untangle_and_smooth(c.points, c.faces, fixed=c.fixed, params=params)
    n_folded = len(limits)
    monkeypatch.setattr(solver_mod, "folded_trial", lambda *a: True)
    limits.clear()
    every = untangle_and_smooth(c.points, c.faces, fixed=c.fixed, params=params)
    assert folded.status == every.status == "untangled"
    assert np.array_equal(folded.points, every.points)
    assert folded.global_iterations == every.global_iterations
    assert 0 < 20 * n_folded < len(limits), (n_folded, len(limits))


def test_lift_stage_result_unchanged_without_the_limit(monkeypatch):
    p, f = load2d("polygon_voronoi")
    fs = as_faceset(f, len(p))
    groups, free = fs.by_arity(), free_nodes(len(p), fs)
    opts = GlobalOptions(lift_rounds=6)
    with_limit, info = lift_min_quality(p, groups, free, opts)
    monkeypatch.setattr(energy_mod.FoldoverEnergy, "step_limit", lambda *a: np.inf)
    without, info2 = lift_min_quality(p, groups, free, opts)
    assert np.array_equal(with_limit, without)
    assert info["iterations"] == info2["iterations"]


@pytest.mark.parametrize("cls", [LiftEnergy, FoldoverEnergy])
def test_step_limit_from_the_last_evaluation_is_the_limit_from_positions(cls):
    """After `evaluate` and `gradient` at z, the blocks' J is z's: the limit read from it
    is the limit computed from the positions, bit for bit."""
    p, f = load2d("tri_two_holes")
    fs = as_faceset(f, len(p))
    groups, free = fs.by_arity(), free_nodes(len(p), fs)
    start, _ = untangle_global(p, groups, free, GlobalOptions(polish_iter=0))
    en = cls(start, groups, free)
    en.qc = 0.5
    st = State(start, free)
    layout, fixed = en.packed(st)
    z = np.concatenate([st.pack(st.x, st.y), fixed])
    rng = np.random.default_rng(2)
    dz = np.zeros_like(z)
    dz[: st.size] = rng.normal(0, 0.05, st.size)
    en.evaluate(z, layout, EPS_MIN)
    en.gradient(layout)
    fresh = en.step_limit(z, dz, layout[0], 1.0, at_point=True)
    computed = en.step_limit(z, dz, layout[0], 1.0)
    assert fresh == computed and 0.0 < fresh < 1.0  # the random direction folds a corner
