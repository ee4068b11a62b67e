"""Algorithm 1: untangle until no element is inverted, then smooth; never worse than the input."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .backends import make_engine
from .engine_numpy import NumpyEngine
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
    global_iterations: int = 0  # optimization iterations of the global stage (beyond the paper)

    def as_dict(self) -> dict:
        return {
            "status": self.status,
            "before": self.before.as_dict(),
            "after": self.after.as_dict(),
            "untangle_iterations": self.untangle_iterations,
            "smooth_iterations": self.smooth_iterations,
            "global_iterations": self.global_iterations,
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
    is called as progress(iteration, phase, stats) after every iteration (phase "untangle",
    "global" or "smooth"); returning False (or raising Cancelled) stops the run and returns
    the input unchanged.
    """
    t0 = time.perf_counter()
    params = params if params is not None else EEGTParams()
    p = _check_points(points)
    fs = as_faceset(faces, p.shape[0])
    free = free_nodes(p.shape[0], fs, fixed)
    if not free.any():
        raise ValueError("every node is fixed (boundary or pinned): nothing to optimize")
    run = _Run(p, fs, free, params, backend, progress)
    try:
        status, message = run.execute()
    except _CancelRun:
        status, message = "cancelled", "cancelled: mesh left unchanged"
    out, after = (p.copy(), run.before) if status == "cancelled" else (run.best_pts, run.best)
    if out is None:
        out = run.engine.best_points()
    return EEGTResult(
        out,
        status,
        run.before,
        after,
        run.n_untangle,
        run.n_smooth,
        time.perf_counter() - t0,
        run.backend_name,
        message,
        free,
        run.n_global,
    )


class _CancelRun(Exception):
    pass


def _device_lbfgs(backend_name: str):
    """The global stage's L-BFGS on the OpenCL device when the run uses OpenCL and the device
    is a CPU (`device_solver` gives none elsewhere); None = the host's NumPy solver."""
    if not backend_name.startswith("opencl"):
        return None
    from .lbfgs_opencl import device_solver

    try:
        solver = device_solver()
    except RuntimeError as exc:  # kernel build failed: the host solver gives the same result
        import warnings

        warnings.warn(f"{exc}; global stage on NumPy", RuntimeWarning, stacklevel=4)
        return None
    return solver


class _Run:
    """One run of the pipeline: EEGT phases on an engine, the global stage on the host."""

    def __init__(self, p, fs, free, params: EEGTParams, backend: str, progress):
        self.p, self.fs, self.free, self.params = p, fs, free, params
        self.backend, self.progress = backend, progress
        self.engine, self.backend_name = make_engine(backend, p, fs, free, params)
        self.before = self.best = self.engine.stats()
        self.best_pts: np.ndarray | None = None  # None: the engine's best buffer holds it
        self.engine.save_best()
        self.n_untangle = self.n_smooth = self.n_global = 0
        self.lbfgs = None  # the global stage's solver (None: the host's), made when it runs

    def report(self, it: int, phase: str, s: Stats) -> None:
        if self.progress is None:
            return
        try:
            stop = self.progress(it, phase, s) is False
        except Cancelled:
            stop = True
        if stop:
            raise _CancelRun

    def track(self, s: Stats) -> None:
        if s.better_than(self.best):
            self.best = s
            self.best_pts = None
            self.engine.save_best()

    def best_points(self) -> np.ndarray:
        return self.engine.best_points() if self.best_pts is None else self.best_pts

    def execute(self) -> tuple[str, str]:
        prm, before = self.params, self.before
        self.report(0, "untangle" if before.n_inverted else "smooth", before)
        current = before
        if before.n_inverted:
            if prm.untangle != "global":
                current = self.untangle_eegt()
            if self.best.n_inverted and prm.untangle != "eegt":
                current = self.global_stage(polish=prm.polish_iterations)
            if self.best.n_inverted:
                return "failed", (
                    f"failed: {self.best.n_inverted} inverted faces remain after "
                    f"{self.n_untangle} untangling iterations"
                    + (f" and {self.n_global} global iterations" if self.n_global else "")
                    + f" (best iterate kept; input had {before.n_inverted})"
                )
        if prm.polish_iterations > 0 and self.n_global == 0:  # the global stage polishes too
            current = self.global_stage(polish=prm.polish_iterations)
        self.smooth_eegt(current)
        status = "untangled" if before.n_inverted else "valid"
        verb = f"untangled in {self.n_untangle} iterations, " if before.n_inverted else ""
        glob = f"{self.n_global} optimization iterations, " if self.n_global else ""
        b = self.best
        return status, (
            f"{verb}{glob}smoothed in {self.n_smooth} iterations: "
            f"q_min {before.q_min:.4f} -> {b.q_min:.4f}, q_avg {before.q_avg:.4f} -> {b.q_avg:.4f}"
        )

    def untangle_eegt(self) -> Stats:
        """EEGT until no face is inverted, the iteration cap, or (eegt+global) a stall."""
        prm = self.params
        current = self.before
        low, since = current.n_inverted, 0
        for _ in range(prm.max_untangle_iterations):
            current = self.engine.step("untangle")
            self.n_untangle += 1
            self.track(current)
            self.report(self.n_untangle, "untangle", current)
            if current.n_inverted == 0:
                break
            if current.n_inverted < low:
                low, since = current.n_inverted, 0
            else:
                since += 1
                if prm.untangle == "eegt+global" and since >= prm.stall_iterations:
                    break
        return current

    def global_stage(self, polish: int) -> Stats:
        """Foldover-free optimization from the best iterate; EEGT continues from its result."""
        from .global_untangle import untangle_global

        start = self.best_points()
        groups = self.fs.by_arity()
        base = self.n_untangle

        def relay(iterations: int, _max_iter: int, n_inv: int) -> None:
            self.n_global = iterations
            self.report(base + iterations, "global", Stats(n_inv, self.best.q_min, self.best.q_avg))

        self.lbfgs = _device_lbfgs(self.backend_name)  # built here: not for runs without one
        try:
            pts, info = untangle_global(
                start,
                groups,
                self.free,
                max_iter=self.params.max_untangle_iterations + polish,
                polish_iter=polish,
                progress=relay,
                lbfgs=self.lbfgs,
            )
            self.n_global = int(info["iterations"])
            if info.get("status") == "cancelled":
                raise _CancelRun
            if info.get("status") == "untangled" and self.params.lift_rounds > 0:
                pts = self.lift(pts, groups)
        finally:
            if self.lbfgs is not None:  # the device solver outlives the run: not its tables
                self.lbfgs.release()
        pts[~self.free] = self.p[~self.free]  # fixed rows bit-identical, whatever happened
        if isinstance(self.engine, NumpyEngine):  # same mesh, same fixed nodes: reuse set-up
            self.engine = self.engine.restarted(pts)
        else:
            self.engine, _ = make_engine(self.backend, pts, self.fs, self.free, self.params)
        current = self.engine.stats()
        if current.better_than(self.best):
            self.best, self.best_pts = current, None
            self.engine.save_best()
        else:  # keep the earlier best as a host copy; the new engine starts from pts
            self.best_pts = start if self.best_pts is None else self.best_pts
        return current

    def lift(self, pts: np.ndarray, groups: dict) -> np.ndarray:
        """Raise q_min of the valid optimization result without lowering its q_avg."""
        from .global_untangle import lift_min_quality

        base = self.n_untangle + self.n_global

        def relay(iterations: int, _rounds: int) -> None:
            self.report(base + iterations, "global", self.best)

        out, info = lift_min_quality(
            pts, groups, self.free, rounds=self.params.lift_rounds, progress=relay, lbfgs=self.lbfgs
        )
        self.n_global += int(info["iterations"])
        return out

    def smooth_eegt(self, current: Stats) -> None:
        prm = self.params
        for _ in range(prm.max_smooth_iterations):
            previous = current
            current = self.engine.step("smooth")
            self.n_smooth += 1
            self.track(current)
            self.report(self.n_untangle + self.n_global + self.n_smooth, "smooth", current)
            if current.q_avg - previous.q_avg < prm.tol:
                break
