"""How many Live Untangle frames run with the cursor still (core.run.live): the modal tools
run a frame on each timer tick while `RestFrames.busy` says the mesh may still change.

Frames at rest untangle (escalate, pull) for at most UNTANGLE_FRAMES since the cursor last
moved, and smooth for at most SETTLE_FRAMES in a row once nothing is tangled or pulled any
more: a smoothing run counts from the last frame that was tangled or pulling, not from the
cursor's move, so a fold opened (or a pull ended) late at rest still gets its smoothing.
"""

from __future__ import annotations

from dataclasses import dataclass

from .live import LiveFrame

__all__ = ["SETTLE_FRAMES", "UNTANGLE_FRAMES", "RestFrames"]

SETTLE_FRAMES = 30  # smoothing frames in a row with the cursor still while the mesh changes
UNTANGLE_FRAMES = 1200  # untangling or pulling frames since the cursor moved (about 20 s)


@dataclass
class RestFrames:
    """The counts of one drag's frames since the cursor last moved (`still`) and in the
    current run of frames that were neither tangled nor pulling (`smoothing`)."""

    still: int = 0
    smoothing: int = 0

    def after(self, frame: LiveFrame, moved: bool) -> None:
        """Count `frame` (`moved`: it put the grabbed nodes at a new cursor place)."""
        self.still = 0 if moved else self.still + 1
        self.smoothing = 0 if moved or frame.opening else self.smoothing + 1

    def busy(self, frame: LiveFrame | None) -> bool:
        """Whether another frame with the cursor still may change the mesh after `frame`
        (the last one; None: none ran yet)."""
        if frame is None or frame.settled or \
                frame.untangle_iterations + frame.smooth_iterations + frame.pull_iterations == 0:
            return False  # nothing left, or a frame that ran nothing (a selection moved whole)
        if frame.opening:
            return self.still < UNTANGLE_FRAMES
        return self.smoothing < SETTLE_FRAMES
