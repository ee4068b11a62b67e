"""The first run maps the process's large NumPy arrays with ordinary pages (importing core
changes nothing; core/host/page_advice.py, docs/scale.md) unless EEGT_HUGE_PAGES=1, a run of
HUGE_PAGES_FROM_FACES faces or more advises huge pages while it works, and a run gives the
same bits with either mapping."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from core.host import page_advice
from core.host.page_advice import HUGE_PAGES_ENV, huge_page_advice, set_huge_page_advice

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.skipif(huge_page_advice() is None,
                                reason="this NumPy has no huge-page switch")

# a fresh process: NumPy's advice before and after importing core, then a run's digest
CHILD = r"""
import hashlib, json, sys
sys.path[:0] = [sys.argv[1], sys.argv[1] + "/tests"]
import numpy
try:
    from numpy._core.multiarray import _set_madvise_hugepage as switch
except ImportError:
    from numpy.core.multiarray import _set_madvise_hugepage as switch
switch(True)
import core
from core.host.page_advice import huge_page_advice
after = huge_page_advice()
from meshdata import load2d
p, fs = load2d("two_holes_twist")
r = core.untangle_and_smooth(p, fs)
print(json.dumps({"after_import": after, "after_run": huge_page_advice(),
                  "inverted": r.after.n_inverted,
                  "digest": hashlib.sha256(r.points.tobytes()).hexdigest()}))
"""


def _child(env_extra: dict[str, str]) -> dict:
    env = {k: v for k, v in os.environ.items() if k != HUGE_PAGES_ENV}
    env.update(env_extra)
    done = subprocess.run([sys.executable, "-c", CHILD, str(ROOT)], env=env,
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_first_run_turns_huge_pages_off_import_does_not_and_the_environment_keeps_them():
    plain = _child({})
    kept = _child({HUGE_PAGES_ENV: "1"})
    assert plain["after_import"] is True
    assert plain["after_run"] is False
    assert kept["after_import"] is True
    assert kept["after_run"] is True
    assert plain["inverted"] == kept["inverted"] == 0
    assert plain["digest"] == kept["digest"]  # the mapping never changes a value


def test_this_process_runs_with_ordinary_pages():
    # a run in this process, without the variable, leaves the advice off
    _advice_seen_by_a_run()
    if os.environ.get(HUGE_PAGES_ENV, "").strip() != "1":
        assert huge_page_advice() is False


def _advice_seen_by_a_run() -> list[bool | None]:
    from meshdata import load2d

    from core import untangle_and_smooth

    p, fs = load2d("tri_two_holes")
    seen: list[bool | None] = []
    untangle_and_smooth(p, fs, progress=lambda it, phase, stats: seen.append(huge_page_advice()))
    return seen


def test_a_run_below_the_size_keeps_ordinary_pages():
    set_huge_page_advice(False)
    seen = _advice_seen_by_a_run()
    assert len(seen) > 3 and not any(seen)
    assert huge_page_advice() is False


def test_a_large_run_advises_huge_pages_while_it_works_and_restores_after(monkeypatch):
    set_huge_page_advice(False)
    monkeypatch.setattr(page_advice, "HUGE_PAGES_FROM_FACES", 10)  # the shared mesh is large
    seen = _advice_seen_by_a_run()
    assert len(seen) > 3 and all(seen)
    assert huge_page_advice() is False


def test_nested_large_runs_restore_once_when_the_outer_one_ends():
    set_huge_page_advice(False)
    n = page_advice.HUGE_PAGES_FROM_FACES
    with page_advice.pages_for_run(n):
        with page_advice.pages_for_run(n):
            assert huge_page_advice() is True
        assert huge_page_advice() is True
    assert huge_page_advice() is False
    with pytest.raises(RuntimeError), page_advice.pages_for_run(n):
        raise RuntimeError("stop")
    assert huge_page_advice() is False
