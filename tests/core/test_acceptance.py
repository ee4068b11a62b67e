"""The one acceptance rule (core.run.accept) and the paths that decide through it."""

from __future__ import annotations

import inspect
from pathlib import Path

import numpy as np
import pytest
from meshdata import load

import core.run.acceptance as acceptance_module
from core import Stats, untangle_and_smooth_3d
from core.run import FLOAT32_TIE, accept, tie_tolerance
from core.uv import uv_untangle

S = Stats(0, 0.5, 0.8)
ROOT = Path(__file__).resolve().parents[2]


def test_tie_tolerance_is_exact_for_float64_and_1e6_for_float32():
    assert tie_tolerance(np.float64) == 0.0 and tie_tolerance(np.dtype("float64")) == 0.0
    assert tie_tolerance(np.float32) == FLOAT32_TIE == 1e-6
    with pytest.raises(ValueError, match="float64 or float32"):
        tie_tolerance(np.float16)


@pytest.mark.parametrize("stored", [np.float64, np.float32])
def test_inverted_count_decides_first(stored):
    assert accept(Stats(3, 0.0, 0.1), Stats(2, 0.0, 0.01), stored)
    assert not accept(Stats(2, 0.0, 0.01), Stats(3, 0.0, 0.9), stored)


@pytest.mark.parametrize("stored", [np.float64, np.float32])
def test_q_min_decides_before_q_avg(stored):
    assert accept(S, Stats(0, 0.6, 0.1), stored)
    assert not accept(S, Stats(0, 0.4, 0.99), stored)


@pytest.mark.parametrize("stored", [np.float64, np.float32])
def test_q_avg_decides_last(stored):
    assert accept(S, Stats(0, 0.5, 0.81), stored)
    assert not accept(S, Stats(0, 0.5, 0.79), stored)


def test_float64_compares_exactly_and_keeps_a_tie():
    up = np.nextafter(0.5, 1.0)
    assert accept(S, Stats(0, up, 0.0))  # one ulp of q_min beats any q_avg
    assert not accept(S, Stats(0, np.nextafter(0.5, 0.0), 1.0))
    assert accept(S, Stats(0, 0.5, np.nextafter(0.8, 1.0)))
    assert accept(S, Stats(0, 0.5, 0.8))  # a tie: no worse than the input
    assert accept(S, S, np.float64)


def test_float32_ties_within_1e6_keep_the_input():
    assert not accept(S, Stats(0, 0.5, 0.8), np.float32)  # a tie keeps the input
    assert not accept(S, Stats(0, 0.5 + 5e-7, 0.8 + 5e-7), np.float32)  # round-off gain
    # q_min within round-off ties: q_avg decides, also within round-off
    assert accept(S, Stats(0, 0.5 - 5e-7, 0.8 + 2e-6), np.float32)
    assert not accept(S, Stats(0, 0.5 - 5e-7, 0.8 - 2e-6), np.float32)
    assert accept(S, Stats(0, 0.5 + 2e-6, 0.0), np.float32)
    assert not accept(S, Stats(0, 0.5 - 2e-6, 1.0), np.float32)


def test_the_rule_matches_the_pipelines_float64_order():
    """float64: accept == (after == before or after.better_than(before)) on a grid of
    neighbouring values (one ulp apart)."""
    q = [np.nextafter(0.5, 0.0), 0.5, np.nextafter(0.5, 1.0)]
    for n in (0, 1):
        for a in q:
            for b in q:
                after = Stats(n, a, b)
                assert accept(S, after) == (after == S or after.better_than(S))


def test_every_path_decides_through_the_one_rule():
    """The run paths and the operators name the rule; none compares Stats on its own."""
    import core.run.live as live
    import core.run.pipeline as pipeline
    import core.run.pipeline_3d as pipeline_3d
    for mod in (pipeline, pipeline_3d, live, uv_untangle):
        src = inspect.getsource(mod)
        assert "accept(" in src, mod.__name__
        assert "after == before" not in src and "better_than(before)" not in src, mod.__name__
    assert acceptance_module.accept is accept
    runner = (ROOT / "operators/mesh/runner.py").read_text()
    assert "untangle_and_smooth_3d(" in runner and "stored=np.float32" in runner
    assert "def improves" not in runner and "better_than" not in runner
    assert "improves" not in (ROOT / "operators/uv/uv_runner.py").read_text()


def test_uv_default_acceptance_is_the_rule_with_the_storage_ties():
    sig = inspect.signature(uv_untangle.untangle_uv)
    assert sig.parameters["accept"].default is None
    assert sig.parameters["store"].default is np.float32


# -- the 3D entry with float32 storage ---------------------------------------------------------

def tilted() -> tuple[np.ndarray, object]:
    v, fs = load("tilted_plane")
    return v.astype(np.float32).astype(np.float64), fs


def test_3d_float32_storage_returns_float32_judged_as_rounded():
    p, fs = tilted()
    r64 = untangle_and_smooth_3d(p, fs)
    r32 = untangle_and_smooth_3d(p, fs, stored=np.float32)
    assert r32.points.dtype == np.float32 and r32.points.shape == p.shape
    assert r32.points.tobytes() == r64.points.astype(np.float32).tobytes()
    assert r32.status == r64.status == "untangled"
    assert r32.before == r64.before
    assert r32.after != r64.after  # the rounded copy's stats, measured as the input's
    assert accept(r32.before, r32.after, np.float32)
    assert r32.after.n_inverted == 0 and abs(r32.after.q_min - r64.after.q_min) < 1e-6


def test_3d_float32_storage_refuses_a_result_whose_stored_copy_is_worse(monkeypatch):
    """The stored copy judged by the one rule with float32 ties: refused, the input is kept
    (float32 bits), after = before, the status and message say so."""
    import core.run.pipeline_3d as pipeline_3d
    p, fs = tilted()
    calls = []

    def rule(before, after, stored=np.float64):
        calls.append(np.dtype(stored))
        return np.dtype(stored) == np.float64  # the float64 run passes, the stored copy not

    monkeypatch.setattr(pipeline_3d, "accept", rule)
    res = untangle_and_smooth_3d(p, fs, stored=np.float32)
    assert calls == [np.dtype(np.float64), np.dtype(np.float32)]
    assert res.points.dtype == np.float32
    assert res.points.tobytes() == p.astype(np.float32).tobytes()
    assert res.after == res.before and res.before.n_inverted == 23
    assert res.status == "failed" and "once stored as float32" in res.message


def nudged_grid() -> tuple[np.ndarray, object]:
    """A regular 6 x 6 quad grid turned out of the xy plane and moved (float32 values), one
    interior node nudged by ~2e-6: the best iterate gains ~1e-11, float32 round-off."""
    n = 6
    xs, ys = np.meshgrid(np.arange(n + 1) * 0.25, np.arange(n + 1) * 0.25)
    p = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    p[3 * (n + 1) + 3, :2] += [2e-6, -1e-6]
    a = 0.7
    turn = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    p = (p @ turn.T + [3.0, -2.0, 5.0]).astype(np.float32).astype(np.float64)
    faces = np.array([(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1,
                       (j + 1) * (n + 1) + i) for j in range(n) for i in range(n)])
    return p, faces


def test_3d_float32_storage_keeps_an_input_that_gains_only_round_off():
    """float64 keeps a result ~1e-11 better (and its rounded copy still moves 11 nodes);
    stored as float32 the gain is a tie (within 1e-6): the input is kept bit for bit."""
    p, faces = nudged_grid()
    r64 = untangle_and_smooth_3d(p, faces)
    assert r64.status == "valid" and 0.0 < r64.after.q_min - r64.before.q_min < 1e-9
    assert np.any(r64.points.astype(np.float32) != p.astype(np.float32), axis=1).sum() == 11
    r32 = untangle_and_smooth_3d(p, faces, stored=np.float32)
    assert r32.status == "valid" and r32.after == r32.before == r64.before
    assert r32.points.tobytes() == p.astype(np.float32).tobytes()
    assert r32.message.endswith("the result was not better than the input once stored as "
                                "float32: input kept")


def test_3d_rejects_other_storage_types():
    p, fs = tilted()
    with pytest.raises(ValueError, match="float64 or float32"):
        untangle_and_smooth_3d(p, fs, stored=np.int32)
