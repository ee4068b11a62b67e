"""The interface every EEGT engine follows (NumPy's and OpenCL's), and how one is built.

The run (core.run.pipeline) builds an engine for one mesh and drives it iteration by
iteration; the twins give the same bits for the same arguments (tests/opencl)."""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np

from ..mesh.faces import FaceSet
from ..metrics.face_quality import Stats
from ..metrics.targets import Targets
from ..params import EEGTParams
from .boundary import BoundaryMotion

__all__ = ["Engine", "EngineInput"]


class EngineInput(NamedTuple):
    """What an engine is built from: the positions, faces and movable nodes of one run, its
    parameters, per-face target shapes (None: regular polygons) and the boundary mode's
    movable nodes, sliding nodes and distance anchors (None: `free` moves, the other used
    nodes are the anchors: the paper)."""

    points: np.ndarray
    faces: FaceSet
    free: np.ndarray
    params: EEGTParams
    targets: Targets | None = None
    motion: BoundaryMotion | None = None


class Engine(Protocol):
    """One run's mesh state, stepped by the pipeline. Built as `Engine(*EngineInput(...))`;
    `name` says which engine ran (the run's report)."""

    name: str
    iteration: int

    def stats(self) -> Stats:
        """Quality stats of the current positions."""
        ...

    def step(self, phase: str) -> Stats:
        """One transform + stitch iteration ('untangle' or 'smooth'); the new stats."""
        ...

    def save_best(self) -> None:
        """Keep the current positions as the best iterate."""
        ...

    def best_points(self) -> np.ndarray:
        """The best iterate kept, (N, 2)."""
        ...

    def points(self) -> np.ndarray:
        """The current positions, (N, 2)."""
        ...

    def restarted(self, points: np.ndarray) -> Engine:
        """A fresh engine for the same run at new positions (same fixed nodes)."""
        ...
