"""Algorithm 1 end to end on the shared meshes, with the paper's parameters."""

import numpy as np
import pytest
from meshdata import load, load2d, mesquite_table1

from core import (
    Cancelled,
    EEGTParams,
    PlaneFrame,
    boundary_nodes,
    mesh_stats,
    untangle_and_smooth,
    untangle_and_smooth_3d,
)

PAPER = EEGTParams.paper()


@pytest.mark.parametrize("name", [
    "quad_hole", "tri_two_holes", pytest.param("naca_deform", marks=pytest.mark.slow),
    "mixed_quad_tri", "polygon_voronoi",
])
def test_paper_mode_untangles_shared_mesh_and_keeps_boundary_bit_identical(name):
    p, f = load2d(name)
    before = mesh_stats(p, f)
    assert before.n_inverted > 0
    res = untangle_and_smooth(p, f, params=PAPER)
    assert res.status == "untangled", res.message
    assert res.after.n_inverted == 0
    check = mesh_stats(res.points, f)  # reported stats are the returned mesh's
    assert check.n_inverted == 0 and check.q_min == res.after.q_min
    assert check.q_avg == pytest.approx(res.after.q_avg, rel=1e-13)
    assert res.after.q_min > 0 and res.after.q_avg > before.q_avg
    b = boundary_nodes(len(p), f)
    assert np.array_equal(res.points[b], p[b])  # bit-identical, not approximately equal
    assert np.isfinite(res.points).all()
    assert res.untangle_iterations >= 1 and res.smooth_iterations >= 1


def test_paper_mode_on_tilted_plane_through_plane_functions():
    v, f = load("tilted_plane")
    assert np.ptp(v[:, 2]) >= 0.99  # really tilted out of z = 0
    res = untangle_and_smooth_3d(v, f, params=PAPER)
    assert res.status == "untangled" and res.after.n_inverted == 0
    b = boundary_nodes(len(v), f)
    assert np.array_equal(res.points[b], v[b])
    # moved nodes stay in the plane of the input
    frame = PlaneFrame.fit(v, f)
    off_in = np.abs((v - frame.origin) @ frame.normal).max()  # OBJ rounding: ~1e-9
    off_out = np.abs((res.points[res.moved] - frame.origin) @ frame.normal).max()
    assert off_out < 1e-12 * np.ptp(v, axis=0).max() < off_in
    flat, _ = load2d("quad_hole")
    ref = untangle_and_smooth(flat, f, params=PAPER)
    assert res.after.q_avg == pytest.approx(ref.after.q_avg, abs=1e-6)


def test_paper_table1_mesh_from_mesquite_untangles():
    p, quads = mesquite_table1()
    before = mesh_stats(p, quads)
    assert before.n_inverted == 23 and before.q_avg == pytest.approx(0.6347, abs=5e-5)
    res = untangle_and_smooth(p, quads, params=PAPER)
    assert res.status == "untangled" and res.after.n_inverted == 0
    assert res.after.q_min > 0.2
    b = boundary_nodes(len(p), quads)
    assert b.sum() == 56 and np.array_equal(res.points[b], p[b])


def test_valid_mesh_skips_untangling_and_is_never_made_worse():
    p, f = load2d("quad_hole")
    first = untangle_and_smooth(p, f, params=PAPER)
    again = untangle_and_smooth(first.points, f, params=PAPER)
    assert again.status == "valid" and again.untangle_iterations == 0
    assert again.after.n_inverted == 0
    assert (again.after.q_min, again.after.q_avg) >= (first.after.q_min, first.after.q_avg)


def test_failed_untangling_returns_best_iterate_never_worse_than_input():
    p, f = load2d("two_holes_twist")
    before = mesh_stats(p, f)
    res = untangle_and_smooth(p, f, params=PAPER.with_(max_untangle_iterations=30))
    assert res.status == "failed" and "inverted" in res.message
    assert res.after.n_inverted <= before.n_inverted
    check = mesh_stats(res.points, f)
    assert (check.n_inverted, check.q_min) == (res.after.n_inverted, res.after.q_min)
    assert np.isfinite(res.points).all()


def test_same_input_gives_bit_identical_output():
    p, f = load2d("mixed_quad_tri")
    a = untangle_and_smooth(p, f, params=PAPER)
    b = untangle_and_smooth(p, f, params=PAPER)
    assert np.array_equal(a.points, b.points)
    assert (a.untangle_iterations, a.smooth_iterations) == (
        b.untangle_iterations,
        b.smooth_iterations,
    )


def test_renumbering_nodes_and_faces_changes_only_roundoff():
    p, f = load2d("polygon_voronoi")
    faces = f.to_lists()
    rng = np.random.default_rng(5)
    perm = rng.permutation(len(p))  # new index of old node i is inv[i]
    inv = np.argsort(perm)
    p2 = p[perm]
    order = rng.permutation(len(faces))
    faces2 = [[int(inv[i]) for i in faces[j]] for j in order]
    a = untangle_and_smooth(p, faces, params=PAPER)
    b = untangle_and_smooth(p2, faces2, params=PAPER)
    assert a.untangle_iterations == b.untangle_iterations
    assert a.smooth_iterations == b.smooth_iterations
    np.testing.assert_allclose(b.points[inv], a.points, rtol=0, atol=1e-12)


def test_pinned_nodes_never_move():
    p, f = load2d("quad_hole")
    free = ~boundary_nodes(len(p), f)
    pinned = np.zeros(len(p), bool)
    pinned[np.flatnonzero(free)[::5]] = True
    res = untangle_and_smooth(p, f, fixed=pinned, params=PAPER)
    assert np.array_equal(res.points[pinned], p[pinned])
    assert not res.moved[pinned].any()
    assert res.after.n_inverted == 0


def test_loose_vertices_are_ignored():
    p, f = load2d("quad_hole")
    p2 = np.vstack([p, [[123.0, -7.0]]])
    res = untangle_and_smooth(p2, f, params=PAPER)
    assert res.points[-1].tolist() == [123.0, -7.0]
    np.testing.assert_array_equal(res.points[:-1], untangle_and_smooth(p, f, params=PAPER).points)


def test_progress_reports_every_iteration_and_cancel_returns_input():
    p, f = load2d("tri_two_holes")
    seen = []

    def progress(it, phase, stats):
        seen.append((it, phase, stats.n_inverted))
        return it < 5

    res = untangle_and_smooth(p, f, params=PAPER, progress=progress)
    assert res.status == "cancelled"
    assert np.array_equal(res.points, p)
    assert res.after == res.before
    assert [s[0] for s in seen] == [0, 1, 2, 3, 4, 5]
    assert all(phase == "untangle" for _, phase, _ in seen)
    assert seen[0][2] == 4914

    def raising(it, phase, stats):
        if phase == "smooth":
            raise Cancelled

    p, f = load2d("quad_hole")
    res = untangle_and_smooth(p, f, params=PAPER, progress=raising)
    assert res.status == "cancelled" and np.array_equal(res.points, p)


def test_input_arrays_are_not_modified():
    p, f = load2d("quad_hole")
    faces = np.array(f.to_lists())
    p_copy, faces_copy = p.copy(), faces.copy()
    untangle_and_smooth(p, faces, params=PAPER)
    assert np.array_equal(p, p_copy) and np.array_equal(faces, faces_copy)


def test_coincident_free_nodes_are_pulled_apart():
    # 3x3 grid of quads; the centre-adjacent free nodes (here: the 4 interior nodes of a 4x4
    # node grid) all collapsed onto one point: zero-area faces, a tangle like any other.
    xs, ys = np.meshgrid(np.arange(4.0), np.arange(4.0))
    p = np.column_stack([xs.ravel(), ys.ravel()])
    faces = [
        [r * 4 + c, r * 4 + c + 1, (r + 1) * 4 + c + 1, (r + 1) * 4 + c]
        for r in range(3)
        for c in range(3)
    ]
    interior = [5, 6, 9, 10]
    p[interior] = [1.5, 1.5]
    res = untangle_and_smooth(p, faces, params=PAPER)
    assert res.status == "untangled" and res.after.n_inverted == 0
    assert res.after.q_min > 0.5


@pytest.mark.parametrize(
    "name",
    ["quad_hole", "tri_two_holes", "naca_deform", "mixed_quad_tri", "polygon_voronoi",
     "two_holes_twist"],
)
def test_default_parameters_untangle_every_shared_mesh_including_the_twist(name):
    p, f = load2d(name)
    res = untangle_and_smooth(p, f)
    assert res.status == "untangled" and res.after.n_inverted == 0, res.message
    assert res.global_iterations > 0  # the optimization stage did the untangling
    b = boundary_nodes(len(p), f)
    assert np.array_equal(res.points[b], p[b])
    check = mesh_stats(res.points, f)
    assert check.n_inverted == 0 and check.q_min == res.after.q_min > 0


def test_default_quality_beats_paper_mode_on_tri_two_holes_and_naca():
    for name, q_min, q_avg in (("tri_two_holes", 0.73, 0.985), ("naca_deform", 0.1, 0.81)):
        p, f = load2d(name)
        res = untangle_and_smooth(p, f)
        assert res.after.q_min > q_min and res.after.q_avg > q_avg, (name, res.after)


def test_eegt_then_global_when_eegt_stalls_on_the_twist():
    p, f = load2d("two_holes_twist")
    res = untangle_and_smooth(p, f, params=EEGTParams(untangle="eegt+global", stall_iterations=20))
    assert res.status == "untangled" and res.after.n_inverted == 0
    assert res.untangle_iterations >= 20 and res.global_iterations > 0


def test_cancel_during_global_stage_returns_input():
    p, f = load2d("naca_deform")
    phases = []

    def progress(it, phase, stats):
        phases.append(phase)
        return phase != "global"

    res = untangle_and_smooth(p, f, progress=progress)
    assert res.status == "cancelled" and np.array_equal(res.points, p)
    assert phases[-1] == "global"


def test_faceset_by_arity_rows_are_the_faces_in_order():
    from core import as_faceset

    faces = [[0, 1, 4, 3], [1, 2, 4], [2, 5, 4], [3, 4, 5, 7, 6]]
    by = as_faceset(faces, 8).by_arity()
    assert sorted(by) == [3, 4, 5]
    assert by[3].tolist() == [[1, 2, 4], [2, 5, 4]] and by[4].tolist() == [[0, 1, 4, 3]]
    assert by[5].tolist() == [[3, 4, 5, 7, 6]] and all(a.flags.c_contiguous for a in by.values())


# ---- a status never claims more than the result ------------------------------------------


def _grid(n: int = 4) -> tuple[np.ndarray, list]:
    """n x n unit quads, nodes row by row."""
    m = n + 1
    xs, ys = np.meshgrid(np.arange(m, dtype=float), np.arange(m, dtype=float))
    return np.column_stack([xs.ravel(), ys.ravel()]), [
        [m * j + i, m * j + i + 1, m * j + i + m + 1, m * j + i + m]
        for j in range(n) for i in range(n)]


def test_two_pinned_nodes_at_one_point_fail_at_once_naming_both_faces():
    """Pinned interior nodes 6 and 7 of a 4 x 4 grid at one point: their edge has length 0
    in faces 1 and 5 whatever the free nodes do. Both faces are frozen (two fixed nodes of
    a corner at one point), the run is 'failed' and says which faces and why, and EEGT does
    not spend its iteration cap on them."""
    p, f = _grid()
    pinned = np.zeros(len(p), dtype=bool)
    pinned[[6, 7]] = True
    p[7] = p[6]
    res = untangle_and_smooth(p, f, fixed=pinned, params=PAPER)
    assert res.status == "failed" and res.n_frozen == 2
    assert (res.before.n_inverted, res.after.n_inverted) == (2, 2)
    assert res.message.startswith("failed: 2 faces stay inverted (faces 1, 5): a corner made "
                                  "of fixed vertices only"), res.message
    assert res.untangle_iterations == 0


@pytest.mark.parametrize("untangle", ["global", "eegt"])
def test_status_is_failed_while_a_face_stays_inverted_even_if_the_rest_untangles(untangle):
    """A boundary node dragged onto the corner (fixed boundary): its face can never open;
    a folded interior node elsewhere is untangled, the mesh smoothed, and still the status
    is 'failed', never 'untangled'."""
    p, f = _grid()
    p[1] = p[0]
    p[18] = [2.6, 2.4]  # interior (3, 3) pushed across its neighbours
    before = mesh_stats(p, f)
    assert before.n_inverted > 1
    res = untangle_and_smooth(p, f, params=PAPER.with_(untangle=untangle))
    assert res.status == "failed" and res.n_frozen == 1
    assert res.after.n_inverted == 1 == mesh_stats(res.points, f).n_inverted
    assert "face 0 stays inverted" in res.message and "untangled in" in res.message
