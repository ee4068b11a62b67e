"""core.host.side_by_side: two pieces of host set-up at once for large work, one after the
other for small, with both ended and exceptions raised in the caller's thread."""

import threading

import pytest

import core.host.side_by_side as sbs
from core.host.side_by_side import SIDE_BY_SIDE_FROM, side_by_side


def test_small_work_runs_both_pieces_in_the_callers_thread_in_order():
    seen = []
    out = side_by_side(lambda: seen.append(("here", threading.current_thread().name)) or 1,
                       lambda: seen.append(("there", threading.current_thread().name)) or 2,
                       SIDE_BY_SIDE_FROM - 1)
    me = threading.current_thread().name
    assert out == (1, 2) and seen == [("here", me), ("there", me)]


def test_large_work_runs_there_in_a_thread_while_here_runs():
    """`here` waits for `there` to have started: one after the other, this would time out."""
    started = threading.Event()
    names = {}

    def here():
        names["here"] = threading.current_thread().name
        return started.wait(timeout=10)

    def there():
        names["there"] = threading.current_thread().name
        started.set()
        return "done"

    assert side_by_side(here, there, SIDE_BY_SIDE_FROM) == (True, "done")
    assert names == {"here": threading.current_thread().name, "there": "eegt-side-by-side"}


def test_an_exception_of_there_is_raised_here_after_here_has_ended():
    ended = []

    def here():
        ended.append("here")
        return 1

    def there():
        raise ValueError("bad mesh")

    with pytest.raises(ValueError, match="bad mesh"):
        side_by_side(here, there, SIDE_BY_SIDE_FROM)
    assert ended == ["here"]


def test_an_exception_of_here_wins_and_there_has_ended_before_it_is_raised(monkeypatch):
    monkeypatch.setattr(sbs, "SIDE_BY_SIDE_FROM", 0)
    release, ended = threading.Event(), []

    def here():
        release.set()
        raise KeyError("here")

    def there():
        release.wait(timeout=10)
        ended.append("there")
        raise ValueError("there")

    with pytest.raises(KeyError):
        side_by_side(here, there, 1)
    assert ended == ["there"]
