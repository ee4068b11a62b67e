"""Algorithm 1: untangle until no element is inverted, then smooth; never worse than the input."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..eegt.backends import make_engine, start_warm_up
from ..eegt.boundary import BoundaryMotion, SlideView, boundary_motion
from ..fpmath import add_reduce
from ..host.heap import keep_freed_memory
from ..host.page_advice import pages_for_run
from ..host.side_by_side import side_by_side
from ..mesh.faces import FaceSet, as_faceset, corner_rows, face_subset
from ..mesh.points import check_points
from ..mesh.reorder import REORDER_MIN_FACES, Renumbering, scattered, z_order
from ..mesh.topology import EdgeInfo, checked_edges, free_nodes, pinched_faces
from ..metrics.face_quality import (
    Stats,
    folded_area,
    inverted_corners,
    mesh_stats,
    quality,
    stats_of,
)
from ..metrics.kept import Kept, fixed_corners, kept_corners, kept_note
from ..metrics.mean_ratio import group_quality
from ..metrics.reference_shapes import reference_targets
from ..metrics.targets import Targets, corner_factors, prepare_targets, target_fallback_note
from ..optimize import (
    STALL_ROUNDS,
    GlobalOptions,
    lift_min_quality,
    stops,
    untangle_budget,
    untangle_global,
)
from ..optimize.device import solver_for
from ..optimize.mesh_tables import Factors
from ..optimize.sampled import Sampled
from ..optimize.submesh import Neighbourhood
from ..params import EEGTParams
from .acceptance import accept
from .algorithm1 import smooth_loop, untangle_loop
from .harmonic import harmonic_positions
from .hopeless import hopeless_nodes, hopeless_note
from .hopeless_groups import hopeless_groups, hopeless_groups_note
from .hopeless_winding import hopeless_winding, hopeless_winding_note
from .repair import REGION, WHOLE, Repaired, keep_targets, repair_folds, touching

__all__ = ["LOCAL_MIN_FACES", "Cancelled", "EEGTResult", "as_given", "free_nodes",
           "normalisation", "stats_as_given", "untangle_and_smooth"]

LOCAL_MIN_FACES = 20_000  # untangle="auto": 'eegt+local' from this many faces on, else 'global'
LOCAL_RINGS = (4, 8, 16)  # rings around EEGT's leftover folds tried by 'eegt+local', in turn
LOCAL_MAX_ITER = 1000  # untangling iterations of one such try (then wider rings, or the whole)
LOCAL_SHARE = 0.5  # a sub-mesh of more than this share of the faces: the whole mesh instead
LOCAL_LEFT = 0.1  # ... and so when EEGT left more than this share of the inverted faces
LOCAL_POLISH_TOL = 1e-4  # 'eegt+local' polish: stops when a run gains less (relative) ...
LOCAL_POLISH_CHUNK = 10  # ... its runs of this many iterations, with fresh L-BFGS memory each
LOCAL_LIFT_RINGS = 3  # 'eegt+local' lift rounds: rings around the faces under the floor (a
#                       round's cost follows its sub-mesh: docs/global_untangle.md) ...
LOCAL_LIFT_GROW = 1.3  # ... and a floor up to this x the q_min before (GlobalOptions.lift_grow)

Progress = Callable[[int, str, Stats], object]


class Cancelled(Exception):
    """Raised by a progress callback to stop a run; the input is returned unchanged."""


@dataclass
class EEGTResult:
    points: np.ndarray
    status: str  # "valid" | "untangled" (no face of the result inverted) | "failed" | "cancelled"
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
    n_kept: int = 0  # valid faces with a straight or concave corner of fixed vertices only
    kept: Kept | None = None  # those corners (core.metrics.kept): how the stats measure them
    targets: np.ndarray | None = None  # (n_corners, 2) what before/after are measured
    # against (the caller's, the reference's or target "keep"'s; None: regular polygons)

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
            "kept_faces": self.n_kept,
        }


def untangle_and_smooth(
    points,
    faces,
    fixed=None,
    params: EEGTParams | None = None,
    backend: str = "numpy",
    progress: Progress | None = None,
    targets=None,
    reference_points=None,
    edges: EdgeInfo | None = None,
    keep_as_given: bool = True,
    attempt: str | None = None,
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
    not strictly convex) fall back to the regular polygon (`n_target_fallback`).

    `reference_points` with `params.target == "reference"`: an (N, 2) mesh of the same
    topology whose faces' shapes are the targets (core.metrics.reference_shapes: counterclockwise,
    finite; its inverted faces fall back to the regular polygon).

    `params.boundary`: "fixed" (boundary nodes never move), "slide" (they move along the
    input boundary polyline; corners above `params.feature_angle`, pinned and non-manifold
    nodes stay), "free" (only pinned and non-manifold nodes stay); see core.eegt.boundary.

    `edges`: the faces' edge analysis (core.mesh.topology.EdgeInfo) when the caller has it
    cheaper than the run's own sort of every corner (a mesh's edge table:
    `EdgeInfo.from_table`); it must describe these faces. None: computed.

    `keep_as_given`: straight or concave corners of fixed vertices only in simple faces are
    kept as given (core.metrics.kept: valid, measured without those vertices, `n_kept`);
    False, or the paper's mode (`untangle="eegt"`), counts them inverted and frozen.

    `attempt`: None, or a region "folds" repair's attempt (core.run.repair sets it): its
    global stage's untangling rounds end on a plateau (`GlobalOptions.end_round_on_plateau`),
    and on a region smaller than the mesh (`repair.REGION`) it gives up after two
    untangling rounds that opened too little of the fold (`GlobalOptions.give_up_early`),
    with no second start; the repair then grows the region.
    """
    t0 = time.perf_counter()
    params = params if params is not None else EEGTParams()
    if not isinstance(params, EEGTParams):
        raise ValueError(f"params must be an EEGTParams, got {type(params).__name__}")
    if attempt not in (None, REGION, WHOLE):
        raise ValueError(f"attempt must be None, {REGION!r} or {WHOLE!r}, got {attempt!r}")
    if params.region == "folds":
        return _untangle_folds(points, faces, fixed, params, backend, progress, targets,
                               reference_points, edges, keep_as_given, t0)
    n_faces = _face_count(faces)
    start_warm_up(backend, n_faces)  # the device gets ready while the input is checked
    with pages_for_run(n_faces), keep_freed_memory(n_faces):
        mesh = _prepare(points, faces, fixed, params, targets, reference_points, edges,
                        keep_as_given)
        run, order = _start(mesh, params, backend, progress, attempt)
        try:
            status, message = run.execute()
        except _CancelRun:
            status, message = "cancelled", "cancelled: mesh left unchanged"
        tg = mesh.targets
        if mesh.hopeless:
            message += f"; {mesh.hopeless}"
        if mesh.kept is not None:
            message += f"; {kept_note(mesh.kept)}"
        if tg is not None and tg.n_fallback:
            message += f"; {target_fallback_note(tg.n_fallback)}"
        out, before, after, status, message = _never_worse(mesh, run, order, status, message)
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
        mesh.free,
        run.n_global,
        int(mesh.frozen.sum()),
        0 if tg is None else tg.n_fallback,
        0 if mesh.kept is None else mesh.kept.n_faces,
        mesh.kept,
        mesh.corners,
    )


@dataclass
class _Mesh:
    """A run's checked input: the caller's points `p` and faces, the targets, which nodes
    move (and how, `motion`), the normalisation (centre, scale) with the normalised points
    `work`, the frozen faces, and the Z-order renumbering a large run works in (None: the
    caller's numbering), and the corners kept as given (None: none; then `fs` is the
    caller's faces, else `kept.measured`: the faces as the run measures them)."""

    p: np.ndarray
    fs: FaceSet
    targets: Targets | None
    free: np.ndarray
    center: np.ndarray
    scale: float
    work: np.ndarray
    motion: BoundaryMotion | None
    frozen: np.ndarray
    renumbered: tuple[Renumbering, FaceSet] | None
    hopeless: str = ""  # why certified-hopeless nodes are held (core/run/hopeless.py)
    kept: Kept | None = None
    corners: np.ndarray | None = None  # the targets as per-corner points (caller's order)


def _face_count(faces) -> int:
    """How many faces the caller gave, before any check (0 when it cannot be told): the
    run's page advice and its freed memory depend on it (core/host/page_advice.py,
    core/host/heap.py)."""
    if isinstance(faces, FaceSet):
        return faces.n_faces
    try:
        return len(faces)
    except TypeError:
        return 0


def _prepare(points, faces, fixed, params: EEGTParams, targets, reference_points,
             edges: EdgeInfo | None, keep_as_given: bool = True) -> _Mesh:
    """Check the input (one-line ValueErrors), prepare the targets, the boundary's motion and
    the normalised points."""
    p = check_points(points)
    fs = as_faceset(faces, p.shape[0])
    targets, keep_from = _target_corners(p, fs, params, targets, reference_points)
    if params.target == "keep":  # (its edge analysis serves the free nodes below too)
        edges = checked_edges(edges, fs, p.shape[0])
        targets = keep_targets(p, fs, free_nodes(p.shape[0], fs, fixed, edges=edges),
                               inverted_corners(p, fs), keep_from)
    tg = prepare_targets(targets, fs)  # its one-line checks first
    corners = None if targets is None or isinstance(targets, Targets) else \
        np.asarray(targets, dtype=np.float64)
    center, scale = normalisation(p, fs)
    work = (p - center) / scale
    # the edge analysis and the renumbering (two sorts) side by side
    renumber = tg is None and params.boundary == "fixed" and _renumbers(fs, p.shape[0])
    edges, renumbered = side_by_side(
        partial(checked_edges, edges, fs, p.shape[0]),
        partial(z_order, work, fs) if renumber else lambda: None,
        fs.n_corners if renumber else 0)
    free = free_nodes(p.shape[0], fs, fixed, edges=edges)
    if params.boundary == "fixed" and not free.any():
        raise ValueError("every node is fixed (boundary or pinned): nothing to optimize")
    _check_orientation(work, fs)
    motion = None  # "fixed": the engines' own path (free_nodes above checked the pins)
    if params.boundary != "fixed":
        motion = boundary_motion(work, fs, fixed, params.boundary, params.feature_angle,
                                 edges=edges)
    if motion is not None:
        free = motion.movable
    # frozen = straight or inverted in the caller's coordinates (where the stats are judged;
    # a straight fixed corner can turn 1e-17 positive once translated), scaled exactly
    given = as_given(p, fs, center, scale)
    # straight or concave corners of fixed vertices only in simple faces: kept as given (not
    # in the paper's mode); the run then works on the faces without those vertices
    paper = params.untangle == "eegt" or not keep_as_given
    kept = None if paper else kept_corners(given, fs, free)
    if kept is not None and isinstance(targets, Targets):
        kept = None  # prepared targets: their corners cannot be left out (the paper's rule)
    if kept is not None:
        fs, renumbered = kept.measured, None
        if targets is not None:
            tg = prepare_targets(np.asarray(targets, dtype=np.float64)[~kept.corner], fs)
    # free nodes that no position can fix (neighbours all fixed) are held: their inverted
    # faces are frozen from the start instead of costing the optimizer minutes
    can_hold = None if motion is None else ~motion.sliding
    held = hopeless_nodes(given, fs, free, can_hold)
    if held.nodes.size:
        free = free.copy()
        free[held.nodes] = False
    # ... and groups of free nodes whose faces' areas add up to a constant that is not > 0
    rims = hopeless_groups(given, fs, free, can_hold)
    if rims.nodes.size:
        free = free.copy()
        free[rims.nodes] = False
    # ... and parts whose fixed boundary crosses itself and winds negatively somewhere
    wound = hopeless_winding(p, fs, free, edges if kept is None else None)
    if wound.nodes.size:
        free = free.copy()
        free[wound.nodes] = False
    frozen = frozen_faces(given, fs, free)
    why = "; ".join(w for w in (hopeless_note(held), hopeless_groups_note(rims, scale * scale),
                                hopeless_winding_note(wound)) if w)
    return _Mesh(p, fs, tg, free, center, scale, work, motion, frozen, renumbered, why, kept,
                 corners)


def _target_corners(p: np.ndarray, fs: FaceSet, params: EEGTParams, targets, reference_points
                    ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(the caller's or the reference's per-corner targets, or None; the reference mesh
    for target "keep", or None), after the one-line checks of the combination."""
    if params.target in ("reference", "keep") and targets is not None:
        raise ValueError(f"give targets or target '{params.target}', not both")
    if params.target == "reference":
        return reference_targets(reference_points, fs, p.shape[0]), None
    if params.target == "keep":
        if reference_points is None:
            return None, None
        reference_targets(reference_points, fs, p.shape[0])  # its checks (one line each)
        return None, np.asarray(reference_points, dtype=np.float64)[:, :2]
    if reference_points is not None:
        raise ValueError("reference_points given but target is 'regular': set "
                         "target='reference' (or 'keep') to use them")
    return targets, None


def _untangle_folds(points, faces, fixed, params: EEGTParams, backend: str,
                    progress: Progress | None, targets, reference_points,
                    edges: EdgeInfo | None, keep_as_given: bool, t0: float) -> EEGTResult:
    """Region "folds" (core/run/repair.py): the run on the folded faces and a margin grown
    while needed; every other node keeps its bits. Stats are the whole mesh's against the
    run's targets: the region's from its run, the faces outside measured once (unchanged);
    with target "keep" a face outside counts 1 (it is its own target) unless it is inverted
    with fixed vertices only. The cost follows the region: the mesh is passed over a few
    times (corner signs, rings), never optimized or measured as a whole."""
    p = check_points(points)
    n = p.shape[0]
    fs = as_faceset(faces, n)
    whole, keep_from = _target_corners(p, fs, params, targets, reference_points)
    if isinstance(whole, Targets):
        raise ValueError("region 'folds' takes targets as an (n_corners, 2) array")
    if whole is not None:
        prepare_targets(whole, fs)  # its one-line checks
        whole = np.asarray(whole, dtype=np.float64)
    edges = checked_edges(edges, fs, n)
    movable = free_nodes(n, fs, fixed, edges=edges)
    if params.boundary != "fixed":  # boundary nodes of the region move as the mode says
        movable = movable | (fs.used_nodes(n) & edges.boundary_mask() & ~_pinned(fixed, p))
    if not movable.any():
        raise ValueError("every node is fixed (boundary or pinned): nothing to optimize")
    center, scale = normalisation(p, fs)
    _check_orientation((p - center) / scale, fs)
    bad = inverted_corners(p, fs)
    # a part whose fixed boundary winds negatively somewhere is held before any attempt
    # (each attempt's run would find it again, margin after margin)
    wound = hopeless_winding(p, fs, movable, edges)
    if wound.nodes.size:
        movable = movable.copy()
        movable[wound.nodes] = False
    seed = bad & touching(fs, movable)
    keep = params.target == "keep"
    if not seed.any():
        region = np.zeros(fs.n_faces, dtype=bool)
        before = stats_of(_outside_stats(p, fs, region, bad, movable, whole, keep,
                                         keep_as_given, params))
        text = "no folded face a move can change: nothing moved (region 'folds')"
        if wound.nodes.size:
            text += f"; {hopeless_winding_note(wound)}"
        return EEGTResult(p.copy(), "valid" if before.n_inverted == 0 else "failed", before,
                          before, 0, 0, time.perf_counter() - t0, backend, text,
                          np.zeros(n, dtype=bool))
    done = repair_folds(p, fs, movable, params, whole, untangle_and_smooth, keep_from, seed,
                        backend=backend, progress=progress, keep_as_given=keep_as_given)
    res = done.result
    out = _outside_stats(p, fs, done.region, bad, movable, whole, keep, keep_as_given, params)
    paper = params.untangle == "eegt" or not keep_as_given
    sub, nodes = done.faces, done.nodes
    kept = None if paper else kept_corners(p[nodes], sub, ~done.held)
    before = stats_of([quality(p[nodes], sub, done.targets, kept=kept), *out])
    after = stats_of([quality(done.points[nodes], sub, done.targets, kept=kept), *out])
    moved = np.zeros(n, dtype=bool)
    moved[done.nodes[np.asarray(res.moved, dtype=bool)]] = True
    status = res.status
    if status in ("valid", "untangled") and after.n_inverted > 0:
        status = "failed"
    message = (f"folds only: {int(done.region.sum())} of {fs.n_faces} faces ({done.rings} "
               f"rings around the folded ones) may move, every other vertex kept; "
               f"{res.message}")
    if wound.nodes.size:
        message += f"; {hopeless_winding_note(wound)}"
    return EEGTResult(done.points, status, before, after, res.untangle_iterations,
                      res.smooth_iterations, time.perf_counter() - t0, res.backend, message,
                      moved, res.global_iterations, res.n_frozen, res.n_target_fallback,
                      res.n_kept, targets=_folds_targets(p, fs, done, whole, keep))


def _folds_targets(p: np.ndarray, fs: FaceSet, done: Repaired, whole: np.ndarray | None,
                   keep: bool) -> np.ndarray | None:
    """The whole mesh's per-corner targets a region "folds" run measured against (what a
    caller measuring its result again must use: the float32 check of
    `untangle_and_smooth_3d`): target "keep", each face's own corners with the region's
    from its run; else the caller's or the reference's (None: regular polygons)."""
    if not keep:
        return whole
    out = np.take(p if p.shape[1] == 2 else p[:, :2], fs.indices, axis=0)
    out[corner_rows(fs, np.flatnonzero(done.region))] = done.targets
    return out


def _outside_stats(p: np.ndarray, fs: FaceSet, region: np.ndarray, bad: np.ndarray,
                   movable: np.ndarray, whole: np.ndarray | None, keep: bool,
                   keep_as_given: bool, params: EEGTParams) -> list[np.ndarray]:
    """The qualities of the faces outside `region` ([] when there are none). Target "keep":
    1 for each (a face is its own target), 0 for an inverted one (its vertices are all
    fixed: it is outside the folds) unless its corners are kept as given; else their mean
    ratio against `whole` (None: regular polygons)."""
    ids = np.flatnonzero(~region)
    if ids.size == 0:
        return []
    paper = params.untangle == "eegt" or not keep_as_given
    if keep:
        q = np.ones(ids.size)
        stuck = np.flatnonzero(bad[ids])
        if stuck.size:
            sub, nodes, _ = face_subset(fs, ids[stuck])
            kept = None if paper else kept_corners(p[nodes], sub, movable[nodes])
            q[stuck] = quality(p[nodes], sub, None, kept=kept)
        return [q]
    sub, nodes, rows = face_subset(fs, ids)
    kept = None if paper else kept_corners(p[nodes], sub, movable[nodes])
    tg = None if whole is None else whole[rows]
    return [quality(p[nodes], sub, tg, kept=kept)]


def _pinned(fixed, p: np.ndarray) -> np.ndarray:
    """(N,) bool of the caller's pins (None: none)."""
    if fixed is None:
        return np.zeros(p.shape[0], dtype=bool)
    return np.asarray(fixed, dtype=bool).reshape(-1)


def _renumbers(fs: FaceSet, n_nodes: int) -> bool:
    """Whether a run with regular targets and a fixed boundary works renumbered in Z order
    (core.mesh.reorder: memory locality): a large mesh numbered without locality."""
    return fs.n_faces >= REORDER_MIN_FACES and scattered(fs, n_nodes)


def _start(mesh: _Mesh, params: EEGTParams, backend: str, progress: Progress | None,
           attempt: str | None = None) -> tuple[_Run, Renumbering | None]:
    """The run over the normalised points, in the renumbering of `_prepare` if it made one
    (returned with it; None: as given)."""
    fs, free, frozen = mesh.fs, mesh.free, mesh.frozen
    if mesh.renumbered is not None:
        order, run_fs = mesh.renumbered
        work = mesh.work[order.nodes]  # the run's numbering from here on (one copy, not two)
        run = _Run(work, run_fs, free[order.nodes], params, backend, progress,
                   frozen[order.faces], frozen_ids=np.flatnonzero(frozen),
                   attempt=attempt)
    else:
        order = None
        run = _Run(mesh.work, fs, free, params, backend, progress, frozen, mesh.targets,
                   mesh.motion, attempt=attempt)
    return run, order


def _never_worse(mesh: _Mesh, run: _Run, order: Renumbering | None, status: str,
                 message: str) -> tuple[np.ndarray, Stats, Stats, str, str]:
    """(points, before, after, status, message): the best iterate in the caller's units,
    only where it moved, and only when it is no worse than the input judged in the caller's
    coordinates (else the input, status and message saying so)."""
    p, fs, center, scale = mesh.p, mesh.fs, mesh.center, mesh.scale
    measured = partial(stats_as_given, fs=fs, center=center, scale=scale, targets=mesh.targets,
                       kept=mesh.kept)
    out = p.copy()
    if status == "cancelled":
        before = measured(p)
        return out, before, before, status, message
    best = run.best_pts if run.best_pts is not None else run.engine.best_points()
    changed = np.any(best != run.p, axis=1) & run.free  # fixed rows stay the input's
    if order is not None:
        best, changed = order.back(best), order.back(changed)
    out[changed] = best[changed] * scale + center
    if changed.any():  # the input's and the result's stats side by side
        before, after = side_by_side(partial(measured, p), partial(measured, out),
                                     fs.n_corners)
    else:
        before = after = measured(p)
    if not accept(before, after):  # judged in the caller's units
        out, after = p.copy(), before
        status = "failed" if before.n_inverted else "valid"
        note = "the result was not better than the input in its own coordinates: input returned"
        if status == "failed":
            message = _failed(f"{note} with {before.n_inverted} inverted faces", run, message)
        else:
            message += f"; {note}"
    if status != "failed" and after.n_inverted:  # never claim more than the result
        message = _failed(f"{after.n_inverted} faces are inverted in the caller's "
                          "coordinates", run, message)
        status = "failed"
    return out, before, after, status, message


def _failed(why: str, run: _Run, message: str) -> str:
    """A 'failed' message that leads with why (and the frozen faces, if any), then what the
    run did (its own message, without its verdict)."""
    head = f"failed: {why}"
    if run.n_frozen:
        frozen = run.stuck_why()
        head += f"; {frozen}"
        message = message.removeprefix(f"failed: {frozen}; ")
    return f"{head}; the run: {message.removeprefix('failed: ')}"


def _used_rows(p: np.ndarray, fs: FaceSet) -> np.ndarray:
    """The rows of p that belong to a face (p itself when all do)."""
    used = fs.used_nodes(p.shape[0])
    return p if used.all() else p[used]


def _column_min(p: np.ndarray) -> np.ndarray:
    """p.min(axis=0) (a minimum has one value whatever the order: the same bits), column by
    column, which NumPy does several times faster on an (N, 2) array."""
    return np.array([p[:, k].min() for k in range(p.shape[1])])


def _column_max(p: np.ndarray) -> np.ndarray:
    """p.max(axis=0), column by column (as `_column_min`)."""
    return np.array([p[:, k].max() for k in range(p.shape[1])])


def normalisation(
    p: np.ndarray, fs: FaceSet, centre_on: np.ndarray | None = None
) -> tuple[np.ndarray, float]:
    """(centre, scale) that map the used nodes into [-1, 1]^2: the bounding-box centre (of
    the `centre_on` nodes if given) and a power of two (so that scaling is exact), computed
    without overflow up to 1e308."""
    used = _used_rows(p, fs)
    lo, hi = _column_min(used), _column_max(used)
    half = float(np.max(0.5 * hi - 0.5 * lo))
    if centre_on is not None:
        lo, hi = _column_min(p[centre_on]), _column_max(p[centre_on])
    center = 0.5 * lo + 0.5 * hi
    if not half > 0.0:
        return center, 1.0
    return center, math.ldexp(1.0, math.frexp(half)[1])


def as_given(p: np.ndarray, fs: FaceSet, center: np.ndarray, scale: float) -> np.ndarray:
    """The caller's points divided by the power-of-two scale (exact: every sign and mean
    ratio is the caller's bit for bit, and the same for any 2^k multiple of the input); the
    normalised points where the mesh sits more than 1e100 sizes from the origin."""
    q = p / scale
    if float(np.max(np.abs(_used_rows(q, fs)))) < 1e100:
        return q
    return (p - center) / scale


def stats_as_given(
    p: np.ndarray, fs: FaceSet, center: np.ndarray, scale: float, targets: Targets | None = None,
    kept: Kept | None = None,
) -> Stats:
    """Stats of the points as the caller has them (what `mesh_stats` of the result says,
    with the corners `kept` as given left out)."""
    return mesh_stats(as_given(p, fs, center, scale), fs, targets, kept)


def _check_orientation(p: np.ndarray, fs: FaceSet) -> None:
    """ValueError for clockwise input (total signed area < 0) or a mesh of zero area: folds
    cannot change the total signed area, so its sign is the faces' intended orientation."""
    total = 0.0
    for g in fs.groups:
        x, y = p[g.nodes, 0], p[g.nodes, 1]
        total += add_reduce(x * np.roll(y, -1, axis=0) - np.roll(x, -1, axis=0) * y)
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


def stuck_note(ids: np.ndarray) -> str:
    """Why a run that ends with frozen faces is 'failed', naming the faces (0-based, in the
    caller's face order; the first few)."""
    ids = np.asarray(ids).ravel()
    shown = ", ".join(str(int(i)) for i in ids[:5]) + (", ..." if ids.size > 5 else "")
    what = (f"face {shown} stays inverted" if ids.size == 1
            else f"{ids.size} faces stay inverted (faces {shown})")
    return (f"{what}: a corner made of fixed vertices only (boundary, pinned, a slide "
            "corner or held as hopeless) is straight or inverted, so no move can fix it")


def frozen_faces(p: np.ndarray, faces, free: np.ndarray) -> np.ndarray:
    """(F,) bool: faces with a corner that no move can make positive: made of fixed nodes
    only with a det <= 0 (straight or inverted), or with two fixed nodes at one point (its
    det is 0 wherever the third goes). These faces count as inverted forever and are left
    out of the untangling goal."""
    fs = as_faceset(faces, p.shape[0])
    out = np.zeros(fs.n_faces, dtype=bool)
    x, y = p[:, 0], p[:, 1]
    for g in fs.groups:
        fc = fixed_corners(x, y, g, free)
        nodes, nxt, prv, fix, fix_n, fix_p = fc.nodes, fc.nxt, fc.prv, fc.fix, fc.fix_n, fc.fix_p
        stuck = fc.unchangeable
        # two fixed nodes of a corner at one point (a node dragged onto its neighbour)
        same_n = (x[nxt] == x[nodes]) & (y[nxt] == y[nodes])
        same_p = (x[prv] == x[nodes]) & (y[prv] == y[nodes])
        same_np = (x[nxt] == x[prv]) & (y[nxt] == y[prv])
        stuck |= (fix & fix_n & same_n) | (fix & fix_p & same_p) | (fix_n & fix_p & same_np)
        out[g.ids[fc.cols]] = stuck.any(axis=0)
    return out


class _CancelRun(Exception):
    pass


class _Run:
    """One run of the pipeline: EEGT phases on an engine, the global stage on the host."""

    def __init__(self, p, fs, free, params: EEGTParams, backend: str, progress, frozen,
                 targets: Targets | None = None, motion: BoundaryMotion | None = None,
                 frozen_ids: np.ndarray | None = None, attempt: str | None = None):
        self.p, self.fs, self.free, self.params = p, fs, free, params
        # the frozen faces' ids in the caller's face order (the run's may be renumbered)
        self.frozen_ids = np.flatnonzero(frozen) if frozen_ids is None else frozen_ids
        self.motion = motion
        slide = None if motion is None else motion.slide
        self.slide = None if slide is None else SlideView(slide)  # the global stage's
        self.frozen = frozen
        self.n_frozen = int(frozen.sum())  # inverted faces no move can change
        self.backend, self.progress = backend, progress
        self.mode = params.untangle
        if self.mode == "auto":
            self.mode = "eegt+local" if fs.n_faces >= LOCAL_MIN_FACES else "global"
        self.targets = targets
        self.engine, self.backend_name = make_engine(backend, p, fs, free, params, targets,
                                                     motion)
        self.before = self.best = self.engine.stats()
        self.best_pts: np.ndarray | None = None  # None: the engine's best buffer holds it
        self.engine.save_best()
        self.n_untangle = self.n_smooth = self.n_global = 0
        self.polished = False  # the global stage's polish (or the lift stage) has run
        self.lifted = 0  # lift rounds the last lift kept
        self.gave_up = False  # a global stage ended for want of progress (stages.STALL_ROUNDS)
        self.attempt = attempt  # a repair's attempt (`untangle_and_smooth`) ...
        self.too_tight = False  # ... whose global stage gave up early (no second start)
        self._groups: tuple[dict[int, np.ndarray], Factors | None] | None = None
        self._near: Neighbourhood | None = None  # made by the local untangle, if it runs
        self.lbfgs = None  # the global stage's solver (None: the host's), made when it runs
        self._harmonic: np.ndarray | None = None  # `_harmonic_map`, made when a stage needs it

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
        prm, before, mode = self.params, self.before, self.mode
        tangled = self.tangled(before)
        self.report(0, "untangle" if tangled else "smooth", before)
        frozen = f"; {frozen_note(self.n_frozen)}" if self.n_frozen else ""
        current = before
        if tangled:
            if mode != "global":
                current = self.untangle_eegt()
            if self.tangled(self.best) and mode == "eegt+local":
                current = self.untangle_local()
            if self.tangled(self.best) and mode != "eegt":
                current = self.untangle_whole()
            if self.tangled(self.best):
                return "failed", (
                    f"failed: {self.best.n_inverted - self.n_frozen} inverted faces remain "
                    f"after {self.n_untangle} untangling iterations"
                    + (f" and {self.n_global} global iterations" if self.n_global else "")
                    + f" (best iterate kept; input had {before.n_inverted - self.n_frozen})"
                    + (f"; the optimizer gave up after {STALL_ROUNDS} rounds in a row without "
                       "progress: no move it finds opens the fold" if self.gave_up else "")
                    + (f"; besides, {self.stuck_why()}" if self.n_frozen else "")
                )
        if not self.polished:  # the whole-mesh global stage polishes and lifts as it goes
            if mode == "eegt+local" and (prm.polish_iterations > 0 or prm.lift_rounds > 0):
                current = self.lift_stage()
            elif mode != "eegt+local" and prm.polish_iterations > 0:
                current = self.global_stage(polish=prm.polish_iterations)
        if not (mode == "eegt+local" and self.lifted):  # lifted rounds leave EEGT smoothing
            self.smooth_eegt(current)  # no better iterate to find (docs/scale.md)
        verb = f"untangled in {self.n_untangle} iterations, " if tangled else ""
        glob = f"{self.n_global} optimization iterations, " if self.n_global else ""
        b = self.best
        text = (f"{verb}{glob}smoothed in {self.n_smooth} iterations: "
                f"q_min {before.q_min:.4f} -> {b.q_min:.4f}, "
                f"q_avg {before.q_avg:.4f} -> {b.q_avg:.4f}")
        if b.n_inverted:  # only frozen faces are left: the run cannot claim a valid mesh
            return "failed", f"failed: {self.stuck_why()}; {text}"
        return ("untangled" if tangled else "valid"), text + frozen

    def untangle_whole(self) -> Stats:
        """The whole-mesh stage from two starts in turn: the input (EEGT's best iterate for
        'eegt+global') and the harmonic map of the interior, the second only when the first
        ends tangled and a move can still help (docs/global_untangle.md, "Harmonic start").
        The harmonic map goes first when 'eegt+local' hands the whole mesh over (EEGT could not
        do the bulk: a moved boundary, not scattered folds) and it leaves less fold to undo
        than the input (`_harmonic_folds_less`)."""
        harmonic_first = self.mode == "eegt+local" and self._harmonic_folds_less()
        current = self._whole_from(harmonic=harmonic_first)
        if self.tangled(self.best) and not self.too_tight and self._restart_may_help():
            current = self._whole_from(harmonic=not harmonic_first)
        return current

    def _whole_from(self, harmonic: bool) -> Stats:
        polish = self.params.polish_iterations
        if harmonic:
            return self.global_stage(polish=polish, start=self._harmonic_map())
        return self.global_stage(polish=polish, from_input=True)

    def _harmonic_map(self) -> np.ndarray:
        """The input with its free interior nodes at their harmonic map (made once a run)."""
        if self._harmonic is None:
            self._harmonic = harmonic_positions(self.p, self.fs, self.free,
                                                tick=self._harmonic_tick)
        return self._harmonic

    def _harmonic_folds_less(self) -> bool:
        """The harmonic map leaves less fold to undo than the input: a smaller folded area
        (`quality.folded_area`) over the faces that are not frozen."""
        return self._folded(self._harmonic_map()) < self._folded(self.p)

    def _folded(self, pts: np.ndarray) -> float:
        """The folded area of the faces at `pts` that are not frozen."""
        area = folded_area(pts, self.fs)
        return add_reduce(area[~self.frozen])

    def _harmonic_tick(self) -> None:
        """Progress during the harmonic start's solve (the best iterate's numbers); a stop
        cancels the run."""
        self.report(self.n_untangle + self.n_global, "global", self.best)

    def _restart_may_help(self) -> bool:
        """Whether an inverted face of the best iterate is neither frozen nor pinched
        (`pinched_faces`: a pair that keeps an inverted face whatever moves)."""
        pinched = pinched_faces(self.fs, self.p.shape[0])
        return any((bad & ~pinched[g.ids]).any()
                   for g, bad in zip(self.fs.groups, self._inverted(self.best_points()),
                                     strict=True))

    def stuck_why(self) -> str:
        """Why the inverted faces left are there: the frozen ones, by their face ids."""
        return stuck_note(self.frozen_ids)

    def untangle_eegt(self) -> Stats:
        """EEGT until no face is inverted or the iteration cap; 'eegt+global' stops at a stall
        (no new low of the inverted count for `stall_iterations`), 'eegt+local' as soon as
        three iterations no longer halve the count (what is left goes to `untangle_local`)."""
        prm = self.params
        low, since = self.before.n_inverted, 0
        counts = [self.before.n_inverted]

        def step() -> Stats:
            current = self.engine.step("untangle")
            self.n_untangle += 1
            self.track(current)
            self.report(self.n_untangle, "untangle", current)
            return current

        def stalled(current: Stats) -> bool:
            nonlocal low, since
            counts.append(current.n_inverted)
            if self.mode == "eegt+local" and len(counts) > 3 and 2 * counts[-1] > counts[-4]:
                return True
            if current.n_inverted < low:
                low, since = current.n_inverted, 0
                return False
            since += 1
            return self.mode == "eegt+global" and since >= prm.stall_iterations

        current, _ = untangle_loop(step, self.tangled, prm.max_untangle_iterations, stalled)
        return self.before if current is None else current

    def untangle_local(self) -> Stats:
        """The foldover-free optimization on the sub-mesh within a few rings of the inverted
        faces EEGT left (wider rings in turn while some remain): most of a large mesh is fine
        by then, and the rest of it stays exactly where EEGT put it. More than LOCAL_LEFT of
        the input's inverted faces left, or a sub-mesh of more than LOCAL_SHARE of the faces,
        means EEGT did not do the bulk: the whole mesh is then optimized from the input
        instead (`global_stage`)."""
        current = self.best
        left = self.best.n_inverted - self.n_frozen
        if left > LOCAL_LEFT * (self.before.n_inverted - self.n_frozen):
            return current
        near = self._neighbourhood()
        for rings in LOCAL_RINGS:
            start = self.best_points()
            bad = self._inverted_movable(start)
            (sub, nodes, sfree, sub_f), _ = near.submesh(bad, rings)
            if not sfree.any() or sum(f.shape[0] for f in sub.values()) > LOCAL_SHARE * bad.size:
                break
            relay = self._local_relay(start, nodes, sfree)

            polish = self.params.polish_iterations  # the sub-mesh leaves the stage well shaped
            budget = min(self.params.max_untangle_iterations, LOCAL_MAX_ITER)
            options = GlobalOptions(max_iter=budget + polish, polish_iter=polish,
                                    long_polish=False)
            sub_pts, info = untangle_global(
                start[nodes], sub, sfree, options,
                progress=relay if self.progress is not None else None, factors=sub_f,
                slide=None if self.slide is None else self.slide.sub(nodes, start),
            )
            self.n_global += int(info["iterations"])
            self.gave_up |= bool(info.get("gave_up"))
            self.too_tight |= bool(info.get("too_tight"))
            if info.get("status") == "cancelled":
                raise _CancelRun
            pts = start.copy()
            pts[nodes[sfree]] = sub_pts[sfree]
            current = self._adopt(pts, start)
            if not self.tangled(self.best):
                break
        return current

    def _local_relay(self, start: np.ndarray, nodes: np.ndarray, sfree: np.ndarray):
        """The progress relay of a sub-mesh solve: the whole mesh's numbers with the
        sub-mesh's free nodes at the solve's current iterate (measured now and then)."""
        base = self.n_untangle + self.n_global
        live: Sampled[Stats] = Sampled()
        moved = nodes[sfree]

        def measure(current: Callable[[], np.ndarray]) -> Stats:
            pts = start.copy()
            pts[moved] = current()[sfree]
            return mesh_stats(pts, self.fs, self.targets)

        def relay(iterations: int, _max_iter: int, _n_inv: int,
                  current: Callable[[], np.ndarray]) -> None:
            self.report(base + iterations, "global", live.update(partial(measure, current)))

        return relay

    def _inverted(self, pts: np.ndarray) -> list[np.ndarray]:
        """Per face group: its inverted faces at `pts` that are not frozen."""
        return [(group_quality(pts[g.nodes, 0], pts[g.nodes, 1]) == 0.0) & ~self.frozen[g.ids]
                for g in self.fs.groups]

    def _inverted_movable(self, pts: np.ndarray) -> np.ndarray:
        """(E,) bool in `_global_groups` order: inverted faces that are not frozen."""
        return np.concatenate([
            bad[~(self.frozen[g.ids] & ~self.free[g.nodes].any(axis=0))]  # inert faces out
            for g, bad in zip(self.fs.groups, self._inverted(pts), strict=True)])

    def lift_stage(self) -> Stats:
        """'eegt+local' on a valid mesh: the lift's whole-mesh run maximises the mean quality
        (up to `polish_iterations`), its rounds raise the worst faces (`lift_rounds`)."""
        start = self.best_points()
        self.lbfgs = self._solver()
        options = GlobalOptions(
            lift_first_iter=self.params.polish_iterations,
            lift_rounds=self.params.lift_rounds,
            lift_rel_tol=LOCAL_POLISH_TOL,
            lift_chunk=LOCAL_POLISH_CHUNK,
            lift_rings=LOCAL_LIFT_RINGS,
            lift_grow=LOCAL_LIFT_GROW,
            solver=self.lbfgs,
            stiff_settle=self.targets is not None,
        )
        try:
            pts = self.lift(start, options)
        finally:
            if self.lbfgs is not None:
                self.lbfgs.release()
        self.polished = True
        return self._adopt(pts, start)

    def global_stage(self, polish: int, from_input: bool = False,
                     start: np.ndarray | None = None) -> Stats:
        """Foldover-free optimization of the whole mesh (from `start`, else from the input or
        from the best iterate), then the lift; EEGT continues from its result."""
        best = None  # the best iterate's host copy, when that is the start
        if start is None:
            use_input = from_input and self.mode == "eegt+local"
            start = self.p if use_input else (best := self.best_points())
        groups, factors = self._global_groups()
        base = self.n_untangle + self.n_global
        live: Sampled[Stats] = Sampled()  # the current iterate's numbers, now and then

        def relay(iterations: int, _max_iter: int, _n_inv: int,
                  current: Callable[[], np.ndarray]) -> None:
            shown = live.update(lambda: mesh_stats(current(), self.fs, self.targets))
            self.report(base + iterations, "global", shown)

        self.lbfgs = self._solver()  # built here: not for runs without one
        budget = untangle_budget(self.params.max_untangle_iterations, int(self.free.sum()))
        options = GlobalOptions(
            max_iter=budget + polish,
            polish_iter=polish,
            lift_rounds=self.params.lift_rounds,
            solver=self.lbfgs,
            give_up_early=self.attempt == REGION,
            end_round_on_plateau=self.attempt is not None,
            stiff_settle=self.targets is not None,
        )
        try:
            pts, info = untangle_global(
                start,
                groups,
                self.free,
                options,
                progress=relay if self.progress is not None else None,  # no pauses unasked
                factors=factors,
                slide=self.slide,
            )
            self.n_global += int(info["iterations"])
            self.gave_up |= bool(info.get("gave_up"))
            self.too_tight |= bool(info.get("too_tight"))
            if info.get("status") == "cancelled":
                raise _CancelRun
            if info.get("status") == "untangled" and self.params.lift_rounds > 0:
                pts = self.lift(pts, options)
        finally:
            if self.lbfgs is not None:  # the device solver outlives the run: not its tables
                self.lbfgs.release()
        self.polished = True
        return self._adopt(pts, best)

    def _solver(self):
        """The global stage's device solver, or None for the host's (always with sliding
        nodes: their parameters are variables the device solvers do not have)."""
        return solver_for(self.backend_name, sliding=self.slide is not None)

    def _adopt(self, pts: np.ndarray, best: np.ndarray | None) -> Stats:
        """Continue the EEGT engine from `pts` (fixed rows reset to the input's bits); the
        best iterate stays the better of it and the earlier best. `best`: the earlier best's
        host copy when the caller has it (it started there), else None (read from the
        engine)."""
        pts[~self.free] = self.p[~self.free]  # fixed rows bit-identical, whatever happened
        if self.best_pts is None:  # keep the earlier best as a host copy
            self.best_pts = self.engine.best_points() if best is None else best
        self.engine = self.engine.restarted(pts)  # same mesh, same fixed nodes: reuse set-up
        current = self.engine.stats()
        if current.better_than(self.best):
            self.best, self.best_pts = current, None
            self.engine.save_best()
        return current

    def _neighbourhood(self) -> Neighbourhood:
        """The node -> element incidence of `_global_groups` (the local untangle's rings and
        the lift's rounds share it)."""
        if self._near is None:
            groups, factors = self._global_groups()
            self._near = Neighbourhood(groups, self.free, factors)
        return self._near

    def _global_groups(self) -> tuple[dict[int, np.ndarray], Factors | None]:
        """The global stage's faces: all but frozen faces whose every node is fixed (constant:
        nothing to optimise, and an inverted one would block the lift's validity guard), and
        their target shapes (None: regular polygons)."""
        if self._groups is None:
            groups, factors = {}, None
            all_factors = None if self.targets is None else corner_factors(self.targets, self.fs)
            for g in self.fs.groups:
                keep = ~(self.frozen[g.ids] & ~self.free[g.nodes].any(axis=0))
                if g.size == self.fs.n_faces and keep.all():  # the faces' own rows, no copy
                    rows = self.fs.indices.reshape(-1, g.n).view()
                    rows.flags.writeable = False
                    groups[g.n] = rows
                else:
                    groups[g.n] = np.ascontiguousarray(g.nodes[:, keep].T)
                if all_factors is not None:
                    factors = factors or {}
                    factors[g.n] = tuple(u[keep] for u in all_factors[g.n])
            self._groups = (groups, factors)
        return self._groups

    def lift(self, pts: np.ndarray, options: GlobalOptions) -> np.ndarray:
        """Raise q_min of the valid optimization result without lowering its q_avg."""
        groups, factors = self._global_groups()
        base = self.n_untangle + self.n_global

        def relay(iterations: int, _rounds: int, q_min: float, q_avg: float) -> None:
            self.report(base + iterations, "global", Stats(self.n_frozen, q_min, q_avg))

        out, info = lift_min_quality(
            pts, groups, self.free, options,
            progress=relay if self.progress is not None else None, factors=factors,
            slide=self.slide, neighbourhood=self._near,
        )
        self.n_global += int(info["iterations"])
        if info.get("status") == "cancelled":
            raise _CancelRun
        self.lifted = int(info.get("rounds", 0))
        return out

    def smooth_eegt(self, current: Stats) -> None:
        """EEGT smoothing from the iterate `current` until `smoothing_done` (or the cap)."""
        def step() -> Stats:
            s = self.engine.step("smooth")
            self.n_smooth += 1
            self.track(s)
            self.report(self.n_untangle + self.n_global + self.n_smooth, "smooth", s)
            return s

        smooth_loop(step, current, self.params)
