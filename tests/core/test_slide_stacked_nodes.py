"""Boundary 'slide' when a boundary node sits on its neighbour (a node dragged onto the next
one along the boundary): the face between them is flat, and only sliding can open it.

The grid is 5 x 5 unit quads on [0, 5]^2 (nodes 0..35, row by row); its input boundary
polyline is the square, so every result boundary node must lie exactly on the square, the
four corners must stay bit-identical and the boundary nodes must keep their order. These
checks are written here from the square, not with core.eegt.boundary."""

import numpy as np
import pytest

from core import EEGTParams, mesh_stats, untangle_and_smooth
from core.eegt.boundary import SlideView, boundary_motion
from core.mesh.faces import as_faceset
from core.optimize import GlobalOptions, untangle_global

N = 5  # quads per side
M = N + 1  # nodes per side
CORNERS = [0, N, M * M - 1, M * N]  # (0, 0), (5, 0), (5, 5), (0, 5)
# the boundary counterclockwise from node 0: bottom, right, top (right to left), left (down)
LOOP = (list(range(M)) + [j * M + N for j in range(1, M)]
        + [M * N + i for i in range(N - 1, -1, -1)] + [j * M for j in range(N - 1, 0, -1)])
RING = [j * M + i for j in range(1, N) for i in range(1, N)
        if i in (1, N - 1) or j in (1, N - 1)]  # interior nodes next to the boundary


def grid() -> tuple[np.ndarray, np.ndarray]:
    """The 5 x 5 quad grid: (36, 2) points, (25, 4) counterclockwise faces."""
    xs, ys = np.meshgrid(np.arange(M, dtype=float), np.arange(M, dtype=float))
    p = np.column_stack([xs.ravel(), ys.ravel()])
    f = [[j * M + i, j * M + i + 1, (j + 1) * M + i + 1, (j + 1) * M + i]
         for j in range(N) for i in range(N)]
    return p, np.array(f)


def dragged_grid() -> tuple[np.ndarray, np.ndarray]:
    """The grid with its second node (1, 0) moved onto the first (0, 0): face 0 is flat."""
    p, f = grid()
    p[1] = p[0]
    return p, f


def square_arc(q: np.ndarray) -> np.ndarray:
    """Arc parameter (0..20, counterclockwise from (0, 0)) of points on the square's
    boundary; NaN for a point off it (not exactly on one of its four sides)."""
    x, y = q[:, 0], q[:, 1]
    inside = (x >= 0) & (x <= N) & (y >= 0) & (y <= N)
    return np.select(
        [inside & (y == 0), inside & (x == N), inside & (y == N), inside & (x == 0)],
        [x, N + y, 3 * N - x, 4 * N - y], np.nan)


def assert_slid_on_the_square(p0: np.ndarray, p1: np.ndarray) -> None:
    """Every boundary node on the square, the corners bit-identical, the order along the
    loop strict (no two boundary nodes left at one point)."""
    arc = square_arc(p1[LOOP])
    assert not np.isnan(arc).any(), np.array(LOOP)[np.isnan(arc)]
    assert np.array_equal(p1[CORNERS], p0[CORNERS])
    assert np.all(np.diff(arc) > 0.0)


# ---- which nodes slide ---------------------------------------------------------------------


def test_a_node_dragged_onto_a_corner_slides_and_the_corner_stays():
    p, f = dragged_grid()
    m = boundary_motion(p, as_faceset(f, len(p)), None, "slide", 30.0)
    sliding = m.sliding
    assert sliding[1] and not sliding[0]  # node 0 keeps the corner, node 1 slides off it
    assert not sliding[CORNERS].any() and m.n_corners == 4
    # every other boundary node slides as on the plain grid
    plain = boundary_motion(*grid()[:1], as_faceset(f, len(p)), None, "slide", 30.0)
    assert np.array_equal(sliding, plain.sliding)


def test_the_corner_keeper_of_a_stack_is_the_node_in_fewest_faces():
    """Node 6 (0, 1) dragged onto corner 0: the stack along the loop is (6, 0); node 0 has
    one face, node 6 two, so node 0 stays and node 6 slides back up the left side."""
    p, f = grid()
    p[M] = p[0]
    m = boundary_motion(p, as_faceset(f, len(p)), None, "slide", 30.0)
    assert m.sliding[M] and not m.sliding[0] and m.n_corners == 4


def test_a_pinned_node_in_the_stack_holds_the_corner():
    p, f = dragged_grid()
    pinned = np.zeros(len(p), dtype=bool)
    pinned[1] = True
    m = boundary_motion(p, as_faceset(f, len(p)), pinned, "slide", 30.0)
    assert m.sliding[0] and not m.movable[1]  # node 0 may slide up: node 1 holds (0, 0)
    assert m.n_corners == 3


def test_a_stack_on_a_straight_side_slides_whole():
    p, f = grid()
    p[2] = p[1]
    m = boundary_motion(p, as_faceset(f, len(p)), None, "slide", 30.0)
    assert m.sliding[[1, 2]].all() and m.n_corners == 4


# ---- item: slide untangles what only sliding can -----------------------------------------


@pytest.mark.parametrize("untangle", ["auto", "global", "eegt", "eegt+global", "eegt+local"])
def test_slide_untangles_a_boundary_node_dragged_onto_the_corner(untangle):
    p, f = dragged_grid()
    res = untangle_and_smooth(p, f, params=EEGTParams(boundary="slide", untangle=untangle))
    assert res.status == "untangled", res.message
    assert (res.before.n_inverted, res.after.n_inverted, res.n_frozen) == (1, 0, 0)
    assert res.after.q_min > 0.999  # measured 1.0: node 1 back at (1, 0)
    assert mesh_stats(res.points, f) == res.after
    assert_slid_on_the_square(p, res.points)
    assert res.points[1, 1] == 0.0 and 0.9 < res.points[1, 0] < 1.1


def test_fixed_reports_the_flat_corner_face_failed_and_names_it():
    p, f = dragged_grid()
    res = untangle_and_smooth(p, f)
    assert res.status == "failed" and res.as_dict()["status"] == "failed"
    assert (res.before.n_inverted, res.after.n_inverted, res.n_frozen) == (1, 1, 1)
    assert res.message.startswith("failed: face 0 stays inverted: a corner made of fixed "
                                  "vertices only"), res.message
    assert np.array_equal(res.points[LOOP], p[LOOP])


def test_free_untangles_it_moving_the_boundary_off_its_line():
    p, f = dragged_grid()
    res = untangle_and_smooth(p, f, params=EEGTParams(boundary="free"))
    assert res.status == "untangled" and res.after.n_inverted == 0
    assert res.after.q_min > 0.99  # measured 0.9999998
    assert np.isnan(square_arc(res.points[LOOP])).any()  # free: off the input boundary


def test_global_stage_lets_the_stacked_sliding_nodes_move_while_tangled():
    """The foldover optimization alone: the sliding nodes of a corner nothing else can open
    move from the start (the others join once the mesh is valid)."""
    p, f = dragged_grid()
    fs = as_faceset(f, len(p))
    m = boundary_motion(p, fs, None, "slide", 30.0)
    groups = fs.by_arity()
    # the boundary held (what 'fixed' can do): the flat corner never opens
    _, held = untangle_global(p, groups, m.movable & ~m.sliding, GlobalOptions(max_iter=500))
    assert held["status"] == "failed" and held["n_inverted_out"] == 1
    out, info = untangle_global(p, groups, m.movable, GlobalOptions(), slide=SlideView(m.slide))
    assert info["status"] == "untangled" and info["n_inverted_out"] == 0
    assert mesh_stats(out, f).n_inverted == 0
    assert_slid_on_the_square(p, out)


@pytest.mark.parametrize("seed", range(8))
def test_slide_untangles_stacked_boundary_nodes_with_jittered_neighbours(seed):
    """A random non-corner boundary node dragged onto a loop neighbour (a corner or a side
    node), and three interior nodes next to the boundary jittered by up to 0.7."""
    rng = np.random.default_rng(seed)
    p, f = grid()
    k = int(rng.choice([i for i, v in enumerate(LOOP) if v not in CORNERS]))
    onto = LOOP[(k + int(rng.choice([-1, 1]))) % len(LOOP)]
    p[LOOP[k]] = p[onto]
    moved = rng.choice(RING, 3, replace=False)
    p[moved] += rng.uniform(-0.7, 0.7, (3, 2))
    assert mesh_stats(p, f).n_inverted >= 1
    for untangle in ("auto", "eegt"):
        res = untangle_and_smooth(p, f, params=EEGTParams(boundary="slide", untangle=untangle))
        assert res.status == "untangled" and res.after.n_inverted == 0, (untangle, res.message)
        assert res.after.q_min > 0.99  # measured 1.0 on every seed (the grid comes back)
        assert_slid_on_the_square(p, res.points)
