"""Freed memory kept for reuse while a run works (glibc's allocator; elsewhere nothing changes).

A large run frees and allocates arrays of tens of MB all the time. glibc hands the free
memory at the top of its heap back to the system once it passes the trim threshold (at most
64 MB under its own rules), so the next array maps fresh pages again, and mapping is slow
where the kernel must zero and, on a virtual machine, the host must back every new page. On
a 2-core virtual machine (docs/scale.md) the 1.06M NumPy run spent 2.6-3.0 s of system time
so; with the freed memory kept, 1.0-1.3 s. A run therefore raises the trim threshold and
grows the heap in large steps while it works; when the last run ends it hands the free
memory back (`malloc_trim`) and sets the thresholds to the values glibc's own rule settles
at for arrays of this size. Only addresses change: every result is the same bits (tested).
"""

from __future__ import annotations

import ctypes
from collections.abc import Iterator
from contextlib import contextmanager
from functools import partial

from .run_scoped import RunScoped

__all__ = ["GLIBC", "KEEP_FROM_FACES", "KEPT", "SETTLED", "available", "engaged",
           "keep_freed_memory"]

# Runs from this many faces on keep their freed memory; smaller runs (a live drag's, one UV
# island's) work in arrays of a few MB and leave the allocator alone, so they never pay a
# `malloc_trim` of the host application's heap.
KEEP_FROM_FACES = 100_000

# mallopt parameters (malloc.h)
M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD = -1, -2, -3
MB = 1 << 20
# during a run: arrays up to 32 MB from the heap (glibc's largest mmap threshold), nothing
# handed back, the heap grown 256 MB at a time (pages are mapped only when touched)
KEPT = {M_MMAP_THRESHOLD: 32 * MB, M_TRIM_THRESHOLD: 2**31 - 1, M_TOP_PAD: 256 * MB}
# after: glibc's own values once its dynamic thresholds have grown to 32 MB arrays
SETTLED = {M_MMAP_THRESHOLD: 32 * MB, M_TRIM_THRESHOLD: 64 * MB, M_TOP_PAD: 128 * 1024}


def _glibc():
    """The process's glibc (mallopt, malloc_trim), or None under another C library."""
    try:
        libc = ctypes.CDLL(None)
        libc.gnu_get_libc_version  # noqa: B018 (only glibc has it)
        mallopt, trim = libc.mallopt, libc.malloc_trim
    except (OSError, AttributeError, TypeError):
        return None
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return mallopt, trim


GLIBC = _glibc()  # (mallopt, malloc_trim) of the process, None under another C library


def available() -> bool:
    """Whether this process's allocator can be told (glibc)."""
    return GLIBC is not None


def _set(values: dict[int, int]) -> None:
    mallopt = GLIBC[0]
    for param, value in values.items():
        mallopt(param, value)


def _hand_back(_: None) -> None:
    _set(SETTLED)
    GLIBC[1](0)


_large_runs = RunScoped(partial(_set, KEPT), _hand_back)


def engaged() -> bool:
    """Whether some run keeps its freed memory now."""
    return _large_runs.inside > 0


@contextmanager
def keep_freed_memory(n_faces: int) -> Iterator[None]:
    """For a run of at least KEEP_FROM_FACES faces: freed memory stays in the process inside
    the block, handed back when the last such block ends (also on an exception). Smaller
    runs: nothing changes."""
    if GLIBC is None or n_faces < KEEP_FROM_FACES:
        yield
        return
    with _large_runs.held():
        yield

