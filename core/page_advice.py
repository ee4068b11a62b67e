"""The page size the process's NumPy arrays are mapped with.

On Linux NumPy asks the kernel for 2 MB pages ("huge pages") for every array of 4 MB or
more. A large run makes and drops many such arrays (set-up tables, per-corner passes,
device tables), so fresh pages are mapped throughout. Where a fresh 2 MB page is
expensive, those faults cost more than the arithmetic on the arrays: on a virtual machine
that hands its free memory back to the host (free page reporting works in 2 MB blocks), the
host backs every such page again on first touch. On the 2-core development VM, the 1.06M
Triangle mesh's `auto` run spent 2.9 s of system time with the advice and 1.1 s without
(docs/scale.md). Heap memory advised once stays advised, so the choice must be made before
the mesh's arrays exist: importing `core` turns the advice off for the process, unless the
environment sets EEGT_HUGE_PAGES=1. Only the mapping changes: every result is the same bits
either way (tested).
"""

from __future__ import annotations

import importlib
import os
import threading
from collections.abc import Callable

__all__ = ["HUGE_PAGES_ENV", "huge_page_advice", "prefer_ordinary_pages", "set_huge_page_advice"]

HUGE_PAGES_ENV = "EEGT_HUGE_PAGES"  # "1": keep NumPy's huge-page advice as it is


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
