"""A process-wide setting that large runs switch while they work.

Runs may nest (the 3D pipeline calls the 2D one) and may run in threads at once (a batch
in one process), and the setting belongs to the whole process: the first run to enter
switches it, the last one to leave puts it back, also when a run raises. core/host/page_advice.py
(NumPy's huge-page advice) and core/host/heap.py (the allocator's trim thresholds) share this.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Generic, TypeVar

__all__ = ["RunScoped"]

T = TypeVar("T")


class RunScoped(Generic[T]):
    """`enter()` when the first run enters `held()`, `leave(token)` with what that `enter`
    returned (the setting to put back) when the last one leaves; both under `lock` (a caller
    that also reads or flips the setting passes its own)."""

    def __init__(self, enter: Callable[[], T], leave: Callable[[T], None],
                 lock: threading.Lock | None = None):
        self._enter, self._leave = enter, leave
        self._lock = lock if lock is not None else threading.Lock()
        self._inside = 0
        self._token: T | None = None

    @property
    def inside(self) -> int:
        """How many runs are inside now."""
        with self._lock:
            return self._inside

    @contextmanager
    def held(self) -> Iterator[None]:
        with self._lock:
            if self._inside == 0:
                self._token = self._enter()
            self._inside += 1
        try:
            yield
        finally:
            with self._lock:
                self._inside -= 1
                if self._inside == 0:
                    self._leave(self._token)  # type: ignore[arg-type]
                    self._token = None
