"""Bad input and edge cases get a clear answer: types, units, orientation, frozen corners,
progress. Each test is named after what it pins."""

from __future__ import annotations

import numpy as np
import pytest
from meshdata import load2d

from core import EEGTParams, mesh_stats, quality, untangle_and_smooth
from core.optimize import energy
from core.optimize.state import TICK_EVERY

FAN_PTS = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]], float)
FAN = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]


# -- types ----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"a": "x"}, "a must be a finite number, got 'x'"),
        ({"a": float("inf")}, "a must be finite"),
        ({"eta": float("nan")}, "eta must be finite"),
        ({"tol": -float("inf")}, "tol must be finite"),
        ({"a": None}, "a must be a finite number, got None"),
        ({"a": True}, "a must be a finite number"),
        ({"max_untangle_iterations": 2.5}, "max_untangle_iterations must be an integer"),
        ({"untangle": 3}, "untangle must be a string"),
    ],
)
def test_params_of_wrong_type_or_infinite_raise_value_error(changes, message):
    with pytest.raises(ValueError, match=message):
        EEGTParams(**changes)


def test_params_accept_numpy_numbers():
    p = EEGTParams(a=np.float64(0.3), max_untangle_iterations=np.int64(10))
    assert p.a == 0.3 and p.max_untangle_iterations == 10


@pytest.mark.parametrize(
    ("faces", "message"),
    [
        ([[0, 1, "a"], [1, 2, 4]], "face indices must be integers, got strings"),
        ([[0, 1, None], [1, 2, 4]], "face indices must be integers, got None"),
        (np.array([[0, 1, None]], dtype=object), "face indices must be integers, got None"),
        ([[0, 1, 4.5]], "face indices must be integers, got 4.5"),
        ([[0, 1, [4]]], "faces must be a sequence of vertex-index sequences"),
        (7, "faces must be a sequence"),
    ],
)
def test_faces_of_strings_or_none_raise_value_error(faces, message):
    keep = FAN_PTS.copy()
    with pytest.raises(ValueError, match=message):
        untangle_and_smooth(FAN_PTS, faces)
    with pytest.raises(ValueError, match=message):
        quality(FAN_PTS, faces)
    assert np.array_equal(FAN_PTS, keep)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"max_untangle_iterations": np.float64(2.5)},
         "invalid parameter: max_untangle_iterations must be an integer, got 2.5$"),
        ({"a": np.float64("nan")}, "invalid parameter: a must be finite, got nan$"),
    ],
)
def test_bad_numpy_scalar_parameters_are_shown_as_plain_numbers(params, message):
    """A NumPy scalar in a refused parameter reads as its number under NumPy 1 and 2 (NumPy
    2's repr would say "np.float64(2.5)")."""
    from core.params import EEGTParams

    with pytest.raises(ValueError, match=message):
        EEGTParams(**params)


def test_quality_of_string_points_raises_value_error():
    with pytest.raises(ValueError, match="points must be an \\(N, 2\\) array of numbers"):
        quality([["a", "b"]] * 5, FAN)
    with pytest.raises(ValueError, match="params must be an EEGTParams"):
        untangle_and_smooth(FAN_PTS, FAN, params={"a": 0.2})
    with pytest.raises(ValueError, match="fixed must be an \\(5,\\) bool array"):
        untangle_and_smooth(FAN_PTS, FAN, fixed=np.array(["x"] * 5))


# -- units ----------------------------------------------------------------------------------
def test_scale_by_power_of_two_gives_bit_identical_scaled_result_from_1e_minus_298_to_1e298():
    p, f = load2d("quad_hole")
    ref = untangle_and_smooth(p, f)
    assert ref.status == "untangled"
    for k in (-990, -512, -3, 7, 500, 990):
        s = 2.0**k
        res = untangle_and_smooth(p * s, f)
        assert res.status == "untangled" and np.array_equal(res.points, ref.points * s), k
        assert (res.after.q_min, res.after.q_avg) == (ref.after.q_min, ref.after.q_avg)


@pytest.mark.parametrize("scale", [1e-300, 1e-160, 1e-20, 1e20, 1e154, 1e300])
def test_result_does_not_depend_on_units_from_1e_minus_300_to_1e300(scale):
    """Regression: at 1e154 the stats were NaN and the run 'valid'; at 1e-300 a valid grid
    was 'failed'; 1e-160 spent 13 s on 5300 iterations."""
    p, f = load2d("quad_hole")
    ref = untangle_and_smooth(p, f)
    res = untangle_and_smooth(p * scale + 3.0 * scale, f)
    assert res.status == "untangled", res.message
    assert np.isfinite([res.after.q_min, res.after.q_avg, res.before.q_avg]).all()
    assert res.after.n_inverted == 0 and abs(res.after.q_avg - ref.after.q_avg) < 0.01
    assert res.after.q_min > 0.7 and res.global_iterations < 2 * ref.global_iterations
    assert np.all(np.isfinite(res.points))
    grid = untangle_and_smooth(ref.points * scale, f)  # an untangled mesh stays valid
    assert grid.status == "valid" and grid.after.n_inverted == 0


# -- orientation ----------------------------------------------------------------------------
def test_clockwise_input_is_refused_up_front_in_one_line():
    p, f = load2d("tri_two_holes")
    with pytest.raises(ValueError, match="faces are clockwise") as err:
        untangle_and_smooth(p, f.reversed())
    assert "\n" not in str(err.value) and "reverse" in str(err.value)


def test_zero_area_mesh_is_refused():
    flat = FAN_PTS * [1.0, 0.0]  # the square squashed onto a line
    with pytest.raises(ValueError, match="zero total area"):
        untangle_and_smooth(flat, FAN)


# -- frozen corners -------------------------------------------------------------------------
def _grid_with_straight_boundary_corner(tangle: bool):
    """3x3 quads; the bottom middle quad gets a boundary node at its edge's midpoint, which
    makes it a pentagon with a 180 degree corner of three boundary (fixed) nodes."""
    pts = [[i, j] for j in range(4) for i in range(4)] + [[1.5, 0.0]]
    node = lambda i, j: 4 * j + i  # noqa: E731
    faces = []
    for j in range(3):
        for i in range(3):
            quad = [node(i, j), node(i + 1, j), node(i + 1, j + 1), node(i, j + 1)]
            if (i, j) == (1, 0):
                quad = [node(1, 0), 16, node(2, 0), node(2, 1), node(1, 1)]
            faces.append(quad)
    p = np.array(pts, float)
    if tangle:
        p[node(1, 1)] = [2.6, 2.4]  # folds the faces around the moved interior node
    return p, faces


def test_straight_corner_of_fixed_nodes_is_kept_as_given():
    """A grid whose boundary n-gon has a 180 degree corner made only of fixed nodes (a knife
    cut): the face is simple and counterclockwise, so the corner is kept as given and the
    run is 'valid' (issue 40); measured without that vertex, the face is a unit square."""
    p, f = _grid_with_straight_boundary_corner(tangle=False)
    res = untangle_and_smooth(p, f)
    assert res.status == "valid" and res.n_frozen == 0 and res.n_kept == 1
    assert res.before.n_inverted == 0 == res.after.n_inverted and res.after.q_min == 1.0
    assert "1 face kept as given" in res.message and "failed" not in res.message


def test_frozen_straight_corner_of_fixed_nodes_is_a_named_failure_in_the_paper_mode():
    """The paper's rule (untangle='eegt'): every corner counts, so that face is inverted and
    no move can change it: the run is 'failed' (CLI exit 3), never 'valid', and its message
    says which face and why."""
    p, f = _grid_with_straight_boundary_corner(tangle=False)
    res = untangle_and_smooth(p, f, params=EEGTParams(untangle="eegt"))
    assert res.status == "failed" and res.n_frozen == 1 and res.n_kept == 0
    assert res.before.n_inverted == 1 == res.after.n_inverted
    assert res.message.startswith("failed: face 1 stays inverted: a corner made of fixed "
                                  "vertices only"), res.message
    assert res.as_dict()["frozen_faces"] == 1


def test_frozen_corner_does_not_stop_untangling_the_rest():
    p, f = _grid_with_straight_boundary_corner(tangle=True)
    before = mesh_stats(p, f)
    assert before.n_inverted > 1
    for untangle in ("global", "eegt+global"):  # the corner kept as given: untangled
        res = untangle_and_smooth(p, f, params=EEGTParams(untangle=untangle))
        assert res.status == "untangled" and res.n_frozen == 0, (untangle, res.message)
        assert res.after.n_inverted == 0 == mesh_stats(res.points, f, kept=res.kept).n_inverted
    res = untangle_and_smooth(p, f, params=EEGTParams(untangle="eegt"))  # the paper's rule
    assert res.status == "failed" and res.n_frozen == 1, res.message
    assert "face 1 stays inverted" in res.message and "untangled in" in res.message
    assert res.after.n_inverted == 1 == mesh_stats(res.points, f).n_inverted


# -- progress -------------------------------------------------------------------------------
@pytest.mark.parametrize("answer", [False, np.False_, 0])
def test_falsy_progress_answer_cancels(answer):
    p, f = load2d("quad_hole")
    res = untangle_and_smooth(p, f, progress=lambda it, phase, s: answer)
    assert res.status == "cancelled" and np.array_equal(res.points, p)


@pytest.mark.parametrize("answer", [None, True, np.True_, 1])
def test_none_or_truthy_progress_answer_continues(answer):
    p, f = load2d("quad_hole")
    res = untangle_and_smooth(p, f, progress=lambda it, phase, s: answer)
    assert res.status == "untangled"


def test_progress_stats_never_jump_back_to_the_inputs_inverted_count():
    """Regression: during the lift the inverted count shown was the input's (4914) again
    after 0 had been shown."""
    p, f = load2d("tri_two_holes")
    seen: list[tuple[int, str, int]] = []
    res = untangle_and_smooth(p, f, progress=lambda it, ph, s: seen.append((it, ph, s.n_inverted)))
    assert res.status == "untangled" and seen[0][2] == 4914
    first_zero = next(k for k, (_, _, n) in enumerate(seen) if n == 0)
    assert all(n == 0 for _, _, n in seen[first_zero:])
    its = [it for it, _, _ in seen]
    assert its == sorted(its)


def test_progress_comes_every_few_iterations_inside_the_global_stage():
    p, f = load2d("naca_deform")
    its = []
    untangle_and_smooth(p, f, progress=lambda it, ph, s: its.append(it) if ph == "global" else None)
    gaps = np.diff(its)
    assert len(its) > 100 and gaps.max() <= TICK_EVERY


def test_big_meshes_tick_every_iteration(monkeypatch):
    """Ticks are spaced by mesh size (TICK_CORNERS / corners iterations), so that a 1M-face
    run calls back every iteration; shown here by lowering the threshold."""
    monkeypatch.setattr(energy, "TICK_CORNERS", 100)
    p, f = load2d("quad_hole")
    its = []
    untangle_and_smooth(p, f, progress=lambda it, ph, s: its.append(it) if ph == "global" else None)
    assert len(its) > 50 and np.diff(its).max() <= 1


@pytest.mark.parametrize("scale", [1e-300, 1e-160, 1e154, 1e300])
def test_planar_3d_mesh_does_not_depend_on_units(scale):
    """Regression: untangle_and_smooth_3d refused a tilted mesh at 1e-300, 1e-160 and 1e154
    ('zero total area') and at 1e300 (overflow to NaN)."""
    from meshdata import load

    from core import untangle_and_smooth_3d

    p, f = load("tilted_plane")
    ref = untangle_and_smooth_3d(p, f)
    res = untangle_and_smooth_3d(p * scale, f)
    assert res.status == "untangled" and np.all(np.isfinite(res.points))
    assert abs(res.after.q_avg - ref.after.q_avg) < 0.01 and res.after.q_min > 0.7
    k = 900 if scale > 1 else -900
    exact = untangle_and_smooth_3d(p * 2.0**k, f)
    assert np.array_equal(exact.points, ref.points * 2.0**k)


@pytest.mark.parametrize("index", [6730, 7995])
def test_bug_straight_fixed_corner_judged_in_the_callers_coordinates(index):
    """Fuzz seed 1: a straight corner of fixed nodes (det exactly 0 as given) turned 1e-17
    positive once translated, so the run counted its face as changeable and returned a
    result worse than the input as the caller measures it. Frozen faces are now decided on
    the caller's points (divided by the power-of-two scale, exact) and the result is never
    worse in the caller's coordinates; a 2^k multiple of the input behaves the same."""
    from bench.fuzz import make_case

    case = make_case(1, index)
    prm = EEGTParams(**case["params"])
    res = untangle_and_smooth(case["points"], case["faces"], fixed=case["fixed"], params=prm)
    assert res.n_frozen >= 1
    assert res.after == res.before or res.after.better_than(res.before)
    assert res.after == mesh_stats(res.points, case["faces"])
    tiny = untangle_and_smooth(case["points"] * 2.0**-341, case["faces"], fixed=case["fixed"],
                               params=prm)
    assert np.array_equal(tiny.points, res.points * 2.0**-341) and tiny.status == res.status


def test_bug_quality_rounding_above_one_gives_no_nan_weight():
    """q can round to 1 + 1 ulp on a regular face: 1 - q < 0 made (1 - q)^eta NaN for a
    non-integer eta, and every node of such a face stood still. A face at 1 + 1 ulp now
    weighs what a face at exactly 1 does (nothing)."""
    from core import free_nodes
    from core.eegt.engine_numpy import NumpyEngine
    from core.mesh.faces import as_faceset

    p, f = load2d("mixed_quad_tri")
    fs = as_faceset(f, len(p))
    moves = []
    for q_top in (1.0, np.nextafter(1.0, 2.0)):
        eng = NumpyEngine(p, fs, free_nodes(len(p), fs), EEGTParams(eta=1.3))
        for q in eng.q:
            q[::3] = q_top  # every third face of each group (near) perfect
        moves.append(eng._node_moves())
    for a, b in zip(moves[0], moves[1], strict=True):
        assert np.all(np.isfinite(b)) and np.array_equal(a, b)


def test_diverging_free_boundary_paper_run_warns_nothing():
    """Fuzz seed 1 case 3, paper settings with a free boundary: the boundary drifts away and
    passes 1e153 at iteration 2483, where the engine's squared edges overflow. The NumPy
    engine warned (RuntimeWarning, overflow) where the OpenCL twin, with the same result,
    does not; the overflow is part of the result and the best iterate is kept."""
    import warnings

    from bench.fuzz import make_case

    case = make_case(1, 3)
    prm = EEGTParams.paper().with_(boundary="free", max_untangle_iterations=2500)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = untangle_and_smooth(case["points"], case["faces"], fixed=case["fixed"],
                                  params=prm)
    assert res.status == "failed" and res.untangle_iterations == 2500
    assert (res.before.n_inverted, res.after.n_inverted) == (4, 1)
    assert res.after.q_avg == pytest.approx(0.8881281962219975, abs=1e-12)
