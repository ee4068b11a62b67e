"""How many Live Untangle frames run with the cursor still (core.run.live_rest): smoothing
counts from the last frame that was tangled or pulling, not from the cursor's move."""

import numpy as np

from core.run import SETTLE_FRAMES, UNTANGLE_FRAMES, LiveFrame, RestFrames


def _frame(status: str = "untangled", smooth: int = 50, pull: int = 0,
           untangle: int = 0) -> LiveFrame:
    return LiveFrame(np.zeros((1, 2)), None, status, untangle, smooth, 0.01,
                     pull_iterations=pull)


def test_a_pull_longer_than_the_smoothing_cap_still_gets_its_smoothing_frames():
    """A move, then 2 * SETTLE_FRAMES frames of a rest's pull, then smoothing frames: each
    smoothing frame up to SETTLE_FRAMES leaves the drag busy, the one after does not."""
    rest = RestFrames()
    rest.after(_frame("tangled", 0, untangle=50), moved=True)
    for _ in range(2 * SETTLE_FRAMES):
        pulled = _frame(smooth=0, pull=40)
        rest.after(pulled, moved=False)
        assert rest.busy(pulled)
    for k in range(1, SETTLE_FRAMES + 1):
        smoothing = _frame()
        rest.after(smoothing, moved=False)
        assert rest.busy(smoothing) == (k < SETTLE_FRAMES)


def test_a_settled_frame_or_one_that_ran_nothing_ends_the_rest_frames():
    rest = RestFrames()
    rest.after(_frame(), moved=True)
    assert rest.busy(_frame())
    assert not rest.busy(_frame(smooth=1))  # settled: smoothing converged
    assert not rest.busy(_frame(smooth=0))
    assert not rest.busy(_frame("tangled", 0))  # ran nothing (a selection moved whole)
    assert not rest.busy(None)


def test_tangled_frames_stop_untangle_frames_after_the_cursor_stopped():
    """Tangled frames go on until UNTANGLE_FRAMES frames since the move, whatever came in
    between; a move starts the count again."""
    rest = RestFrames()
    rest.after(_frame("tangled", 0, untangle=50), moved=True)
    tangled = _frame("tangled", 0, untangle=50)
    for _ in range(UNTANGLE_FRAMES - 1):
        rest.after(tangled, moved=False)
    assert rest.busy(tangled)
    rest.after(tangled, moved=False)
    assert not rest.busy(tangled)
    rest.after(tangled, moved=True)
    assert rest.busy(tangled)
