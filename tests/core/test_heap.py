"""A run keeps its freed memory for reuse and hands it back when it ends (core/host/heap.py,
docs/scale.md); the result is the same bits with the allocator left alone."""

from __future__ import annotations

import os

import numpy as np
import pytest
from meshdata import load2d

from core import EEGTParams, untangle_and_smooth
from core.host import heap

pytestmark = pytest.mark.skipif(not heap.available(), reason="not glibc's allocator")

PAGE = os.sysconf("SC_PAGE_SIZE")


def _resident_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE / 2**20


def _churn(total_mb: int = 96, each_mb: int = 24) -> None:
    """Allocate, touch and free arrays below glibc's mmap threshold (heap arrays)."""
    arrays = [np.ones(each_mb * 2**20 // 8) for _ in range(total_mb // each_mb)]
    del arrays


def test_freed_memory_stays_inside_the_block_and_goes_back_after():
    heap.GLIBC[1](0)
    base = _resident_mb()
    with heap.keep_freed_memory(heap.KEEP_FROM_FACES):
        _churn()
        kept = _resident_mb()
    after = _resident_mb()
    assert kept - base > 80  # the 96 MB freed inside the block stayed resident
    assert after - base < 20  # handed back when the block ended


def test_nested_blocks_hand_back_once_when_the_outer_one_ends():
    heap.GLIBC[1](0)
    base = _resident_mb()
    with heap.keep_freed_memory(heap.KEEP_FROM_FACES):
        with heap.keep_freed_memory(heap.KEEP_FROM_FACES):
            _churn()
        assert _resident_mb() - base > 80  # the inner block's end handed nothing back
    assert _resident_mb() - base < 20


def test_memory_handed_back_when_the_block_raises():
    heap.GLIBC[1](0)
    base = _resident_mb()
    with pytest.raises(RuntimeError), heap.keep_freed_memory(heap.KEEP_FROM_FACES):
        _churn()
        raise RuntimeError("stop")
    assert _resident_mb() - base < 20


def _engaged_during_a_run(p, fs) -> list[bool]:
    seen: list[bool] = []
    untangle_and_smooth(p, fs, progress=lambda it, phase, stats: seen.append(heap.engaged()))
    return seen


def test_small_runs_leave_the_allocator_alone_and_large_ones_keep_memory(monkeypatch):
    p, fs = load2d("tri_two_holes")
    seen = _engaged_during_a_run(p, fs)
    assert len(seen) > 3 and not any(seen)
    monkeypatch.setattr(heap, "KEEP_FROM_FACES", 10)  # the shared mesh counts as large
    seen = _engaged_during_a_run(p, fs)
    assert len(seen) > 3 and all(seen)
    assert not heap.engaged()


def test_run_gives_the_same_bits_with_the_allocator_left_alone(monkeypatch):
    p, fs = load2d("two_holes_twist")
    monkeypatch.setattr(heap, "KEEP_FROM_FACES", 10)
    kept = untangle_and_smooth(p, fs, params=EEGTParams())
    monkeypatch.setattr(heap, "GLIBC", None)  # keep_freed_memory does nothing
    plain = untangle_and_smooth(p, fs, params=EEGTParams())
    assert kept.after.n_inverted == plain.after.n_inverted == 0
    assert kept.points.tobytes() == plain.points.tobytes()
