"""A fold no move opens and no certificate names ends the optimizer's run after
STALL_ROUNDS rounds without progress (core/optimize/stages.py), not after its whole budget."""

from pathlib import Path

import numpy as np

import core.run.pipeline as pipeline
from core import untangle_and_smooth
from core.mesh import read_obj
from core.optimize import STALL_ROUNDS, GlobalOptions, untangle_global
from core.run.hopeless import Hopeless
from core.run.hopeless_groups import HopelessGroups

U_STAR = Path(__file__).resolve().parents[1] / "e2e" / "data" / "u_star_impossible.obj"


def _u_star() -> tuple[np.ndarray, dict[int, np.ndarray], list[list[int]]]:
    p, fs = read_obj(U_STAR)
    tris = np.ascontiguousarray(fs.groups[0].nodes.T)
    return p[:, :2].copy(), {3: tris}, tris.tolist()


def test_u_star_without_its_certificate_gives_up_after_the_stall_rounds():
    """The optimizer alone on the U-star: each round leaves the worst det and the inverted
    count where they were; it stops after STALL_ROUNDS of them (was 20 300 iterations over
    19 368 rounds at the eps floor), 'failed', gave_up set, the best iterate returned."""
    p, groups, _ = _u_star()
    free = np.zeros(len(p), dtype=bool)
    free[8] = True
    out, info = untangle_global(p, groups, free)
    assert info["status"] == "failed" and info["gave_up"] is True
    assert STALL_ROUNDS <= info["rounds"] <= STALL_ROUNDS + 1
    assert info["n_inverted_out"] == 2
    assert info["iterations"] < 50 * STALL_ROUNDS
    assert np.array_equal(out[~free], p[~free])


def test_a_solvable_fold_does_not_give_up():
    """An octagon fan whose centre is dragged outside it: untangled, gave_up False."""
    t = 2 * np.pi * np.arange(8) / 8
    p = np.vstack([np.column_stack([np.cos(t), np.sin(t)]), [1.3, 0.2]])
    tris = np.array([[8, i, (i + 1) % 8] for i in range(8)])
    free = np.zeros(9, dtype=bool)
    free[8] = True
    _, info = untangle_global(p, {3: tris}, free)
    assert info["status"] == "untangled" and info["gave_up"] is False


def test_run_without_certificates_says_it_gave_up_in_well_under_a_second_of_iterations(
        monkeypatch):
    """The whole run on the U-star with both certificates switched off: 'failed' with the
    reason, a few hundred optimizer iterations (was 40 600, 78-97 s)."""
    p, _, faces = _u_star()
    monkeypatch.setattr(pipeline, "hopeless_nodes", lambda *a, **k: Hopeless(
        np.zeros(0, dtype=np.int64), ()))
    monkeypatch.setattr(pipeline, "hopeless_groups", lambda *a, **k: HopelessGroups(
        np.zeros(0, dtype=np.int64), ()))
    res = untangle_and_smooth(p, faces)
    assert res.status == "failed"
    assert res.after.n_inverted == 2
    assert res.global_iterations < 4 * 50 * STALL_ROUNDS
    assert (f"the optimizer gave up after {STALL_ROUNDS} rounds in a row without progress"
            in res.message), res.message


def _node_out_of_a_square(dy: float):
    """A regular triangulated square (boundary fixed) whose node nearest (0.5, 0.9) is
    pinned ``dy`` higher: (points, groups, free)."""
    from bench.meshgen import jittered_square
    from core import boundary_nodes

    p, fs = jittered_square(800, jitter=0.0)
    g = int(np.argmin(np.hypot(p[:, 0] - 0.5, p[:, 1] - 0.9)))
    p[g, 1] += dy
    free = ~boundary_nodes(p.shape[0], fs)
    free[g] = False
    return p, fs.by_arity(), free


def test_give_up_early_ends_a_region_too_tight_after_two_rounds():
    """A node pinned above the square's fixed top edge (no position of the others opens its
    fan): with ``give_up_early`` the run ends after its second untangling round, 'failed',
    too_tight and gave_up set; without, it goes on (more rounds, too_tight False)."""
    p, groups, free = _node_out_of_a_square(0.2)
    _, early = untangle_global(p, groups, free, GlobalOptions(give_up_early=True))
    assert early["status"] == "failed" and early["too_tight"] is True
    assert early["gave_up"] is True and early["rounds"] == 2
    _, plain = untangle_global(p, groups, free)
    assert plain["too_tight"] is False and plain["rounds"] > 2
    assert plain["iterations"] > early["iterations"]


def test_give_up_early_judges_the_second_round_tight_check_iterations_in(monkeypatch):
    """The node pinned 0.2 above the top edge: the second round is already too tight
    TIGHT_CHECK iterations in, and the run gives up there (888 iterations in all, measured)
    instead of at the round's end (1 375): the same points, too_tight either way."""
    from core.optimize import stages

    p, groups, free = _node_out_of_a_square(0.2)
    checked, ic = untangle_global(p, groups, free, GlobalOptions(give_up_early=True))
    monkeypatch.setattr(stages, "TIGHT_CHECK", 10**9)  # judged at the round's end only
    at_end, ie = untangle_global(p, groups, free, GlobalOptions(give_up_early=True))
    assert ic["too_tight"] is ie["too_tight"] is True and ic["rounds"] == ie["rounds"] == 2
    assert ic["iterations"] == 888 and ie["iterations"] == 1375
    assert np.array_equal(checked, at_end)


def test_give_up_early_ends_a_later_round_that_creeps():
    """A node pinned 0.1 up onto the square's fixed top edge (its fan cannot open; the
    first two rounds halve the worst det, so the two-round rule lets them pass): the third
    untangling round keeps every inverted element and raises the worst det by less than
    SLOW_RISE of it, and ``give_up_early`` ends the run there, 'failed', too_tight; without
    it the run creeps on to its whole budget (48 rounds, measured)."""
    p, groups, free = _node_out_of_a_square(0.1)
    _, early = untangle_global(p, groups, free, GlobalOptions(give_up_early=True))
    assert early["status"] == "failed" and early["too_tight"] is True
    assert early["gave_up"] is True and early["rounds"] == 3
    _, plain = untangle_global(p, groups, free)
    assert plain["status"] == "failed" and plain["too_tight"] is False
    assert plain["rounds"] > 20 and plain["iterations"] > 5 * early["iterations"]


def test_give_up_early_leaves_a_fold_that_opens_bit_identical():
    """A node pinned 0.05 up inside the square (its fan folds, the others can open it):
    the same points, bit for bit, with and without ``give_up_early``."""
    p, groups, free = _node_out_of_a_square(0.05)
    a, ia = untangle_global(p, groups, free, GlobalOptions(give_up_early=True))
    b, ib = untangle_global(p, groups, free)
    assert ia["n_inverted_in"] > 0 and ia["status"] == ib["status"] == "untangled"
    assert ia["too_tight"] is False
    assert np.array_equal(a, b)


def _folds_run(p, faces, fixed, watch: int, monkeypatch):
    """A region "folds" run with target "keep" and the settle's watch at `watch` iterations."""
    from core import EEGTParams
    from core.optimize import stages

    monkeypatch.setattr(stages, "SETTLE_WATCH", watch)
    return untangle_and_smooth(p, faces, fixed=fixed,
                               params=EEGTParams(region="folds", target="keep"))


def test_repair_attempt_stops_a_settle_that_never_reaches_the_climbs_q_min(monkeypatch):
    """An O-grid of triangles with its cylinder slid 0.1 chords: the repair's region settles
    at a floor its q_min never reaches (so the settle is not kept); the attempt stops it after
    SETTLE_WATCH iterations instead of SETTLE_ITER_SHAPED (target shapes): the same points,
    bit for bit, and SETTLE_ITER_SHAPED - SETTLE_WATCH fewer iterations."""
    from bench.repair_meshes import Spec, make
    from core.optimize.stages import SETTLE_ITER_SHAPED, SETTLE_WATCH

    c = make(Spec("ogridtri", 2000, "slide", {"dx": 0.1, "reach": 0.1}))
    watched = _folds_run(c.points, c.faces, c.fixed, SETTLE_WATCH, monkeypatch)
    full = _folds_run(c.points, c.faces, c.fixed, SETTLE_ITER_SHAPED, monkeypatch)
    assert watched.status == full.status == "untangled"
    assert np.array_equal(watched.points, full.points)
    assert (watched.global_iterations
            == full.global_iterations - (SETTLE_ITER_SHAPED - SETTLE_WATCH))


def test_repair_attempt_leaves_a_settle_that_reaches_the_climbs_q_min(monkeypatch):
    """An O-grid of quads with its cylinder slid 0.1 chords: the region's settle reaches the
    climb's q_min within the watch and runs its full length: the same points and iterations
    with and without the watch."""
    from bench.repair_meshes import Spec, make
    from core.optimize.stages import SETTLE_ITER_SHAPED, SETTLE_WATCH

    c = make(Spec("ogrid", 2000, "slide", {"dx": 0.1, "reach": 0.1}))
    watched = _folds_run(c.points, c.faces, c.fixed, SETTLE_WATCH, monkeypatch)
    full = _folds_run(c.points, c.faces, c.fixed, SETTLE_ITER_SHAPED, monkeypatch)
    assert watched.status == full.status == "untangled"
    assert np.array_equal(watched.points, full.points)
    assert watched.global_iterations == full.global_iterations


def test_repair_attempt_stops_a_settle_whose_q_avg_falls_from_the_start(monkeypatch):
    """An O-grid of quads with its cylinder turned 60 degrees: the region's settle lifts
    q_min above the climb's at once but lowers q_avg from the start, so it is not kept; the
    attempt stops it after SETTLE_WATCH iterations: the same points, bit for bit, and fewer
    iterations than the settle run to its end."""
    from bench.repair_meshes import Spec, make
    from core.optimize.stages import SETTLE_ITER_SHAPED, SETTLE_WATCH

    c = make(Spec("ogrid", 1000, "turn", {"angle": 60.0, "reach": 0.3}))
    watched = _folds_run(c.points, c.faces, c.fixed, SETTLE_WATCH, monkeypatch)
    full = _folds_run(c.points, c.faces, c.fixed, SETTLE_ITER_SHAPED, monkeypatch)
    assert watched.status == full.status == "untangled"
    assert np.array_equal(watched.points, full.points)
    assert watched.global_iterations < full.global_iterations
