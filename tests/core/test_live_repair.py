"""The live drag's escalation (core/run/live_repair.py) and the resumable foldover-free
solve it runs (core.optimize.untangle_global's ``resume``)."""

from __future__ import annotations

import numpy as np
from oracles import inverted_faces

from bench.meshgen import jittered_square
from core import boundary_nodes
from core.optimize import GlobalOptions, Resume, untangle_global
from core.run.live import LiveSession
from core.run.live_repair import carried


def _folded(n: int = 800):
    """A regular triangulated square whose centre node is pulled three cells away (its fan
    folds): (points, faces, free, the node)."""
    p, fs = jittered_square(n, jitter=0.0)
    free = ~boundary_nodes(p.shape[0], fs)
    g = int(np.argmin(np.hypot(p[:, 0] - 0.5, p[:, 1] - 0.5)))
    q = p.copy()
    q[g] += [0.15, 0.1]
    free[g] = False
    return q, fs, free, g


def test_resume_none_is_the_cold_run_bit_for_bit():
    """``resume=None`` (the default) gives the same bits and info as before it existed."""
    q, fs, free, _ = _folded()
    a, ia = untangle_global(q, fs.by_arity(), free, GlobalOptions(lift_rounds=0))
    b, ib = untangle_global(q, fs.by_arity(), free, GlobalOptions(lift_rounds=0), resume=None)
    assert a.tobytes() == b.tobytes()
    assert ia["iterations"] == ib["iterations"] and ia["eps_history"] == ib["eps_history"]
    assert "resume" not in ib


def _calls(q, fs, free, resume: Resume | None, n: int = 300):
    """Calls of 10 iterations each from ``q`` until the fold opens (at most ``n``):
    (points, info of the last, calls, each call's first eps)."""
    opts = GlobalOptions(max_iter=10, polish_iter=0, long_polish=False, lift_rounds=0)
    pts, starts = q.copy(), []
    for _ in range(n):
        pts, info = untangle_global(pts, fs.by_arity(), free, opts, resume=resume)
        starts.append(info["eps_history"][0] if info["eps_history"] else None)
        if info["n_inverted_out"] == 0:
            break
    return pts, info, len(starts), starts


def test_resumed_calls_open_a_fold_that_fresh_calls_do_not():
    """Split into calls of 10 iterations (a frame's share), a resumed solve keeps its eps
    and open round from call to call (an eps is lowered only after a whole round, as in one
    long call) and opens the fold; fresh calls start their continuation over each time and
    never get there. Fixed nodes keep their bits; a call after the valid end starts cold."""
    q, fs, free, g = _folded()
    _, first = untangle_global(q, fs.by_arity(), free, GlobalOptions(lift_rounds=0))
    assert first["status"] == "untangled"
    fresh = _calls(q, fs, free, None)
    assert fresh[1]["n_inverted_out"] > 0  # 300 fresh calls: still folded
    assert set(fresh[3]) == {first["eps_history"][0]}  # each one starts over
    r = Resume()
    pts, info, calls, starts = _calls(q, fs, free, r)
    assert info["n_inverted_out"] == 0 and 1 < calls < 300
    assert starts[0] == first["eps_history"][0]
    assert len(set(starts)) > 1  # the continuation went on across calls
    assert r.calls == calls and r.eps is None and r.used == 0
    assert np.array_equal(pts[~free], q[~free])
    assert pts[g].tobytes() == q[g].tobytes()


def test_carried_start_keeps_a_drag_with_room_valid():
    """A regular mesh's centre node moved by three cells with its neighbourhood carried
    along (``carried``): no face inverted (the node moved alone folds its fan), the node at
    its target, every node that stays bit-identical."""
    p, fs = jittered_square(2000, jitter=0.0)
    free = ~boundary_nodes(p.shape[0], fs)
    g = np.array([int(np.argmin(np.hypot(p[:, 0] - 0.5, p[:, 1] - 0.5)))])
    free[g] = False
    target = p[g] + [0.1, -0.07]
    alone = p.copy()
    alone[g] = target
    assert inverted_faces(alone, fs).any()
    out = carried(p, g, target, free)
    assert out is not None
    assert not inverted_faces(out, fs).any()
    assert np.array_equal(out[g], target)
    assert np.array_equal(out[~free & ~np.isin(np.arange(p.shape[0]), g)],
                          p[~free & ~np.isin(np.arange(p.shape[0]), g)])
    assert carried(p, g, p[g], free) is None  # no move: nothing to carry


def _thin_strip(columns: int = 21, rows: int = 400):
    """Rectangles 0.0151 x 0.001 (aspect 15), as Blender's Unwrap lays out a subdivided
    cylinder's side: (points, quads as (F, 4) node ids, free nodes: the border fixed)."""
    i, j = np.meshgrid(np.arange(columns + 1), np.arange(rows + 1), indexing="ij")
    p = np.stack([i * 0.0151, j * 0.001], axis=-1).reshape(-1, 2).astype(np.float64)
    a, b = np.meshgrid(np.arange(columns), np.arange(rows), indexing="ij")
    n0 = (a * (rows + 1) + b).ravel()
    quads = np.stack([n0, n0 + rows + 1, n0 + rows + 2, n0 + 1], axis=1)
    free = ~((i == 0) | (i == columns) | (j == 0) | (j == rows)).ravel()
    return p, quads, free


def test_carried_start_keeps_thin_cells_valid():
    """A node of a strip of thin cells (aspect 15) moved 3 and 5 cell widths up the strip
    and aside, its neighbourhood carried along: no face inverted. A fall with a ridge
    through the node (linear in each direction) flipped 5 and 12 of these cells: the
    linear phi across a thin cell that straddles the ridge is much steeper than phi."""
    p, quads, free = _thin_strip()
    g = np.array([16 * 401 + 200])  # five columns from the border
    free[g] = False
    for length in (0.045, 0.08):
        target = p[g] + length * np.array([-0.48, 0.877])
        out = carried(p, g, target, free)
        assert out is not None
        assert not inverted_faces(out, quads).any()
        assert np.array_equal(out[g], target)


def test_release_goes_on_while_a_fold_is_left_then_keeps():
    """``finishing``: a tangled frame with the escalation on goes on (frames until the fold
    opens), a valid one is kept; EEGT alone (no escalation) with more folds than at the
    start puts every value back."""
    p, fs = jittered_square(2000, jitter=0.0)
    g = [int(np.argmin(np.hypot(p[:, 0] - 0.5, p[:, 1] - 0.5)))]
    jump = p[g] + [0.3, 0.2]
    eegt = LiveSession(p, fs, g, escalate=False)
    frame = eegt.frame(jump, budget=None, iterations=1)
    assert frame.status == "tangled"
    assert eegt.finishing(frame) == "restore"
    live = LiveSession(p, fs, g)
    frame = live.frame(jump, budget=0.0, iterations=1)
    if frame.status == "tangled":
        assert live.finishing(frame) == "go on"
    for _ in range(50):
        if live.finishing(frame) != "go on":
            break
        frame = live.frame(None, budget=0.1)
    assert live.finishing(frame) == "keep"
    assert frame.stats.n_inverted == 0


def test_a_release_that_cannot_open_the_fold_with_the_node_held_lets_it_go():
    """The grabbed node dragged out of the square (its faces can never all turn left with it
    there): the escalation holds the fold and a release would put every value back; the
    one-shot repair with the node let go (``released``) keeps the drag valid instead:
    0 inverted faces by an independent count, the border and the nodes outside the repair's
    margin bit-identical, the node moved back inside."""
    p, fs = jittered_square(2000, jitter=0.0)
    border = boundary_nodes(p.shape[0], fs)
    g = int(np.argmin(np.hypot(p[:, 0] - 0.5, p[:, 1] - 0.9)))
    live = LiveSession(p, fs, [g], pull_after=None)
    out = p[[g]] + [0.0, 0.2]  # above the top edge
    frame = live.frame(out, budget=None)
    for _ in range(100):
        if live.finishing(frame) != "go on":
            break
        frame = live.frame(None, budget=None)
    assert live.finishing(frame) == "restore" and frame.stats.n_inverted > 0
    kept = live.released(frame.points)
    assert kept is not None
    assert not inverted_faces(kept, fs).any()
    assert np.array_equal(kept[border], p[border])
    assert kept[g, 1] < 1.0  # back inside the square
    far = np.hypot(p[:, 0] - p[g, 0], p[:, 1] - p[g, 1]) > 0.5
    assert np.array_equal(kept[far], frame.points[far])  # the repair's margin only
