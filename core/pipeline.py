"""Algorithm 1: untangle until no element is inverted, then smooth; never worse than the input."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .backends import make_engine
from .engine_numpy import NumpyEngine
from .faces import FaceSet, as_faceset
from .global_untangle import stops
from .params import EEGTParams
from .quality import Stats, _check_points, mesh_stats
from .targets import Targets, prepare_targets, target_fallback_note
from .topology import free_nodes

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
    n_frozen: int = 0  # faces with a non-positive corner of fixed nodes only: never changeable
    n_target_fallback: int = 0  # faces whose target shape was unusable: regular polygon used

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
            "frozen_faces": self.n_frozen,
            "target_fallback_faces": self.n_target_fallback,
        }


def untangle_and_smooth(
    points,
    faces,
    fixed=None,
    params: EEGTParams | None = None,
    backend: str = "numpy",
    progress: Progress | None = None,
    targets=None,
) -> EEGTResult:
    """Untangle and smooth a planar polygon mesh (counterclockwise faces = valid).

    `fixed` pins extra nodes; boundary, non-manifold and loose nodes never move. The run
    works in normalised coordinates (centred, scaled by a power of two), so its result does
    not depend on the units: a mesh scaled by 2^k gives the same result scaled by 2^k, bit
    for bit. Nodes that did not move are returned bit-identical.

    `progress(iteration, phase, stats)` is called after every EEGT iteration and, inside the
    global stage (phase "global"), every few L-BFGS iterations (about every 0.3 s of work,
    whatever the mesh size); stats are the current iterate's where the stage knows them, else
    the best so far. Returning a falsy value other than None (False, np.False_, 0) or raising
    Cancelled stops the run and returns the input unchanged.

    `targets`: None (every face is pulled towards the regular polygon: the paper), or an
    (n_corners, 2) array, one 2D target point per face corner in the faces' corner order:
    each face is pulled towards its target's shape (translation, rotation, uniform scale
    free), and every quality of the run (best iterate, before/after, never worse than the
    input) is the mean ratio against the targets. Unusable targets (non-finite, a corner
    not strictly convex) fall back to the regular polygon (`n_target_fallback`). The global
    stage (untangle "global", polish, lift) still optimises regular shapes.
    """
    t0 = time.perf_counter()
    params = params if params is not None else EEGTParams()
    if not isinstance(params, EEGTParams):
        raise ValueError(f"params must be an EEGTParams, got {type(params).__name__}")
    p = _check_points(points)
    fs = as_faceset(faces, p.shape[0])
    tg = prepare_targets(targets, fs)
    free = free_nodes(p.shape[0], fs, fixed)
    if not free.any():
        raise ValueError("every node is fixed (boundary or pinned): nothing to optimize")
    center, scale = _normalisation(p, fs)
    work = (p - center) / scale
    _check_orientation(work, fs)
    # frozen = straight or inverted in the caller's coordinates (where the stats are judged;
    # a straight fixed corner can turn 1e-17 positive once translated), scaled exactly
    frozen = frozen_faces(_as_given(p, fs, center, scale), fs, free)
    run = _Run(work, fs, free, params, backend, progress, frozen, tg)
    try:
        status, message = run.execute()
    except _CancelRun:
        status, message = "cancelled", "cancelled: mesh left unchanged"
    if tg is not None and tg.n_fallback:
        message += f"; {target_fallback_note(tg.n_fallback)}"
    before = _stats_as_given(p, fs, center, scale, tg)
    out, after = p.copy(), before
    if status != "cancelled":
        best = run.best_pts if run.best_pts is not None else run.engine.best_points()
        changed = np.any(best != work, axis=1) & free  # fixed rows stay the input's, always
        out[changed] = best[changed] * scale + center
        after = _stats_as_given(out, fs, center, scale, tg) if changed.any() else before
        if not (after == before or after.better_than(before)):  # judged in the caller's units
            out, after = p.copy(), before
            status = "failed" if before.n_inverted > run.n_frozen else "valid"
            message += "; the result was not better than the input in its own coordinates: "
            message += "input returned"
    return EEGTResult(
        out,
        status,
        before,
        after,
        run.n_untangle,
        run.n_smooth,
        time.perf_counter() - t0,
        run.backend_name,
        message,
        free,
        run.n_global,
        int(frozen.sum()),
        0 if tg is None else tg.n_fallback,
    )


def _normalisation(
    p: np.ndarray, fs: FaceSet, centre_on: np.ndarray | None = None
) -> tuple[np.ndarray, float]:
    """(centre, scale) that map the used nodes into [-1, 1]^2: the bounding-box centre (of
    the `centre_on` nodes if given) and a power of two (so that scaling is exact), computed
    without overflow up to 1e308."""
    used = p[fs.used_nodes(p.shape[0])]
    lo, hi = used.min(axis=0), used.max(axis=0)
    half = float(np.max(0.5 * hi - 0.5 * lo))
    if centre_on is not None:
        lo, hi = p[centre_on].min(axis=0), p[centre_on].max(axis=0)
    center = 0.5 * lo + 0.5 * hi
    if not half > 0.0:
        return center, 1.0
    return center, math.ldexp(1.0, math.frexp(half)[1])


def _as_given(p: np.ndarray, fs: FaceSet, center: np.ndarray, scale: float) -> np.ndarray:
    """The caller's points divided by the power-of-two scale (exact: every sign and mean
    ratio is the caller's bit for bit, and the same for any 2^k multiple of the input); the
    normalised points where the mesh sits more than 1e100 sizes from the origin."""
    q = p / scale
    if float(np.max(np.abs(q[fs.used_nodes(p.shape[0])]))) < 1e100:
        return q
    return (p - center) / scale


def _stats_as_given(
    p: np.ndarray, fs: FaceSet, center: np.ndarray, scale: float, targets: Targets | None = None
) -> Stats:
    """Stats of the points as the caller has them (what `mesh_stats` of the result says)."""
    return mesh_stats(_as_given(p, fs, center, scale), fs, targets)


def _check_orientation(p: np.ndarray, fs: FaceSet) -> None:
    """ValueError for clockwise input (total signed area < 0) or a mesh of zero area: folds
    cannot change the total signed area, so its sign is the faces' intended orientation."""
    total = 0.0
    for g in fs.groups:
        x, y = p[g.nodes, 0], p[g.nodes, 1]
        total += float(np.sum(x * np.roll(y, -1, axis=0) - np.roll(x, -1, axis=0) * y))
    if total < 0.0:
        raise ValueError(
            "faces are clockwise (the mesh's total signed area is negative): reverse every "
            "face's vertex order (in Blender: Mesh > Normals > Flip)"
        )
    if not total > 0.0:
        raise ValueError("mesh has zero total area: cannot tell its orientation")


def frozen_note(n_frozen: int) -> str:
    """The sentence that reports frozen faces (the run's message, Blender's report line)."""
    return (f"{n_frozen} faces have a straight or inverted corner made of fixed vertices "
            "only: they cannot change")


def frozen_faces(p: np.ndarray, faces, free: np.ndarray) -> np.ndarray:
    """(F,) bool: faces with a corner made of fixed nodes only whose det is <= 0 (straight or
    inverted). No move can change such a corner, so these faces count as inverted forever
    and are left out of the untangling goal."""
    fs = as_faceset(faces, p.shape[0])
    out = np.zeros(fs.n_faces, dtype=bool)
    for g in fs.groups:
        nxt, prv = np.roll(g.nodes, -1, axis=0), np.roll(g.nodes, 1, axis=0)
        x, y = p[:, 0], p[:, 1]
        det = (x[nxt] - x[g.nodes]) * (y[prv] - y[g.nodes]) - (y[nxt] - y[g.nodes]) * (
            x[prv] - x[g.nodes]
        )
        stuck = ~(free[g.nodes] | free[nxt] | free[prv]) & (det <= 0.0)
        out[g.ids] = stuck.any(axis=0)
    return out


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

    def __init__(self, p, fs, free, params: EEGTParams, backend: str, progress, frozen,
                 targets: Targets | None = None):
        self.p, self.fs, self.free, self.params = p, fs, free, params
        self.frozen = frozen
        self.n_frozen = int(frozen.sum())  # inverted faces no move can change
        self.backend, self.progress = backend, progress
        self.targets = targets
        self.engine, self.backend_name = make_engine(backend, p, fs, free, params, targets)
        self.before = self.best = self.engine.stats()
        self.best_pts: np.ndarray | None = None  # None: the engine's best buffer holds it
        self.engine.save_best()
        self.n_untangle = self.n_smooth = self.n_global = 0
        self.lbfgs = None  # the global stage's solver (None: the host's), made when it runs

    def report(self, it: int, phase: str, s: Stats) -> None:
        if self.progress is None:
            return
        try:
            stop = stops(self.progress(it, phase, s))
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

    def tangled(self, s: Stats) -> bool:
        """Some face that a move can change is inverted."""
        return s.n_inverted > self.n_frozen

    def execute(self) -> tuple[str, str]:
        prm, before = self.params, self.before
        tangled = self.tangled(before)
        self.report(0, "untangle" if tangled else "smooth", before)
        frozen = f"; {frozen_note(self.n_frozen)}" if self.n_frozen else ""
        current = before
        if tangled:
            if prm.untangle != "global":
                current = self.untangle_eegt()
            if self.tangled(self.best) and prm.untangle != "eegt":
                current = self.global_stage(polish=prm.polish_iterations)
            if self.tangled(self.best):
                return "failed", (
                    f"failed: {self.best.n_inverted - self.n_frozen} inverted faces remain "
                    f"after {self.n_untangle} untangling iterations"
                    + (f" and {self.n_global} global iterations" if self.n_global else "")
                    + f" (best iterate kept; input had {before.n_inverted - self.n_frozen})"
                    + frozen
                )
        if prm.polish_iterations > 0 and self.n_global == 0:  # the global stage polishes too
            current = self.global_stage(polish=prm.polish_iterations)
        self.smooth_eegt(current)
        status = "untangled" if tangled else "valid"
        verb = f"untangled in {self.n_untangle} iterations, " if tangled else ""
        glob = f"{self.n_global} optimization iterations, " if self.n_global else ""
        b = self.best
        return status, (
            f"{verb}{glob}smoothed in {self.n_smooth} iterations: "
            f"q_min {before.q_min:.4f} -> {b.q_min:.4f}, q_avg {before.q_avg:.4f} -> {b.q_avg:.4f}"
            + frozen
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
            if not self.tangled(current):
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
        groups = self._global_groups()
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
                progress=relay if self.progress is not None else None,  # no pauses unasked
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
            self.engine, _ = make_engine(
                self.backend, pts, self.fs, self.free, self.params, self.targets
            )
        current = self.engine.stats()
        if current.better_than(self.best):
            self.best, self.best_pts = current, None
            self.engine.save_best()
        else:  # keep the earlier best as a host copy; the new engine starts from pts
            self.best_pts = start if self.best_pts is None else self.best_pts
        return current

    def _global_groups(self) -> dict[int, np.ndarray]:
        """The global stage's faces: all but frozen faces whose every node is fixed (constant:
        nothing to optimise, and an inverted one would block the lift's validity guard)."""
        groups = {}
        for g in self.fs.groups:
            inert = self.frozen[g.ids] & ~self.free[g.nodes].any(axis=0)
            groups[g.n] = np.ascontiguousarray(g.nodes[:, ~inert].T)
        return groups

    def lift(self, pts: np.ndarray, groups: dict) -> np.ndarray:
        """Raise q_min of the valid optimization result without lowering its q_avg."""
        from .global_untangle import lift_min_quality

        base = self.n_untangle + self.n_global

        def relay(iterations: int, _rounds: int, q_min: float, q_avg: float) -> None:
            self.report(base + iterations, "global", Stats(self.n_frozen, q_min, q_avg))

        out, info = lift_min_quality(
            pts, groups, self.free, rounds=self.params.lift_rounds,
            progress=relay if self.progress is not None else None, lbfgs=self.lbfgs
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
