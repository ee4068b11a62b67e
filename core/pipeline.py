"""Algorithm 1: untangle until no element is inverted, then smooth; never worse than the input."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .backends import make_engine
from .faces import as_faceset
from .params import EEGTParams
from .quality import Stats, _check_points
from .topology import EdgeInfo

__all__ = ["Cancelled", "EEGTResult", "free_nodes", "untangle_and_smooth"]

Progress = Callable[[int, str, Stats], object]


class Cancelled(Exception):
    """Raised by a progress callback to stop a run; the input is returned unchanged."""


@dataclass
class EEGTResult:
    points: np.ndarray
    status: str  # "valid" | "untangled" | "failed" | "cancelled"
    before: Stats
    after: Stats
    untangle_iterations: int
    smooth_iterations: int
    seconds: float
    backend: str
    message: str
    moved: np.ndarray  # (N,) bool: nodes the run was allowed to move

    def as_dict(self) -> dict:
        return {
            "status": self.status,
            "before": self.before.as_dict(),
            "after": self.after.as_dict(),
            "untangle_iterations": self.untangle_iterations,
            "smooth_iterations": self.smooth_iterations,
            "seconds": self.seconds,
            "backend": self.backend,
            "message": self.message,
        }


def free_nodes(n_nodes: int, faces, fixed=None) -> np.ndarray:
    """(N,) bool: nodes the method may move (not boundary, non-manifold, pinned or loose)."""
    fs = as_faceset(faces, n_nodes)
    edges = EdgeInfo(fs, n_nodes)
    if edges.conflict.any():
        k = int(np.flatnonzero(edges.conflict)[0])
        raise ValueError(
            f"faces are not consistently oriented: edge ({int(edges.lo[k])}, {int(edges.hi[k])}) "
            f"is used twice in the same direction ({int(edges.conflict.sum())} such edges; "
            "recalculate normals)"
        )
    free = fs.used_nodes(n_nodes) & ~edges.boundary_mask()
    if fixed is not None:
        pinned = np.asarray(fixed)
        if pinned.shape != (n_nodes,):
            raise ValueError(f"fixed must be an ({n_nodes},) bool array, got shape {pinned.shape}")
        free &= ~pinned.astype(bool)
    return free


def untangle_and_smooth(
    points,
    faces,
    fixed=None,
    params: EEGTParams | None = None,
    backend: str = "numpy",
    progress: Progress | None = None,
) -> EEGTResult:
    """Untangle and smooth a planar polygon mesh (counterclockwise faces = valid).

    `fixed` pins extra nodes; boundary, non-manifold and loose nodes never move. `progress`
    is called as progress(iteration, phase, stats) after every iteration; returning False
    (or raising Cancelled) stops the run and returns the input unchanged.
    """
    t0 = time.perf_counter()
    params = params if params is not None else EEGTParams()
    p = _check_points(points)
    fs = as_faceset(faces, p.shape[0])
    free = free_nodes(p.shape[0], fs, fixed)
    if not free.any():
        raise ValueError("every node is fixed (boundary or pinned): nothing to optimize")
    engine, backend_name = make_engine(backend, p, fs, free, params)
    before = engine.stats()
    best = before
    engine.save_best()
    n_untangle = n_smooth = 0

    def cancelled(it: int, phase: str, s: Stats) -> bool:
        if progress is None:
            return False
        try:
            return progress(it, phase, s) is False
        except Cancelled:
            return True

    def done(status: str, message: str, out: np.ndarray, after: Stats) -> EEGTResult:
        return EEGTResult(
            out,
            status,
            before,
            after,
            n_untangle,
            n_smooth,
            time.perf_counter() - t0,
            backend_name,
            message,
            free,
        )

    def cancel() -> EEGTResult:
        return done("cancelled", "cancelled: mesh left unchanged", p.copy(), before)

    if cancelled(0, "untangle" if before.n_inverted else "smooth", before):
        return cancel()
    current = before
    if before.n_inverted:
        for _ in range(params.max_untangle_iterations):
            current = engine.step("untangle")
            n_untangle += 1
            if current.better_than(best):
                best = current
                engine.save_best()
            if cancelled(n_untangle, "untangle", current):
                return cancel()
            if current.n_inverted == 0:
                break
        if best.n_inverted:
            return done(
                "failed",
                f"failed: {best.n_inverted} inverted faces remain after {n_untangle} "
                f"untangling iterations (best iterate kept; input had {before.n_inverted})",
                engine.best_points(),
                best,
            )
    for _ in range(params.max_smooth_iterations):
        previous = current
        current = engine.step("smooth")
        n_smooth += 1
        if current.better_than(best):
            best = current
            engine.save_best()
        if cancelled(n_untangle + n_smooth, "smooth", current):
            return cancel()
        if current.q_avg - previous.q_avg < params.tol:
            break
    status = "untangled" if before.n_inverted else "valid"
    verb = f"untangled in {n_untangle} iterations, " if before.n_inverted else ""
    return done(
        status,
        f"{verb}smoothed in {n_smooth} iterations: q_min {before.q_min:.4f} -> {best.q_min:.4f}, "
        f"q_avg {before.q_avg:.4f} -> {best.q_avg:.4f}",
        engine.best_points(),
        best,
    )
