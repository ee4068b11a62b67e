"""Progress numbers of a solve's current iterate, measured now and then: often enough that
a progress line follows the run, seldom enough that measuring stays a small share of it."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Generic, TypeVar

__all__ = ["SAMPLE_EVERY", "SAMPLE_SHARE", "Sampled"]

SAMPLE_EVERY = 0.5  # seconds between two measurements at least ...
SAMPLE_SHARE = 0.05  # ... and at least 1 / SAMPLE_SHARE times what the last one cost

T = TypeVar("T")


class Sampled(Generic[T]):
    """The latest of a measurement taken at most every SAMPLE_EVERY seconds (longer when it
    is costly); `value` is None until the first one. Only what a progress report shows goes
    through here: a run's result never depends on when it was measured."""

    def __init__(self) -> None:
        self.value: T | None = None
        self._at = 0.0
        self._cost = 0.0

    def update(self, measure: Callable[[], T]) -> T:
        """`measure()` when the last measurement is old enough (or there is none), else the
        last value."""
        now = time.perf_counter()
        if self.value is None or now - self._at >= max(SAMPLE_EVERY, self._cost / SAMPLE_SHARE):
            self.value = measure()
            self._at = time.perf_counter()
            self._cost = self._at - now
        return self.value

    def set(self, value: T) -> None:
        """A measurement made elsewhere (at the end of a solve, say) becomes the latest."""
        self.value = value
        self._at = time.perf_counter()
