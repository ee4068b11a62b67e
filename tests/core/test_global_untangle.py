"""Tests of core.optimize (foldover-free energy + L-BFGS, the lift); the boundary (the tests'
oracle, tests/oracles.py) and the quality are computed independently of the core, the meshes
read by tests/meshdata.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from meshdata import load2d, load_groups, spun_hole
from oracles import boundary_mask

import core.optimize.stages as stages
from core.optimize import GlobalOptions, lift_min_quality, untangle_global


def quality(points: np.ndarray, groups: dict[int, np.ndarray]) -> tuple[float, float, int]:
    """The mean ratio (docs/method.md 3): q_min, q_avg (inverted = 0), number inverted."""
    qs, n_inv = [], 0
    for n, f in groups.items():
        p = points[f]
        a = (n - 2) * np.pi / n
        winv = np.linalg.inv(np.array([[1.0, np.cos(a)], [0.0, np.sin(a)]]))
        jac = np.stack([np.roll(p, -1, axis=1) - p, np.roll(p, 1, axis=1) - p], axis=-1)
        det_j = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
        m = jac @ winv
        det_m = m[..., 0, 0] * m[..., 1, 1] - m[..., 0, 1] * m[..., 1, 0]
        qk = 2.0 * det_m / np.maximum(np.sum(m * m, axis=(-1, -2)), 1e-300)
        bad = np.any(det_j <= 0, axis=1)
        n_inv += int(bad.sum())
        qs.append(np.where(bad, 0.0, qk.mean(axis=1)))
    q = np.concatenate(qs)
    return float(q.min()), float(q.mean()), n_inv


def load_case(name: str) -> tuple[np.ndarray, dict[int, np.ndarray], np.ndarray]:
    pts, groups = load_groups(name)
    return pts, groups, ~boundary_mask(groups, len(pts))


def check_result(pts, groups, free, out, info) -> tuple[float, float, int]:
    assert out.shape == pts.shape and out.dtype == np.float64
    assert np.all(np.isfinite(out))
    assert np.array_equal(out[~free], pts[~free])  # bit-identical non-free rows
    q = quality(out, groups)
    assert info["n_inverted_out"] == q[2]
    assert info["iterations"] <= 3000
    return q


@pytest.mark.parametrize("name", ["two_holes_twist", "naca_deform"])
def test_deformation_folds_untangled(name: str) -> None:
    pts, groups, free = load_case(name)
    assert quality(pts, groups)[2] > 0
    out, info = untangle_global(pts, groups, free)
    q_min, q_avg, n_inv = check_result(pts, groups, free, out, info)
    assert n_inv == 0 and info["status"] == "untangled"
    assert q_min > 0.02 and q_avg > 0.7
    assert info["eps_history"] and info["seconds"] > 0


def test_naca_perturbed_untangled() -> None:
    pts, groups, free = load_case("naca_deform")
    span = float(np.ptp(pts, axis=0).max())
    for seed in (101, 202):
        rng = np.random.default_rng(seed)
        p2 = pts.copy()
        p2[free] += 1e-9 * span * rng.standard_normal((int(free.sum()), 2))
        out, info = untangle_global(p2, groups, free, GlobalOptions(polish_iter=0))  # untangle only
        assert check_result(p2, groups, free, out, info)[2] == 0 and info["status"] == "untangled"


@pytest.mark.parametrize("name", ["quad_hole", "mixed_quad_tri", "polygon_voronoi"])
def test_polygons_untangled(name: str) -> None:
    pts, groups, free = load_case(name)
    out, info = untangle_global(pts, groups, free)
    q_min, q_avg, n_inv = check_result(pts, groups, free, out, info)
    assert n_inv == 0
    assert q_min > 0.5 and q_avg > 0.85


def test_deterministic_and_input_untouched() -> None:
    pts, groups, free = load_case("polygon_voronoi")
    before = pts.copy()
    a, ia = untangle_global(pts, groups, free)
    b, ib = untangle_global(pts.copy(), {n: f.copy() for n, f in groups.items()}, free.copy())
    assert np.array_equal(pts, before)
    assert a.tobytes() == b.tobytes()
    assert ia["iterations"] == ib["iterations"] and ia["eps_history"] == ib["eps_history"]


def grid(n: int) -> tuple[np.ndarray, dict[int, np.ndarray], np.ndarray]:
    """Unit square, (n+1)^2 nodes, 2 n^2 counterclockwise triangles; boundary fixed."""
    t = np.linspace(0.0, 1.0, n + 1)
    xx, yy = np.meshgrid(t, t)
    pts = np.stack([xx.ravel(), yy.ravel()], 1)
    ij = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = ij[:-1, :-1].ravel(), ij[:-1, 1:].ravel(), ij[1:, 1:].ravel(), ij[1:, :-1].ravel()
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    free = (pts[:, 0] > 0) & (pts[:, 0] < 1) & (pts[:, 1] > 0) & (pts[:, 1] < 1)
    return pts, {3: tris}, free


def test_synthetic_fold() -> None:
    pts, groups, free = grid(8)
    folded = pts.copy()
    # push a column of interior nodes across its neighbours: a fold of several triangles
    col = free & np.isclose(pts[:, 0], 0.375)
    folded[col, 0] += 0.3
    assert quality(folded, groups)[2] > 4
    out, info = untangle_global(folded, groups, free)
    q_min, _, n_inv = check_result(folded, groups, free, out, info)
    assert n_inv == 0 and q_min > 0.5


def test_collapsed_nodes_pulled_apart() -> None:
    pts, groups, free = grid(6)
    collapsed = pts.copy()
    collapsed[free] = [0.3, 0.6]  # every free node at one point (zero-area elements)
    out, info = untangle_global(collapsed, groups, free)
    _, _, n_inv = check_result(collapsed, groups, free, out, info)
    assert n_inv == 0


def test_valid_mesh_stays_valid_and_nothing_to_do() -> None:
    pts, groups, free = grid(5)
    out, info = untangle_global(pts, groups, free)
    assert check_result(pts, groups, free, out, info)[2] == 0
    out2, info2 = untangle_global(pts, groups, np.zeros(len(pts), dtype=bool))
    assert info2["status"] == "nothing to do" and np.array_equal(out2, pts)


def test_progress_can_cancel() -> None:
    pts, groups, free = load_case("quad_hole")
    calls: list[tuple[int, int, int]] = []

    def cb(it: int, total: int, n_inv: int, _current) -> bool:
        calls.append((it, total, n_inv))
        return False

    out, info = untangle_global(pts, groups, free, progress=cb)
    assert len(calls) == 1 and info["status"] == "cancelled"
    assert np.array_equal(out[~free], pts[~free]) and np.all(np.isfinite(out))


def test_bad_input_rejected() -> None:
    pts, groups, free = grid(3)
    bad = pts.copy()
    bad[5, 0] = np.nan
    with pytest.raises(ValueError):
        untangle_global(bad, groups, free)
    with pytest.raises(ValueError):
        untangle_global(pts, groups, free[:-1])


def test_unfixable_element_left_out_of_the_goal_not_looped() -> None:
    """A corner of fixed nodes only that is inverted can never change: it is not a reason to
    fail or to iterate (the pipeline counts such faces apart: test_frozen_faces_*)."""
    pts, groups, free = grid(10)
    tri = groups[3][0]
    fixed_free = free.copy()
    fixed_free[tri] = False
    bad = pts.copy()
    bad[tri[1]] = bad[tri[0]] + [-0.01, 0.0]  # an inverted element no free node can repair
    assert quality(bad, groups)[2] == 1
    out, info = untangle_global(bad, groups, fixed_free)
    assert info["status"] == "untangled" and info["iterations"] < 500  # no futile iterations
    assert quality(out, groups)[2] == 1 and info["n_inverted_out"] == 0
    assert np.array_equal(out[~fixed_free], bad[~fixed_free]) and np.all(np.isfinite(out))


def test_bit_identical_across_blas_threads() -> None:
    """Same bytes with 1 BLAS thread (subprocess) as with the default thread count."""
    import hashlib
    import os
    import subprocess
    import sys

    pts, groups, free = load_case("naca_deform")
    out, _ = untangle_global(pts, groups, free, GlobalOptions(polish_iter=0))
    here = hashlib.sha256(out.tobytes()).hexdigest()
    code = (
        "import hashlib\n"
        "from tests.core.test_global_untangle import GlobalOptions, load_case, untangle_global\n"
        "p, g, f = load_case('naca_deform')\n"
        "o, _ = untangle_global(p, g, f, GlobalOptions(polish_iter=0))\n"
        "print(hashlib.sha256(o.tobytes()).hexdigest())\n"
    )
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    root = Path(__file__).resolve().parents[2]
    paths = [str(root), str(root / "tests"), env.get("PYTHONPATH", "")]  # tests: meshdata
    env["PYTHONPATH"] = os.pathsep.join(p for p in paths if p)
    res = subprocess.run(
        [sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True, check=True
    )
    assert res.stdout.strip() == here


def test_polish_power_raises_min_quality() -> None:
    pts, groups, free = load_case("quad_hole")
    q1 = quality(untangle_global(pts, groups, free)[0], groups)
    q4 = quality(untangle_global(pts, groups, free, GlobalOptions(polish_power=4.0))[0], groups)
    assert q1[2] == q4[2] == 0
    assert q4[0] > q1[0] + 0.02  # measured 0.776 vs 0.737
    with pytest.raises(ValueError):
        untangle_global(pts, groups, free, GlobalOptions(polish_power=0.0))


@pytest.mark.parametrize("turns", [1, 2])
def test_full_turn_twist_not_left_degenerate(turns: int) -> None:
    """A disc turned by whole turns: the first valid iterate has dets ~1e-12; the polish must
    still reach a good mesh (with eps kept large after validity it stalled at q_min 1e-11)."""
    pts, groups, free = grid(40)
    c = np.array([0.5, 0.5])
    d = pts - c
    a = 2.0 * np.pi * turns * np.clip((0.2 - np.hypot(d[:, 0], d[:, 1])) / 0.05, 0.0, 1.0)
    twisted = c + np.stack(
        [np.cos(a) * d[:, 0] - np.sin(a) * d[:, 1], np.sin(a) * d[:, 0] + np.cos(a) * d[:, 1]], 1
    )
    twisted[~free] = pts[~free]
    assert quality(twisted, groups)[2] > 20
    out, info = untangle_global(twisted, groups, free)
    q_min, _, n_inv = check_result(twisted, groups, free, out, info)
    assert n_inv == 0 and q_min > 0.5  # measured 0.73-0.74 (before the fix: 1e-13 and 0.14)


def test_max_iter_bounds_the_work() -> None:
    pts, groups, free = load_case("naca_deform")
    out, info = untangle_global(pts, groups, free, GlobalOptions(max_iter=20))
    assert info["iterations"] <= 20 and info["status"] == "failed"
    assert 0 < info["n_inverted_out"] < info["n_inverted_in"]  # best iterate, fewer folds
    check_result(pts, groups, free, out, info)
    # a much larger cap untangles (the exact count is trajectory-dependent: no knife edge)
    out, info = untangle_global(pts, groups, free, GlobalOptions(max_iter=3000, polish_iter=10_000))
    assert info["iterations"] <= 3000 and info["status"] == "untangled"


def test_progress_reported_inside_the_polish_and_cancels_there() -> None:
    pts, groups, free = load_case("two_holes_twist")
    calls: list[int] = []
    untangle_global(pts, groups, free, progress=lambda it, m, n, _c: calls.append(it))
    assert len(calls) >= 10 and calls == sorted(calls)  # not only once per eps round
    seen: list[int] = []

    def stop_in_polish(it: int, total: int, n_inv: int, _current) -> bool:
        seen.append(it)
        return n_inv > 0 or it < 100

    out, info = untangle_global(pts, groups, free, progress=stop_in_polish)
    assert info["status"] == "cancelled" and 100 <= info["iterations"] < 200
    assert np.all(np.isfinite(out)) and np.array_equal(out[~free], pts[~free])


@pytest.mark.parametrize("name", ["quad_hole", "mixed_quad_tri"])
def test_lift_raises_min_quality_without_lowering_mean(name: str) -> None:
    pts, groups, free = load_case(name)
    polished = untangle_global(pts, groups, free)[0]
    m0, a0, _ = quality(polished, groups)
    out, info = lift_min_quality(polished, groups, free)
    m1, a1, n_inv = quality(out, groups)
    assert info["status"] == "lifted" and n_inv == 0
    assert m1 > m0 + 0.02 and a1 >= a0  # measured 0.737 -> 0.78 (quad_hole), 0.752 -> 0.83
    assert info["q_min_out"] == pytest.approx(m1) and info["q_avg_out"] == pytest.approx(a1)
    assert np.array_equal(out[~free], pts[~free])
    again, _ = lift_min_quality(polished, groups, free)
    assert np.array_equal(again, out)  # deterministic


def test_lift_leaves_inverted_input_unchanged_and_can_cancel() -> None:
    pts, groups, free = load_case("quad_hole")
    out, info = lift_min_quality(pts, groups, free)  # 23 inverted: nothing to lift
    assert info["status"] == "unchanged" and np.array_equal(out, pts)
    polished = untangle_global(pts, groups, free)[0]
    out, info = lift_min_quality(polished, groups, free, progress=lambda it, r, q_min, q_avg: False)
    assert info["status"] == "cancelled" and np.array_equal(out, polished)


def jittered_lattice(n: int, amp: float, seed: int):
    """A unit square of 2 n^2 right triangles, interior nodes shaken by up to amp / n
    (valid for amp < 0.5), and its interior (free) nodes."""
    g = np.linspace(0.0, 1.0, n + 1)
    x, y = np.meshgrid(g, g, indexing="ij")
    pts = np.column_stack([x.ravel(), y.ravel()])
    inner = (pts > 0.0).all(axis=1) & (pts < 1.0).all(axis=1)
    rng = np.random.default_rng(seed)
    pts[inner] += rng.uniform(-amp / n, amp / n, (int(inner.sum()), 2))
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    b, d = a + n + 1, a + 1
    c = b + 1
    tris = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    return pts, {3: tris}, inner


def test_lift_progress_shows_the_whole_mesh_runs_current_numbers() -> None:
    """The whole-mesh run, in runs of 10, reports each run's end point, not the input's
    numbers (the kept iterate's) all along."""
    pts, groups, free = jittered_lattice(60, 0.3, 1)
    seen: list = []
    options = GlobalOptions(lift_first_iter=300, lift_rounds=0, lift_rel_tol=1e-7,
                            lift_chunk=10)
    _, info = lift_min_quality(pts, groups, free, options,
                               progress=lambda it, r, q_min, q_avg: seen.append((it, q_min, q_avg)))
    q_avgs = [a for _, _, a in seen]
    assert len(set(q_avgs)) >= 5  # measured 7 distinct values in 8 calls (65 iterations)
    assert q_avgs[0] > info["q_avg_in"] + 0.05  # not the input's numbers (0.792 -> 0.866)
    assert q_avgs == sorted(q_avgs) and seen[-1][1:] == info["trail"][0]


def test_lift_rings_must_not_be_negative() -> None:
    with pytest.raises(ValueError, match="lift_rings"):
        GlobalOptions(lift_rings=-1)


@pytest.mark.parametrize(("degrees", "triangles"), [(120, False), (120, True), (100, False)])
def test_spun_hole_untangles_regression_inner_runs_too_short(degrees, triangles) -> None:
    """Regression: with 60 L-BFGS iterations per eps round the interior could not turn far
    enough before eps shrank, and a hole boundary spun 100-120 degrees stayed folded (57-64
    inner-ring faces inverted after 5300 iterations, 30000 did not help). Rounds now run to
    convergence: about 1300-1500 iterations."""
    pts, groups = spun_hole(12, 64, degrees, triangles)
    free = ~boundary_mask(groups, len(pts))
    assert quality(pts, groups)[2] == 64  # the whole inner ring is inverted
    out, info = untangle_global(pts, groups, free, GlobalOptions(max_iter=5300))
    assert np.array_equal(out[~free], pts[~free])
    q_min, _q_avg, n_inv = quality(out, groups)
    assert info["status"] == "untangled" and n_inv == 0 and q_min > 0.0
    assert info["iterations"] < 2500


def test_spun_hole_180_degrees_untangles_and_the_stage_cap_is_respected() -> None:
    """The pipeline's global stage may use max_untangle_iterations + polish iterations: a
    hole spun half a turn (either way round is valid) untangles with the defaults (some
    2700-4000 iterations, depending on the trajectory), and a cap far below that is obeyed
    by each of the two stages a failing run makes (from the input, then from the harmonic
    start)."""
    from core import EEGTParams, untangle_and_smooth

    pts, groups = spun_hole(6, 32, 180, False)
    res = untangle_and_smooth(pts, groups[4])
    assert res.status == "untangled" and res.after.n_inverted == 0 < res.before.n_inverted
    assert res.global_iterations > 1000  # far beyond what a short cap allows
    capped = untangle_and_smooth(
        pts, groups[4], params=EEGTParams(max_untangle_iterations=200, polish_iterations=50)
    )
    assert capped.status == "failed" and 250 < capped.global_iterations <= 2 * 250
    assert 0 < capped.after.n_inverted <= capped.before.n_inverted  # best iterate, never worse


def test_lift_grow_must_exceed_one() -> None:
    with pytest.raises(ValueError, match="lift_grow"):
        GlobalOptions(lift_grow=1.0)


def test_local_mode_lift_takes_the_larger_floor_step(monkeypatch) -> None:
    """'eegt+local' lifts with lift_grow LOCAL_LIFT_GROW (1.3), 'global' with the default
    1.15: the whole-mesh mode keeps its results, the large-mesh mode reaches a higher q_min
    in the same rounds (bench/scale_mesher.py: 0.7876 -> 0.7938 at 1.06M triangles)."""
    from core import EEGTParams, untangle_and_smooth
    from core.run import pipeline

    seen: list[float] = []
    real = pipeline.lift_min_quality

    def spy(*a, **k):
        seen.append(a[3].lift_grow)
        return real(*a, **k)

    monkeypatch.setattr(pipeline, "lift_min_quality", spy)
    pts, groups, free = jittered_lattice(30, 0.3, 2)
    for mode in ("eegt+local", "global"):
        res = untangle_and_smooth(pts, groups[3], fixed=~free, params=EEGTParams(untangle=mode))
        assert res.after.n_inverted == 0
    assert seen == [pipeline.LOCAL_LIFT_GROW, 1.15] and pipeline.LOCAL_LIFT_GROW == 1.3


def lift_runs(name: str, monkeypatch, retry: bool) -> tuple[object, dict]:
    """untangle_and_smooth's defaults on tests/data/NAME.obj, with or without the lift's
    half-step retry: (result, the lift's info)."""
    from core import EEGTParams, untangle_and_smooth
    from core.optimize import stages
    from core.run import pipeline

    infos: list[dict] = []
    real = pipeline.lift_min_quality

    def spy(*a, **k):
        out, info = real(*a, **k)
        infos.append(info)
        return out, info

    monkeypatch.setattr(pipeline, "lift_min_quality", spy)
    if not retry:
        monkeypatch.setattr(stages, "LIFT_RETRY", 1.0)
    pts, faces = load2d(name)
    res = untangle_and_smooth(pts, faces, params=EEGTParams(), backend="numpy")
    monkeypatch.undo()
    assert res.after.n_inverted == 0 and len(infos) == 1
    return res, infos[0]


def test_lift_round_that_costs_too_much_q_avg_is_retried_at_half_the_step(monkeypatch) -> None:
    """naca_deform's eighth lift round raises q_min 0.415 -> 0.474 but takes q_avg below 97 %
    of the lift's best (0.841): the climb ended there, at the paper's q_min (0.4157). Tried
    again at half the floor step it is kept and the climb goes on (measured 0.4442 / 0.8508
    against 0.4154 / 0.8547)."""
    monkeypatch.setattr(stages, "SETTLE_FLOOR", 0.0)  # the climb alone (no settle)
    before, _ = lift_runs("naca_deform", monkeypatch, retry=False)
    after, info = lift_runs("naca_deform", monkeypatch, retry=True)
    assert before.after.q_min < 0.4157 < 0.4357 < after.after.q_min
    assert after.after.q_avg > max(before.after.q_avg - 0.005, 0.8102 + 0.03)
    trail = info["trail"]
    missed = [i for i in range(1, len(trail) - 1)
              if trail[i + 1][0] < trail[i][0] and trail[i + 1][1] > trail[i][1]]
    assert missed  # a round's point followed by the retry's lower q_min, higher q_avg
    assert info["q_min_out"] > trail[missed[0] - 1][0]  # the climb went past the miss


def test_lift_on_a_good_mesh_ends_at_the_first_miss(monkeypatch) -> None:
    """Once q_min >= q_avg / 2 a round must keep the input's q_avg: a miss there ends the
    climb as before (quad_hole: the same points with and without the retry)."""
    plain, _ = lift_runs("quad_hole", monkeypatch, retry=False)
    res, info = lift_runs("quad_hole", monkeypatch, retry=True)
    assert np.array_equal(res.points, plain.points)
    last_m, last_a = info["trail"][-1]  # the miss: more q_min, less q_avg, not kept
    assert last_m > info["q_min_out"] and last_a < info["q_avg_out"]
    assert res.after.q_min > 0.77 and res.after.q_avg > 0.892  # measured 0.7706 / 0.8922


def test_local_mode_leaves_out_eegt_smoothing_after_a_kept_lift_round() -> None:
    """'eegt+local': once a lift round is kept, EEGT smoothing (which would move every node
    and not raise the lifted worst faces) is left out; without lift rounds it runs."""
    from core import EEGTParams, untangle_and_smooth

    pts, groups, free = jittered_lattice(30, 0.3, 2)
    lifted = untangle_and_smooth(pts, groups[3], fixed=~free,
                                 params=EEGTParams(untangle="eegt+local"))
    plain = untangle_and_smooth(pts, groups[3], fixed=~free,
                                params=EEGTParams(untangle="eegt+local", lift_rounds=0))
    assert lifted.smooth_iterations == 0 and plain.smooth_iterations >= 1
    assert lifted.global_iterations > plain.global_iterations  # the rounds ran
    assert lifted.after.q_min > plain.after.q_min + 0.01  # measured 0.861 against 0.848


def test_long_untangle_gets_a_polish_as_long_as_the_untangling() -> None:
    """A hole spun 100 degrees takes over 1000 L-BFGS iterations to untangle; the polish then
    gets as many (up to one eps round, 1000 here) instead of polish_iter's 300, on top of
    max_iter, and raises q_min from 0.151 to 0.316 (measured); long_polish=False keeps 300."""
    pts, groups = spun_hole(12, 64, 100, False)
    free = ~boundary_mask(groups, len(pts))
    short_out, short = untangle_global(pts, groups, free,
                                       GlobalOptions(max_iter=5300, long_polish=False))
    out, info = untangle_global(pts, groups, free, GlobalOptions(max_iter=5300))
    assert short["status"] == info["status"] == "untangled"
    assert short["iterations"] <= info["iterations"] - 500  # 1413 against 2175
    assert quality(short_out, groups)[0] < 0.2 < 0.3 < quality(out, groups)[0]
    # the longer polish comes on top of max_iter: a cap just past the untangling still
    # leaves it its full length
    cap = short["iterations"] - 250
    _, capped = untangle_global(pts, groups, free, GlobalOptions(max_iter=cap))
    assert capped["status"] == "untangled" and capped["iterations"] > cap + 500
    # polish_iter=0 still returns the first valid iterate, after over 1000 iterations
    _, first = untangle_global(pts, groups, free, GlobalOptions(max_iter=5300, polish_iter=0))
    assert first["status"] == "untangled" and 1000 < first["iterations"] <= cap


def measure_every_tick(monkeypatch) -> None:
    """Progress numbers measured at every tick (`Sampled` otherwise waits between two)."""
    import core.optimize.sampled as sampled

    monkeypatch.setattr(sampled, "SAMPLE_EVERY", 0.0)
    monkeypatch.setattr(sampled, "SAMPLE_SHARE", float("inf"))


def test_lift_progress_inside_one_long_run_shows_its_current_numbers(monkeypatch) -> None:
    """Without runs of a fixed length ('global' mode's lift) the whole-mesh run is one solve:
    its ticks show the current iterate's numbers, rising, not the input's all along."""
    measure_every_tick(monkeypatch)
    pts, groups, free = jittered_lattice(60, 0.3, 1)
    seen: list = []
    options = GlobalOptions(lift_first_iter=300, lift_rounds=0, lift_rel_tol=1e-7)
    _, info = lift_min_quality(pts, groups, free, options,
                               progress=lambda it, r, q_min, q_avg: seen.append((it, q_min, q_avg)))
    inside = [a for it, _, a in seen[:-1]]  # the last call is the run's end
    assert len(inside) >= 2 and len(set(inside)) == len(inside)
    assert inside[0] > info["q_avg_in"] + 0.03 and inside == sorted(inside)


def test_pipeline_progress_in_the_global_stage_shows_the_current_iterate(monkeypatch) -> None:
    """Regression: the global stage reported the input's q_avg (and the best inverted count,
    the input's until a round ended better) while the iterate moved. Now each report is the
    current iterate's: on the spun hole the count rises above the input's 64 before it falls
    to 0, and the valid iterates' q_avg (about 0.33-0.37: the untangled inner ring pulls its
    neighbours) moves from report to report, far from the input's 0.774."""
    from core import EEGTParams, untangle_and_smooth

    measure_every_tick(monkeypatch)
    pts, groups = spun_hole(12, 64, 100, False)
    rows: list = []
    res = untangle_and_smooth(pts, groups[4], params=EEGTParams(untangle="global"),
                              progress=lambda it, phase, s: rows.append((phase, s)))
    inside = [s for phase, s in rows if phase == "global"]
    counts = [s.n_inverted for s in inside]
    assert res.before.n_inverted == 64 and max(counts) > 64 and counts[-1] == 0
    valid = [s.q_avg for s in inside if s.n_inverted == 0]
    assert len(set(valid)) >= 5 and max(valid) < res.before.q_avg - 0.3
    assert abs(valid[-1] - res.after.q_avg) < 0.02


def test_pipeline_progress_in_the_local_untangle_shows_the_current_iterate(monkeypatch) -> None:
    """Regression: the local untangle's sub-mesh solve reported the best iterate's numbers
    (EEGT's q_min and q_avg, its 4 inverted faces) until it ended. Now each report is the
    whole mesh with the sub-mesh at the solve's current iterate: the count reaches 0 inside
    the solve and q_avg moves from report to report as the sub-mesh is polished."""
    import dataclasses

    from core import EEGTParams, untangle_and_smooth
    from core.run import pipeline

    measure_every_tick(monkeypatch)
    real_eegt, real_local = pipeline._Run.untangle_eegt, pipeline._Run.untangle_local
    rows: list = []
    span: list[int] = []

    def one_eegt_step(self):  # leaves 4 of the 94 inverted faces to the local stage
        full = self.params
        self.params = dataclasses.replace(full, max_untangle_iterations=1)
        try:
            return real_eegt(self)
        finally:
            self.params = full

    def local(self):
        span.append(len(rows))
        try:
            return real_local(self)
        finally:
            span.append(len(rows))

    monkeypatch.setattr(pipeline._Run, "untangle_eegt", one_eegt_step)
    monkeypatch.setattr(pipeline._Run, "untangle_local", local)
    pts, groups, free = jittered_lattice(30, 0.6, 1)
    res = untangle_and_smooth(pts, groups[3], fixed=~free, params=EEGTParams(untangle="eegt+local"),
                              progress=lambda it, phase, s: rows.append((phase, s)))
    eegt = [s for phase, s in rows[:span[0]] if phase == "untangle"]
    inside = [s for _, s in rows[span[0]:span[1]]]
    assert [s.n_inverted for s in eegt] == [94, 4] and res.status == "untangled"
    assert len(inside) >= 5 and inside[-1].n_inverted == 0
    assert len({s.q_avg for s in inside}) >= 4  # the best iterate's would be one value
    assert all(s.q_avg != eegt[-1].q_avg for s in inside)


def test_lift_progress_inside_a_local_round_shows_the_whole_mesh_at_its_current_point(
        monkeypatch) -> None:
    """Regression: a lift round's sub-mesh solve ticked with the kept iterate's numbers until
    it ended. Now its ticks show the whole mesh's (q_min, q_avg) with the sub-mesh at the
    solve's current point: q_min moves inside each round (below the kept iterate's at first:
    the floor's energy is not q_min itself) and the round's end reports its result."""
    import core.optimize.energy as energy

    measure_every_tick(monkeypatch)
    monkeypatch.setattr(energy, "TICK_EVERY", 1)  # a tick every iteration, small meshes too
    pts, groups, free = jittered_lattice(60, 0.3, 1)
    seen: list = []
    options = GlobalOptions(lift_first_iter=300, lift_rounds=3, lift_rel_tol=1e-7,
                            lift_chunk=10, lift_rings=3)
    _, info = lift_min_quality(pts, groups, free, options,
                               progress=lambda it, r, q_min, q_avg: seen.append((r, q_min)))
    for r in (1, 2, 3):
        inside = [m for rr, m in seen if rr == r]  # the round's ticks, then its end
        start, end = info["trail"][r - 1][0], info["trail"][r][0]
        assert inside[-1] == end > start  # the round's end: its result
        ticks = inside[:-1]  # measured 10-13 distinct values in each round
        assert len(set(ticks)) >= 4 and start not in ticks
