"""Two independent pieces of a large run's host set-up at once.

NumPy lets go of the interpreter lock inside its sorts, gathers and ufuncs, so a second
thread keeps a second core busy while the device still idles. Worth it for compute-bound
pieces (sorts); two memory-bound ones (gathers, counts) only share the memory bandwidth.
Each piece computes exactly what it computes alone: no result depends on the split.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TypeVar

__all__ = ["SIDE_BY_SIDE_FROM", "side_by_side"]

SIDE_BY_SIDE_FROM = 100_000  # items below which a thread costs more than it saves

A = TypeVar("A")
B = TypeVar("B")


def side_by_side(here: Callable[[], A], there: Callable[[], B], items: int
                 ) -> tuple[A, B]:
    """(here(), there()): `there` in a thread while `here` runs in the caller's, when the
    work has at least SIDE_BY_SIDE_FROM items; else one after the other. Both have ended
    when it returns or raises; an exception of `here` wins over one of `there`."""
    if items < SIDE_BY_SIDE_FROM:
        return here(), there()
    out: list = [None, None]  # there's result, there's exception

    def run() -> None:
        try:
            out[0] = there()
        except BaseException as exc:  # raised in the caller's thread below
            out[1] = exc

    thread = threading.Thread(target=run, name="eegt-side-by-side")
    thread.start()
    try:
        mine = here()
    finally:
        thread.join()
    if out[1] is not None:
        raise out[1]
    return mine, out[0]
