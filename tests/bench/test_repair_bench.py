"""bench.repair_bench and bench.repair_meshes on one tiny case (seconds): the case is made,
cached and reloaded with the same bits, the repair leaves nothing inverted and keeps every
node outside its region, and the measures read 1 / 0 where nothing changed."""

from __future__ import annotations

import os

import numpy as np
import pytest

from bench import repair_bench as rb
from bench import repair_meshes as rm
from core import faces_from_csr, mesh_stats

TINY = rm.Spec("ogrid", 1000, "slide", {"dx": 0.1, "reach": 0.1, "first": 1e-2})


@pytest.fixture(autouse=True)
def tmp_cache(tmp_path, monkeypatch):
    monkeypatch.setattr(rm, "CACHE", tmp_path)


def test_tiny_o_grid_case_folds_near_the_wall_and_reloads_the_same_bits():
    case = rm.load(TINY)
    assert TINY.path.exists()
    assert mesh_stats(case.reference, case.faces).n_inverted == 0
    folded = mesh_stats(case.points, case.faces).n_inverted
    assert 10 < folded < 0.2 * case.n_faces
    assert case.wall.sum() == 32 and np.all(case.fixed[case.wall])
    far = case.fixed & ~case.wall
    assert np.array_equal(case.points[far], case.reference[far])
    again = rm.load(TINY)
    assert np.array_equal(again.points, case.points)
    assert np.array_equal(again.faces.indices, case.faces.indices)


def test_repair_row_leaves_nothing_inverted_and_the_input_row_measures_the_deformation():
    case = rm.load(TINY)
    rows = rb.run_case(case, ("keep",), timeout=120.0)
    assert [r.column for r in rows] == ["input", "keep"]
    inp, keep = rows
    assert inp.inverted == inp.folded > 0 and inp.moved == 0.0
    assert keep.inverted == 0, keep.note
    assert 0.0 < keep.moved < 0.5 and keep.rings is not None and keep.rings >= 3
    # the wall cells away from the fold keep the input's first layer (here the deformation's
    # own change: a first cell of 1e-2 chords lags behind the slid wall)
    assert keep.layer_med == inp.layer_med and keep.layer_worst_away == inp.layer_worst_away
    text = rb.table(rows)
    assert len(text) == 4 and text[3].startswith("| ogrid-1000-slide")
    assert len(rb.summary(rows)) == 4


def test_the_undeformed_mesh_measures_1_against_itself_and_the_folded_input_0():
    case = rm.load(TINY)
    geo = rb.geometry(case)
    built = rb.measure(case, geo, case.reference, rb.Row("tiny", "ogrid", "x", case.n_faces, 0))
    assert np.isclose(built.built_min, 1.0) and np.isclose(built.built_p1, 1.0)
    assert built.area_p95 == 0.0 and built.aspect_p95 == 0.0
    given = rb.measure(case, geo, case.points, rb.Row("tiny", "ogrid", "x", case.n_faces, 0))
    assert given.built_min == 0.0 and given.inverted > 0


def test_the_p95_floor_counts_every_cell_around_a_moved_node_as_undeformed():
    """floors: the input's per-cell values, those of the cells with a moved node set to 0.
    Constant values make the p95 exact: nothing moved keeps them, everything moved gives 0,
    one face's nodes (under 5 % of the cells) leave the p95 where it was."""
    from dataclasses import replace

    case = rm.load(TINY)
    geo = rb.geometry(case)
    flat = replace(geo, area_in=np.full(case.n_faces, 2.0), aspect_in=np.full(case.n_faces, 3.0))
    n = case.points.shape[0]
    assert rb.floors(flat, case.faces, np.zeros(n, dtype=bool)) == (2.0, 3.0)
    assert rb.floors(flat, case.faces, np.ones(n, dtype=bool)) == (0.0, 0.0)
    one = np.zeros(n, dtype=bool)
    one[case.faces.to_lists()[0]] = True
    assert rb.floors(flat, case.faces, one) == (2.0, 3.0)


def test_the_floor_is_the_input_p95_where_nothing_moved_and_under_a_repair_p95():
    case = rm.load(TINY)
    inp, keep = rb.run_case(case, ("keep",), timeout=120.0)
    assert (inp.area_floor, inp.aspect_floor) == (inp.area_p95, inp.aspect_p95)
    assert keep.area_floor <= keep.area_p95 and keep.aspect_floor <= keep.aspect_p95
    assert keep.area_floor < inp.area_p95  # the repair moved the folded cells


def test_the_floor_table_marks_a_peer_p95_below_our_floor():
    base = dict(case="c", family="f", cells=10, folded=1)
    keep = rb.Row(column="keep", inverted=0, area_p95=1.5, area_floor=0.9, aspect_p95=1.2,
                  aspect_floor=0.5, **base)
    peer = rb.Row(column="peer", inverted=0, area_p95=0.8, aspect_p95=0.6, **base)
    stopped = rb.Row(column="peer", **{**base, "case": "d"})
    lines = rb.floor_table([keep, peer, rb.Row(column="keep", **{**base, "case": "d"}), stopped])
    assert lines[2:] == ["| c | 1.5, 0.9, 0.8 (below) | 1.2, 0.5, 0.6 |"]


def test_keep_fast_repairs_without_the_lift_rounds_and_keeps_the_rest():
    assert rb.PARAMS["keep-fast"].lift_rounds == 0 and rb.PARAMS["keep"].lift_rounds > 0
    case = rm.load(TINY)
    rows = rb.run_case(case, ("keep", "keep-fast"), timeout=120.0)
    inp, keep, fast = rows
    assert fast.column == "keep-fast" and fast.inverted == 0 and fast.note == ""
    assert 0.0 < fast.moved < 0.5 and fast.rings == keep.rings
    assert fast.layer_med == inp.layer_med and 0.0 < fast.built_min <= 1.0


def test_keep_on_the_device_repairs_like_keep_or_is_left_out_without_one():
    case = rm.load(TINY)
    rows = rb.run_case(case, ("keep", "keep-cl"), timeout=120.0)
    by = {r.column: r for r in rows}
    assert set(by) <= {"input", "keep", "keep-cl"} and "keep" in by
    if "keep-cl" in by:  # (its bits are NumPy's on a CPU device: tests/opencl)
        assert by["keep-cl"].inverted == 0, by["keep-cl"].note
        assert 0.0 < by["keep-cl"].moved < 0.5


def test_keep_on_the_device_finishes_in_a_process_whose_device_is_already_set_up():
    """A child forked from a process with an OpenCL runtime cannot use it (pocl's threads
    are not copied: it waits for ever), so the bench then spawns its runs. The device is
    set up here first, as in a test session that ran the OpenCL tests before."""
    from core.eegt import warm_up

    why = warm_up("auto")
    if why is not None:
        pytest.skip(why)
    rows = rb.run_case(rm.load(TINY), ("keep-cl",), timeout=60.0)
    assert [r.column for r in rows] == ["input", "keep-cl"]
    assert rows[1].inverted == 0, rows[1].note


def test_each_call_runs_in_a_process_of_its_own():
    one, two = rm.in_fresh_process(os.getpid), rm.in_fresh_process(os.getpid)
    assert len({os.getpid(), one, two}) == 3


def test_a_gmsh_boundary_layer_mesh_has_the_same_counts_whatever_was_made_before_it():
    # gmsh orders some sets by memory address, so two fresh processes can place and number
    # the nodes a little differently (the case cache keeps the first mesh made); the counts
    # and the wall are the same, and each mesh comes from a fresh gmsh (the test above)
    pytest.importorskip("gmsh", reason="gmsh is not installed")
    first = rm.fresh_gmsh_bl("cylinder", 1000)
    rm.fresh_gmsh_bl("naca", 1000, quads=False)  # another mesh in between
    again = rm.fresh_gmsh_bl("cylinder", 1000)
    assert first[0].shape == again[0].shape
    arities = [(g.n, g.size) for g in first[1].groups]
    assert arities == [(g.n, g.size) for g in again[1].groups] and {n for n, _ in arities} == {3, 4}
    assert int(first[2].sum()) == int(again[2].sum()) > 0
    walls = [m[0][m[2]] for m in (first, again)]
    walls = [w[np.lexsort(w.T[::-1])] for w in walls]  # the wall's nodes, in one order
    assert np.allclose(walls[0], walls[1], rtol=0.0, atol=1e-12)


def test_measures_of_a_rectangle_and_a_triangle():
    p = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 1.0], [0.0, 1.0], [2.0, 3.0]])
    fs = faces_from_csr([0, 4], [4, 3], [0, 1, 2, 3, 3, 2, 4], 5)
    assert np.allclose(rb.aspects(p, fs)[0], 4.0)
    assert np.allclose(rb.signed_areas(p, fs), [4.0, 4.0])
    eq = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(0.75)]])
    assert np.allclose(rb.aspects(eq, faces_from_csr([0], [3], [0, 1, 2], 3)), 1.0)
    wall = np.array([True, True, False, False, False])
    f, a, b = rb.wall_cells(fs, wall)
    assert f.tolist() == [0] and {a[0], b[0]} == {0, 1}
    assert rb.abs_log_ratio(np.array([-1.0, 2.0]), np.array([1.0, 2.0])).tolist() == [np.inf,
                                                                                      0.0]


def test_repeated_runs_report_the_median_seconds_and_say_when_points_differ(monkeypatch):
    """--repeat 3: the row's seconds are the median of the three runs' (3, 1, 2 -> 2), its
    measures the first run's; a run whose points differ is named in the note."""
    case = rm.load(TINY)
    real = rb._ours
    first = real(case, "keep", 120.0)
    secs = iter([3.0, 1.0, 2.0, 3.0, 1.0, 2.0])
    shift = iter([0.0, 0.0, 0.0, 0.0, 1e-9, 0.0])

    def timed(_case, _col, _timeout):
        pts, moved, status, message, _, backend = first
        return pts + next(shift), moved, status, message, next(secs), backend

    monkeypatch.setattr(rb, "_ours", timed)
    alike = {r.column: r for r in rb.run_case(case, ("keep",), timeout=120.0, repeat=3)}
    assert alike["keep"].seconds == 2.0 and alike["keep"].note == ""
    assert alike["keep"].inverted == 0
    differ = {r.column: r for r in rb.run_case(case, ("keep",), timeout=120.0, repeat=3)}
    assert differ["keep"].seconds == 2.0
    assert differ["keep"].note == " 3 runs gave different points!"


def test_a_repeated_run_that_stops_is_named_and_left_out_of_the_median(monkeypatch):
    """--repeat 3 where the second run stops at the timeout: the median of the other two
    (3, 1 -> 2), the first run's measures, and a note that one of three runs stopped."""
    case = rm.load(TINY)
    first = rb._ours(case, "keep", 120.0)
    got = iter([3.0, None, 1.0])

    def timed(_case, _col, _timeout):
        secs = next(got)
        if secs is None:
            return None
        pts, moved, status, message, _, backend = first
        return pts, moved, status, message, secs, backend

    monkeypatch.setattr(rb, "_ours", timed)
    row = {r.column: r for r in rb.run_case(case, ("keep",), timeout=120.0, repeat=3)}["keep"]
    assert row.seconds == 2.0 and row.inverted == 0
    assert row.note == " 1 of 3 runs stopped or raised (not in the median)"


def test_unseen_cases_are_held_out_pinned_and_named_once():
    specs = rb.unseen_specs()
    names = [s.name for s in specs]
    assert len(names) == len(set(names)) == 14
    assert all(s.held_out and s.mesh == "public" for s in specs)
    assert all(len(rm.PUBLIC[str(s.size)].digest) == 16 for s in specs)
    assert {s.motion for s in specs} == {"turn", "slide"}


def _folded(spec: rm.Spec) -> tuple[int, int]:
    from core.run import folded_faces

    case = rm.make(spec)
    return int(folded_faces(case.points, case.faces, ~case.fixed).sum()), case.n_faces


@pytest.mark.parametrize("spec", rb.unseen_specs(), ids=lambda s: s.name)
def test_unseen_case_takes_the_smallest_step_that_folds_one_percent(spec):
    try:
        rm.public_file(str(spec.size))
    except FileNotFoundError as exc:
        pytest.skip(str(exc))
    key, step = ("angle", 5.0) if spec.motion == "turn" else ("dx", 0.05)
    folded, cells = _folded(spec)
    assert folded >= max(20, 0.01 * cells)
    smaller = {**spec.params, key: round(spec.params[key] - step, 2)}
    folded, cells = _folded(rm.Spec(spec.mesh, spec.size, spec.motion, smaller, True))
    assert folded < max(20, 0.01 * cells)
