"""A resting drag that yields (core/run/live_pull.py): the grabbed node pulled towards the
cursor through valid layouts only, when the frames cannot open the fold with it pinned."""

from __future__ import annotations

import numpy as np
from oracles import inverted_faces

from bench.meshgen import jittered_square
from core import boundary_nodes
from core.optimize.energy import FoldoverEnergy
from core.optimize.solver import ResumableLBFGS, lbfgs
from core.optimize.stages import EPS_MIN
from core.optimize.state import State
from core.run.live import LiveSession
from core.run.live_pull import PULL_REACH, PullEnergy


def _rest(live: LiveSession, frame, limit: int = 400):
    """Rest frames (no time budget) until the pull is done or the frames settle."""
    for _ in range(limit):
        frame = live.frame(None, budget=None)
        if frame.settled:
            break
    return frame


def test_a_node_pulled_out_of_the_square_stops_inside_with_no_face_inverted():
    """The grabbed node asked above the top edge (no place there is valid): the rest's pull
    from the drag's start ends with 0 inverted faces by an independent count, the node below
    the top edge and ``held_back`` its distance from the cursor; the border and every node
    beyond the pull's reach keep their bits."""
    p, fs = jittered_square(2000, jitter=0.0)
    border = boundary_nodes(p.shape[0], fs)
    g = int(np.argmin(np.hypot(p[:, 0] - 0.5, p[:, 1] - 0.9)))
    live = LiveSession(p, fs, [g], pull_after=0.0)
    asked = p[[g]] + [0.0, 0.2]
    frame = live.frame(asked, budget=None)
    assert frame.status == "tangled"
    assert live.finishing(frame) == "go on"
    frame = _rest(live, frame)
    assert frame.pull_iterations == 0 and frame.status == "untangled"
    assert not inverted_faces(frame.points, fs).any()
    assert frame.points[g, 1] < 1.0
    d = frame.points[g] - asked[0]
    assert frame.held_back == float(np.sqrt(d[0] * d[0] + d[1] * d[1]))
    assert frame.held_back > 0.1
    assert np.array_equal(frame.points[border], p[border])
    way = float(np.hypot(*(asked[0] - p[g])))  # from y 0.9 to 1.1: within 0.1 of y = 1
    beyond = np.hypot(p[:, 0] - p[g, 0], p[:, 1] - 1.0) > PULL_REACH * way + 0.1 + 0.1
    assert beyond.sum() > p.shape[0] // 2  # (one ring of faces more: 0.1)
    assert np.array_equal(frame.points[beyond], p[beyond])
    assert live.finishing(frame) == "keep"


def test_a_pull_the_layout_lets_through_puts_the_node_on_the_cursor():
    """A centre node asked 0.43 up in one jump, the border 0.07 beyond (no fold-free carried
    start: a node that stays too near ahead; one frame of one iteration leaves it folded):
    the pull gets it there through valid layouts and then puts it exactly on the cursor's
    place; the frames after it smooth with the node pinned there. A pull frame on the way
    is valid but not settled (the node still travels)."""
    p, fs = jittered_square(2000, jitter=0.0)
    border = boundary_nodes(p.shape[0], fs)
    g = int(np.argmin(np.hypot(p[:, 0] - 0.5, p[:, 1] - 0.5)))
    live = LiveSession(p, fs, [g], pull_after=0.0)
    asked = p[[g]] + [0.0, 0.43]
    frame = live.frame(asked, budget=0.0, iterations=1)
    assert frame.status == "tangled"
    pulled = live.frame(None, budget=None)
    assert pulled.pull_iterations > 0
    assert not inverted_faces(pulled.points, fs).any()
    assert pulled.status != "tangled" and pulled.held_back > 0.0 and not pulled.settled
    frame = _rest(live, pulled)
    assert np.array_equal(frame.points[g], asked[0])
    assert frame.held_back == 0.0 and frame.settled
    assert not inverted_faces(frame.points, fs).any()
    assert np.array_equal(frame.points[border], p[border])


def test_a_node_dragged_past_the_border_beside_it_is_pulled_back_inside():
    """A node of the row next to the bottom edge asked 2.5 rows below it: its triangle with
    two border nodes inverts, a face no move of the free nodes changes (frozen while the
    cursor holds the node there; no other face is left inverted). At rest that fold still
    starts the pull, from the drag's start (a layout with such a face inverted is no pull's
    base): the node stops just inside, 0 inverted faces by an independent count, and a
    release keeps it."""
    p, fs = jittered_square(800, jitter=0.0)
    h = float(np.unique(p[:, 1])[1])
    g = int(np.argmin(np.hypot(p[:, 0] - 0.5, p[:, 1] - h)))
    live = LiveSession(p, fs, [g], pull_after=0.0)
    asked = p[[g]] + [0.0, -2.5 * h]
    frame = live.frame(asked, budget=None)
    assert frame.status == "tangled" and frame.n_tangled == 0
    assert live.finishing(frame) == "go on"
    frame = _rest(live, frame)
    assert frame.status == "untangled" and not inverted_faces(frame.points, fs).any()
    assert 0.0 < frame.points[g, 1] < h and frame.held_back > 1.4 * h  # cursor: 1.5 h past border
    assert live.finishing(frame) == "keep"


def test_a_cursor_move_ends_the_pull():
    """After a pull frame, a new cursor place runs an ordinary frame with the node there."""
    p, fs = jittered_square(800, jitter=0.0)
    g = int(np.argmin(np.hypot(p[:, 0] - 0.5, p[:, 1] - 0.9)))
    live = LiveSession(p, fs, [g], pull_after=0.0)
    live.frame(p[[g]] + [0.0, 0.2], budget=None)
    assert live.frame(None, budget=None).pull_iterations > 0
    to = p[[g]] + [0.01, 0.0]
    frame = live.frame(to, budget=None)
    assert frame.pull_iterations == 0 and frame.held_back == 0.0
    assert np.array_equal(frame.points[g], to[0])


def test_no_pull_without_escalation_or_with_pull_after_none():
    """``escalate=False`` (EEGT only) and ``pull_after=None`` never pull: the node stays
    where the cursor asks and the fold stays."""
    p, fs = jittered_square(800, jitter=0.0)
    g = int(np.argmin(np.hypot(p[:, 0] - 0.5, p[:, 1] - 0.9)))
    asked = p[[g]] + [0.0, 0.2]
    for live in (LiveSession(p, fs, [g], escalate=False, pull_after=0.0),
                 LiveSession(p, fs, [g], pull_after=None)):
        frame = live.frame(asked, budget=None)
        for _ in range(3):
            frame = live.frame(None, budget=None)
        assert frame.pull_iterations == 0 and frame.status == "tangled"
        assert np.array_equal(frame.points[g], asked[0])


def test_pull_energy_gradient_matches_central_differences():
    """The pull's gradient is the energy's plus 2 w (x_k - c_k): central differences of
    ``evaluate`` agree to 1e-6 (relative) on every coordinate of a small valid mesh."""
    p, fs = jittered_square(60, jitter=0.3, seed=4)
    free = ~boundary_nodes(p.shape[0], fs)
    en = FoldoverEnergy(p, fs.by_arity(), free)
    st = State(p, free)
    k = np.array([0, 3])
    pe = PullEnergy(en, k, np.array([[0.4, 0.6], [0.7, 0.2]]), 3.0)
    layout, fixed = pe.packed(st)
    v = st.pack(st.x, st.y)
    z = np.concatenate([v, fixed])
    pe.evaluate(z, layout, 1e-3)
    g = pe.gradient(layout)[: v.size]
    h = 1e-6
    num = np.empty(v.size)
    for i in range(v.size):
        zp, zm = z.copy(), z.copy()
        zp[i] += h
        zm[i] -= h
        num[i] = (pe.evaluate(zp, layout, 1e-3)[0] - pe.evaluate(zm, layout, 1e-3)[0]) / (2 * h)
    assert np.allclose(g, num, rtol=1e-6, atol=1e-6 * np.abs(num).max())


def test_resumable_lbfgs_split_into_calls_is_one_solve_bit_for_bit():
    """``ResumableLBFGS``: 7 + 7 + 6 iterations in three calls reach the same point, to the
    bit, as one guarded ``lbfgs`` of 20 (the memory and the stall rule carry over), on a
    valid jittered square."""
    p, fs = jittered_square(200, jitter=0.2, seed=3)
    free = ~boundary_nodes(p.shape[0], fs)
    en = FoldoverEnergy(p, fs.by_arity(), free)
    st = State(p, free)
    v0 = st.pack(st.x, st.y)
    one, its = lbfgs(en, st, v0, EPS_MIN, max_it=20, guard=True, rel_tol=0.0)
    assert its == 20
    split = ResumableLBFGS(en, st, v0, EPS_MIN)
    assert [split.run(n, rel_tol=0.0) for n in (7, 7, 6)] == [(7, False)] * 2 + [(6, False)]
    assert np.array_equal(split.v, one)
