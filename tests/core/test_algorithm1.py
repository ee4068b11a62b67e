"""Algorithm 1's EEGT loops (core.run.algorithm1), shared by the whole run and live frames."""

from __future__ import annotations

import inspect
import time

from core import EEGTParams, Stats
from core.run.algorithm1 import Deadline, smooth_loop, smoothing_done, untangle_loop

P = EEGTParams(tol=1e-3, tol_min=1e-3, max_smooth_iterations=10)


def feed(seq: list[Stats]):
    it = iter(seq)
    return lambda: next(it)


def test_untangle_loop_stops_at_the_first_untangled_iterate():
    seq = [Stats(5, 0, 0.1), Stats(2, 0, 0.2), Stats(0, 0.1, 0.3), Stats(0, 0.2, 0.4)]
    last, n = untangle_loop(feed(seq), lambda s: s.n_inverted > 0, 10)
    assert (last, n) == (Stats(0, 0.1, 0.3), 3)


def test_untangle_loop_stop_hook_and_cap():
    seq = [Stats(5, 0, 0.1), Stats(4, 0, 0.2), Stats(3, 0, 0.3)]
    seen = []
    last, n = untangle_loop(feed(seq), lambda s: True, 10,
                            lambda s: seen.append(s) or s.n_inverted == 4)
    assert (last, n) == (Stats(4, 0, 0.2), 2) and len(seen) == 2
    last, n = untangle_loop(feed(seq), lambda s: True, 2)
    assert (last, n) == (Stats(4, 0, 0.2), 2)
    assert untangle_loop(feed([]), lambda s: True, 0) == (None, 0)


def test_smoothing_stop_rule():
    a = Stats(0, 0.5, 0.8)
    assert not smoothing_done(a, Stats(0, 0.5, 0.8 + 2e-3), P)  # mean improves by tol
    assert smoothing_done(a, Stats(0, 0.5, 0.8 + 5e-4), P)
    assert not smoothing_done(a, Stats(0, 0.5 + 1e-3, 0.8), P)  # mean holds, worst improves
    assert smoothing_done(a, Stats(0, 0.5 + 1e-3, 0.8 - 1e-9), P)  # mean drops
    assert smoothing_done(a, Stats(0, 0.5 + 1.0, 0.8), EEGTParams(tol_min=0.0))


def test_smooth_loop_counts_and_stops():
    seq = [Stats(0, 0.5, 0.81), Stats(0, 0.5, 0.82), Stats(0, 0.5, 0.8201), Stats(0, 0.5, 0.9)]
    last, n = smooth_loop(feed(seq), Stats(0, 0.5, 0.8), P)
    assert (last, n) == (Stats(0, 0.5, 0.8201), 3)
    last, n = smooth_loop(feed(seq), Stats(0, 0.5, 0.8), P, lambda s: True)
    assert (last, n) == (Stats(0, 0.5, 0.81), 1)


def test_deadline_uses_the_last_steps_time():
    assert not Deadline(None).late()
    clock = Deadline(time.perf_counter() + 10.0)
    assert not clock.late()
    timed = clock.timed(lambda phase: Stats(0, 0.5, 0.8))
    assert timed("smooth") == Stats(0, 0.5, 0.8) and clock.step >= 0.0
    clock.step = 20.0  # the next step would end past the deadline
    assert clock.late()
    assert Deadline(time.perf_counter() - 1.0).late()


def test_pipeline_and_live_share_the_loops():
    import core.run.live as live
    import core.run.pipeline as pipeline
    for mod in (pipeline, live):
        src = inspect.getsource(mod)
        assert "untangle_loop(" in src and "smooth_loop(" in src, mod.__name__
        assert "prm.tol_min" not in src and "d_avg" not in src, mod.__name__
