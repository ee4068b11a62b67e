"""`core.optimize.sampled.Sampled`: progress numbers measured now and then, never so often
that measuring becomes a noticeable share of a run."""

from __future__ import annotations

import core.optimize.sampled as sampled
from core.optimize.sampled import Sampled


def test_first_update_measures_then_the_last_value_until_the_interval_passed(monkeypatch):
    clock = [100.0]
    monkeypatch.setattr(sampled.time, "perf_counter", lambda: clock[0])
    calls = []

    def measure():
        calls.append(clock[0])
        return len(calls)

    s: Sampled[int] = Sampled()
    assert s.value is None and s.update(measure) == 1
    clock[0] += 0.1
    assert s.update(measure) == 1 and len(calls) == 1
    clock[0] += sampled.SAMPLE_EVERY
    assert s.update(measure) == 2 and len(calls) == 2


def test_a_costly_measurement_waits_in_proportion_to_its_cost(monkeypatch):
    """A measurement that took 1 s is next taken 1 / SAMPLE_SHARE s later, not after
    SAMPLE_EVERY: measuring stays SAMPLE_SHARE of the time at most."""
    clock = [0.0]
    monkeypatch.setattr(sampled.time, "perf_counter", lambda: clock[0])

    def slow():
        clock[0] += 1.0
        return clock[0]

    s: Sampled[float] = Sampled()
    first = s.update(slow)
    clock[0] += 1.0 / sampled.SAMPLE_SHARE - 0.5
    assert s.update(slow) == first
    clock[0] += 0.5
    assert s.update(slow) > first


def test_set_makes_an_outside_measurement_the_latest(monkeypatch):
    clock = [5.0]
    monkeypatch.setattr(sampled.time, "perf_counter", lambda: clock[0])
    s: Sampled[str] = Sampled()
    s.set("end of a solve")
    assert s.update(lambda: "measured") == "end of a solve"
    clock[0] += sampled.SAMPLE_EVERY
    assert s.update(lambda: "measured") == "measured"
