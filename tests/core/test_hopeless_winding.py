"""Parts whose fixed boundary crosses itself and winds negatively somewhere are held before
the run (core/run/hopeless_winding.py): no optimizer iteration is spent on them, the
message names two boundary edges that cross and the winding number, the rest of the mesh
runs as usual."""

import numpy as np
from meshdata import quad_strip, spiked_strip

from core import EEGTParams, mesh_stats, untangle_and_smooth
from core.mesh.faces import as_faceset
from core.run.hopeless_winding import hopeless_winding


def _folded(x0: float = 0.0) -> tuple[np.ndarray, list[list[int]]]:
    """The strip with interior node (2, 1) pushed across its neighbour: a fold a move fixes."""
    p, f = quad_strip(x0=x0)
    p[7 + 2] = [x0 + 3.6, 1.4]
    return p, f


def test_a_boundary_node_dragged_through_the_far_side_is_held_at_once_with_the_point():
    p, f = spiked_strip()
    before = mesh_stats(p, f).n_inverted
    assert before > 0
    res = untangle_and_smooth(p, f)
    assert res.status == "failed"
    assert res.global_iterations == 0 and res.untangle_iterations == 0
    assert res.after.n_inverted == before
    assert np.array_equal(res.points, p) and not res.moved.any()
    assert "the fixed boundary of 18 faces crosses itself (its edges " in res.message
    assert ") and winds -1 times beside that crossing" in res.message, res.message
    assert "held as hopeless" in res.message


def test_the_witness_is_a_spike_edge_crossing_the_far_edge():
    p, f = spiked_strip()
    fs = as_faceset(f, p.shape[0])
    free = np.zeros(p.shape[0], dtype=bool)
    free[[8, 9, 10, 11, 12, 15, 16, 17, 18, 19]] = True  # the interior nodes
    h = hopeless_winding(p, fs, free)
    assert h.nodes.tolist() == [8, 9, 10, 11, 12, 15, 16, 17, 18, 19]
    ((a, b, c, d, w, n_faces),) = h.parts
    assert (w, n_faces) == (-1, 18)
    spike, top = {(2, 3), (3, 4)}, {(22, 23), (23, 24)}  # node 3's edges, the top row's
    assert {tuple(sorted((a, b))), tuple(sorted((c, d)))} in (
        {e, t} for e in spike for t in top)


def test_a_fold_beside_the_crossed_part_is_untangled_and_the_part_kept():
    a, fa = spiked_strip()
    b, fb = _folded(x0=10.0)
    p = np.vstack([a, b])
    f = fa + [[v + len(a) for v in face] for face in fb]
    res = untangle_and_smooth(p, f)
    assert res.status == "failed"
    assert np.array_equal(res.points[: len(a)], a)
    second = [[v - len(a) for v in face] for face in f[len(fa):]]
    assert mesh_stats(res.points[len(a):], second).n_inverted == 0
    assert mesh_stats(b, fb).n_inverted > 0
    assert "winds -1 times" in res.message


def test_a_boundary_with_a_free_node_is_not_examined():
    p, f = spiked_strip()
    fs = as_faceset(f, p.shape[0])
    free = np.zeros(p.shape[0], dtype=bool)
    free[[8, 9, 10, 11, 12, 15, 16, 17, 18, 19]] = True
    free[1] = True  # a boundary node that may move (a sliding one): the chain is not fixed
    assert hopeless_winding(p, fs, free).nodes.size == 0


def _overlapping_ring(turn: float = 2.0 * np.pi + 1.0, k: int = 48
                      ) -> tuple[np.ndarray, list[list[int]]]:
    """Two layers of quads between radii 1, 1.5 and 2 over an angle past a full turn, the
    radii shrinking by a fifth on the way (a spiral) so that the end passes inside the
    start: valid faces whose boundary crosses itself and winds twice where they overlap."""
    t = np.linspace(0.0, turn, k + 1)
    shrink = 1.0 - 0.2 * t / turn
    rows = [np.column_stack([r * shrink * np.cos(t), r * shrink * np.sin(t)])
            for r in (1.0, 1.5, 2.0)]
    p = np.vstack(rows)
    m = k + 1
    f = [[j * m + i, (j + 1) * m + i, (j + 1) * m + i + 1, j * m + i + 1]
         for j in range(2) for i in range(k)]
    return p, f


def test_a_self_overlapping_ring_that_winds_twice_is_not_held_and_is_untangled():
    p, f = _overlapping_ring()
    m = 49
    assert mesh_stats(p, f).n_inverted == 0
    p[m + 47] *= 1.45  # a middle node beside the end, whose edge crosses the start, pushed out
    assert mesh_stats(p, f).n_inverted > 0
    res = untangle_and_smooth(p, f, params=EEGTParams())
    assert "winds" not in res.message, res.message
    assert res.status in ("untangled", "valid") and res.after.n_inverted == 0


def test_the_repair_of_a_crossed_boundary_fails_at_once_and_moves_nothing():
    p, f = spiked_strip()
    res = untangle_and_smooth(p, f, params=EEGTParams(target="keep", region="folds"))
    assert res.status == "failed" and not res.moved.any()
    assert res.global_iterations == 0
    assert "winds -1 times" in res.message


def test_a_repair_beside_a_crossed_part_repairs_the_fold_and_names_the_part():
    a, fa = spiked_strip()
    b, fb = _folded(x0=10.0)
    p = np.vstack([a, b])
    f = fa + [[v + len(a) for v in face] for face in fb]
    res = untangle_and_smooth(p, f, params=EEGTParams(target="keep", region="folds"))
    assert res.status == "failed"
    assert not res.moved[: len(a)].any() and res.moved[len(a):].any()
    second = [[v - len(a) for v in face] for face in f[len(fa):]]
    assert mesh_stats(res.points[len(a):], second).n_inverted == 0
    assert res.after.n_inverted == mesh_stats(a, fa).n_inverted
    assert res.message.count("winds -1 times") == 1, res.message
