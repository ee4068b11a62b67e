"""core.host.run_scoped.RunScoped: the first run in switches the process's setting, the last one
out puts it back: nested, raising and concurrent runs included."""

import threading

import pytest

from core.host.run_scoped import RunScoped


def _recorder():
    calls = []
    return calls, RunScoped(lambda: calls.append("enter"), lambda _: calls.append("leave"))


def test_nested_runs_switch_once_and_restore_when_the_outer_one_leaves():
    calls, scoped = _recorder()
    with scoped.held():
        with scoped.held():
            assert calls == ["enter"] and scoped.inside == 2
        assert calls == ["enter"] and scoped.inside == 1
    assert calls == ["enter", "leave"] and scoped.inside == 0
    with scoped.held():
        pass
    assert calls == ["enter", "leave", "enter", "leave"]


def test_leave_gets_back_what_the_first_enter_returned():
    """The setting from before the first run (enter's token) is what the last one restores,
    once per outermost run."""
    given, restored = iter([True, False]), []
    scoped = RunScoped(lambda: next(given), restored.append)
    with scoped.held():
        with scoped.held():
            pass
    assert restored == [True]
    with scoped.held():
        pass
    assert restored == [True, False]


def test_a_run_that_raises_still_restores():
    calls, scoped = _recorder()
    with pytest.raises(RuntimeError), scoped.held():
        raise RuntimeError("run failed")
    assert calls == ["enter", "leave"] and scoped.inside == 0


def test_runs_in_two_threads_share_one_switch():
    """Both runs are inside at once (a barrier holds them): one enter, one leave, after the
    second has left."""
    calls, scoped = _recorder()
    both_in, first_out = threading.Barrier(2, timeout=10), threading.Event()
    seen = []

    def run(name: str, wait: bool) -> None:
        with scoped.held():
            both_in.wait()
            if wait:
                first_out.wait(timeout=10)
            seen.append((name, list(calls)))
        if not wait:
            first_out.set()

    threads = [threading.Thread(target=run, args=("a", False)),
               threading.Thread(target=run, args=("b", True))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert seen == [("a", ["enter"]), ("b", ["enter"])]
    assert calls == ["enter", "leave"] and scoped.inside == 0
