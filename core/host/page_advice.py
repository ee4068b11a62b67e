"""The page size the process's NumPy arrays are mapped with.

On Linux NumPy asks the kernel for 2 MB pages ("huge pages") for every array of 4 MB or
more. A large run makes and drops many such arrays (set-up tables, per-corner passes,
device tables), so fresh pages are mapped throughout. Where a fresh 2 MB page is
expensive, those faults cost more than the arithmetic on the arrays: on a virtual machine
that hands its free memory back to the host (free page reporting works in 2 MB blocks), the
host backs every such page again on first touch. On a 2-core virtual machine (docs/scale.md),
the 1.06M Triangle mesh's `auto` run spent 2.9 s of system time with the advice and 1.1-2.0 s
without. Heap memory advised once stays advised, so the choice is made before a
run's own arrays exist: the first run turns the advice off for the process (importing `core`
changes nothing), unless the environment sets EEGT_HUGE_PAGES=1. Only the mapping changes:
every result is the same bits either way (tested).

Large runs are the exception. From HUGE_PAGES_FROM_FACES faces on, a run's arrays are tens
of MB each and their page tables no longer fit the caches, so with ordinary pages every
random gather also walks the page tables: the 4M-triangle `auto` run took 38.5-39.7 s with
ordinary pages and 31.2-32.6 s with the advice on while it worked (the 1.06M mesh: 9.1-9.3 s
ordinary, 9.5-11.3 s advised). Such a run turns the advice on for its duration
(`pages_for_run`) and restores the process's setting after.
"""

from __future__ import annotations

import functools
import importlib
import os
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from .run_scoped import RunScoped

__all__ = ["HUGE_PAGES_ENV", "HUGE_PAGES_FROM_FACES", "huge_page_advice", "pages_for_run",
           "prefer_ordinary_pages", "set_huge_page_advice"]

HUGE_PAGES_ENV = "EEGT_HUGE_PAGES"  # "1": keep NumPy's huge-page advice as it is
HUGE_PAGES_FROM_FACES = 2_000_000  # runs this large work with the advice on


def _find_setter() -> Callable[[bool], bool] | None:
    """NumPy's switch of the huge-page advice (it returns the previous setting); None where
    this NumPy has none."""
    for name in ("numpy._core.multiarray", "numpy.core.multiarray"):
        try:
            module = importlib.import_module(name)
        except ImportError:
            continue
        setter = getattr(module, "_set_madvise_hugepage", None)
        if callable(setter):
            return setter
    return None


_SETTER = _find_setter()
_lock = threading.Lock()
# the advice on while large runs work; the process's setting from before the first back after
_large_runs = RunScoped(lambda: bool(_SETTER(True)), lambda saved: _SETTER(saved), _lock)


def set_huge_page_advice(on: bool) -> bool | None:
    """Set NumPy's huge-page advice; the previous setting (None: this NumPy has no switch)."""
    if _SETTER is None:
        return None
    with _lock:
        return bool(_SETTER(bool(on)))


def huge_page_advice() -> bool | None:
    """Whether NumPy now advises 2 MB pages for large arrays (None: this NumPy cannot say)."""
    if _SETTER is None:
        return None
    with _lock:
        now = bool(_SETTER(False))
        _SETTER(now)
    return now


def prefer_ordinary_pages() -> bool | None:
    """Turn the advice off for the process unless HUGE_PAGES_ENV is "1"; the setting now."""
    if os.environ.get(HUGE_PAGES_ENV, "").strip() == "1":
        return huge_page_advice()
    set_huge_page_advice(False)
    return huge_page_advice()


@functools.cache
def _first_run() -> bool | None:
    """The process's setting, made once, when the first run starts."""
    return prefer_ordinary_pages()


@contextmanager
def pages_for_run(n_faces: int) -> Iterator[None]:
    """The process's setting made on the first run (`prefer_ordinary_pages`); the advice on
    inside the block for a run of at least HUGE_PAGES_FROM_FACES faces (the process's setting
    back when the last such run ends, also on an exception); smaller runs leave it as it is."""
    _first_run()
    if _SETTER is None or n_faces < HUGE_PAGES_FROM_FACES:
        yield
        return
    with _large_runs.held():
        yield
