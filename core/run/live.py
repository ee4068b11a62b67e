"""Live untangling: a drag's warm-started EEGT frames (NumPy; never imports bpy).

A drag sets up once (``LiveSession``: topology, free nodes, targets, the search over the
fixed nodes that do not move) and then runs frames: each frame moves the grabbed nodes to the
cursor (they are pins), runs a few EEGT iterations from where the last frame left the mesh
and returns the new positions with their quality. One frame is, bit for bit, the cold run
``untangle_and_smooth(points, faces, fixed=pins, params=live_params(params, k))`` on the same
input (EEGT untangling while a movable face is inverted, then EEGT smoothing, at most ``k``
iterations each, the best iterate kept, never worse than its input), except that a frame may
stop early when its time budget is spent and that a frame which ends still tangled returns its
last iterate (where the next frame's untangling goes on) instead of the best one. Meshes the
cold run renumbers for memory locality (``core.mesh.reorder``, 50 000 faces and more in a
scattered numbering) run in their own order here.

A session whose every node is grabbed (a selection dragged as a whole) has nothing to
optimize: its frames translate the grabbed nodes and measure them.

``uv_region`` cuts what a UV drag moves out of a welded UV map: the grabbed UV vertices'
islands (or their selected faces), mirrored islands reflected as ``core.uv.uv_untangle`` does;
``uv_vertex_corners`` lists every face corner (Blender loop) of its UV vertices, those of faces
outside the region included, so that a moved UV vertex moves whole. A drag's cursor is kept
within ``cursor_bounds`` (``CURSOR_REACH``) and what it writes passes ``storable_float32``.
docs/live.md describes the tools built on it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from ..eegt.distance import NearestBoundary
from ..eegt.engine_numpy import NumpyEngine, edge_lengths
from ..mesh.faces import FaceSet, as_faceset
from ..mesh.topology import checked_edges, free_nodes
from ..metrics.face_quality import Stats, stats_of
from ..metrics.kept import Kept, kept_corners
from ..metrics.targets import Targets, prepare_targets
from ..params import EEGTParams
from ..uv.uv_layout import UVLayout, island_faces
from .acceptance import accept
from .algorithm1 import Deadline, smooth_loop, untangle_loop
from .live_pull import PULL_AFTER, GrabPull
from .live_repair import RegionRepair, RepairStep, carried
from .live_reuse import AnchorSearch, GivenQuality, StillDistances
from .pipeline import as_given, frozen_faces, normalisation, untangle_and_smooth

__all__ = ["CURSOR_REACH", "FINISH_BUDGET", "FINISH_GO_ON", "FINISH_KEEP", "FINISH_LIMIT",
           "FINISH_RESTORE", "FRAME_BUDGET", "FRAME_ITERATIONS", "LiveFrame", "LiveSession",
           "UVRegion", "clamp_cursor", "cursor_bounds", "live_params", "storable_float32",
           "uv_region", "uv_vertex_corners"]

FRAME_ITERATIONS = 50  # at most this many untangling and this many smoothing steps a frame
FRAME_BUDGET = 0.04  # seconds a frame aims at, its writes into Blender included (at least
# one iteration runs: a mesh whose single iteration takes longer passes it)
FINISH_KEEP, FINISH_GO_ON, FINISH_RESTORE = "keep", "go on", "restore"  # `finishing`
FINISH_BUDGET = 0.1  # seconds of a frame while a release finishes the repair (the editor
# stays responsive to Esc between frames)
FINISH_LIMIT = 30.0  # seconds a release finishes the repair at most (then `finishing`'s
# out_of_time: a fold still open as FINISH_RESTORE, a pull kept where it got to)
CURSOR_REACH = 1000.0  # a drag's cursor is kept within the dragged mesh's bounding box grown
# on every side by this many times the box's longer side: farther than any pull on screen,
# near enough that every place is finite in float32 and the frame's scaling stays sane
_FLOAT32_MAX = float(np.finfo(np.float32).max)


def cursor_bounds(points: np.ndarray, reach: float = CURSOR_REACH) -> np.ndarray:
    """(2, 2) [low, high] corners of the places a drag's cursor may take: the bounding box
    of ``points`` ((N, 2), the dragged mesh in the cursor's coordinates) grown on every side
    by ``reach`` times its longer side (1 for a box of no size), within float32's range."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    lo, hi = p.min(axis=0), p.max(axis=0)
    side = float(np.max(hi - lo))
    grow = reach * (side if side > 0.0 else 1.0)
    return np.clip(np.stack([lo - grow, hi + grow]), -_FLOAT32_MAX, _FLOAT32_MAX)


def clamp_cursor(at, bounds: np.ndarray) -> np.ndarray | None:
    """The cursor ``at`` (2,) clamped into ``bounds`` (``cursor_bounds``; infinities go to
    the bound), or None when it is not a place (NaN, None)."""
    if at is None:
        return None
    a = np.asarray(at, dtype=np.float64).reshape(2)
    if np.isnan(a).any():
        return None
    return np.minimum(np.maximum(a, bounds[0]), bounds[1])


def storable_float32(values: np.ndarray) -> np.ndarray:
    """``values`` as float32, what Blender stores; ValueError (one line) when one is NaN or
    beyond float32's range (it would be stored as inf or NaN)."""
    v = np.asarray(values, dtype=np.float64)
    if not (np.abs(v) <= _FLOAT32_MAX).all():
        raise ValueError("a place beyond float32's range: nothing written")
    return v.astype(np.float32)


def live_params(params: EEGTParams | None, iterations: int) -> EEGTParams:
    """The parameters of one frame: EEGT only (no global stage, polish or lift), a fixed
    boundary, at most ``iterations`` untangling and smoothing iterations."""
    return replace(params if params is not None else EEGTParams(), untangle="eegt",
                   polish_iterations=0, lift_rounds=0, boundary="fixed",
                   max_untangle_iterations=iterations, max_smooth_iterations=iterations)


@dataclass(frozen=True)
class LiveFrame:
    """One frame's outcome (positions in the caller's coordinates)."""

    points: np.ndarray  # (N, 2) float64
    stats: Stats  # of ``points``: inverted faces, worst and mean quality
    status: str  # "valid" | "untangled" | "tangled" (movable faces still inverted)
    untangle_iterations: int
    smooth_iterations: int
    seconds: float
    n_tangled: int = 0  # inverted faces a move can change (the rest are frozen)
    repair: RepairStep | None = None  # the escalation's region solves, if they ran
    pull_iterations: int = 0  # the pull's iterations (``core.run.live_pull``), if it ran
    held_back: float = 0.0  # how far the layout holds the grabbed nodes from the cursor

    @property
    def opening(self) -> bool:
        """Whether the frames are still opening a fold (a movable face inverted) or pulling
        the grabbed nodes (a pull's frames are valid while the nodes still travel)."""
        return self.status == "tangled" or bool(self.pull_iterations)

    @property
    def settled(self) -> bool:
        """Nothing left for frames with the cursor still: not `opening`, and the smoothing
        converged (at most one iteration)."""
        return not self.opening and self.smooth_iterations <= 1


class LiveSession:
    """One drag: set up once, then ``frame`` per cursor position.

    ``points`` (N, 2) and ``faces`` a counterclockwise planar mesh; ``fixed`` (N,) bool pins
    that stay; ``grab`` the node ids that follow the cursor (pins too); ``targets`` per-corner
    target shapes as in ``untangle_and_smooth``. When every node of the faces is grabbed,
    frames translate them (nothing to optimize: ``rigid``). ``escalate``: the foldover-free
    stage on a tangled region and the rest's pull (``pull_after`` seconds of a tangled rest;
    None: never) as ``frame`` describes; False: EEGT only. ValueError (one line) for bad
    input or when nothing but some grabbed nodes can move."""

    def __init__(self, points, faces, grab, fixed=None, params: EEGTParams | None = None,
                 targets=None, escalate: bool = True, keep_as_given: bool = True,
                 pull_after: float | None = PULL_AFTER):
        p = np.array(points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 2 or not np.isfinite(p).all():
            raise ValueError("points must be a finite (N, 2) array")
        self.fs: FaceSet = as_faceset(faces, p.shape[0])
        self.faces = self.fs  # the caller's faces (``fs`` is what the frames measure)
        n = p.shape[0]
        self.grab = np.asarray(grab, dtype=np.int64).ravel()
        if self.grab.size and (self.grab.min() < 0 or self.grab.max() >= n):
            raise ValueError(f"grabbed nodes must be node ids 0..{n - 1}")
        if np.unique(self.grab).size != self.grab.size:
            raise ValueError("grabbed nodes must be distinct")
        pins = np.zeros(n, dtype=bool) if fixed is None else np.array(fixed, dtype=bool)
        if pins.shape != (n,):
            raise ValueError(f"fixed must be an ({n},) bool array, got shape {pins.shape}")
        self._pins_given = pins.copy()  # the caller's pins without the grabbed nodes
        self._targets_given = None if targets is None or isinstance(targets, Targets) else \
            np.asarray(targets, dtype=np.float64)  # `released`'s (region "folds" takes arrays)
        pins[self.grab] = True
        self.pins = pins
        edges = checked_edges(None, self.fs, n)
        self.free = free_nodes(n, self.fs, pins, edges=edges)
        self._movable = self.free.copy()  # the free and the grabbed nodes (a pull moves them)
        self._movable[self.grab] = True
        used = self.fs.used_nodes(n)
        grabbed = np.zeros(n, dtype=bool)
        grabbed[self.grab] = True
        self.rigid = not self.free.any() and not (used & ~grabbed).any()
        if not self.free.any() and not self.rigid:
            raise ValueError("every node is fixed (boundary or pinned): nothing to optimize")
        self.params = params if params is not None else EEGTParams()
        self._engine_params = live_params(self.params, 1)  # steps read no iteration cap
        self.kept = None if self.rigid or not keep_as_given else \
            self._kept_at(p, grabbed, targets)
        if self.kept is not None:  # the frames measure the faces without the kept vertices
            self.fs = self.kept.measured
            if targets is not None:
                targets = np.asarray(targets, dtype=np.float64)[~self.kept.corner]
            used = self.fs.used_nodes(n)
        self.targets = prepare_targets(targets, self.fs)
        self.points = p.copy()
        still = ~self.free & used
        still[self.grab] = False
        self._still_ids = np.flatnonzero(still)
        self._engine: NumpyEngine | None = None
        self._frame_of: tuple[float, float, float] | None = None  # the still search's frame
        self._still: StillDistances | None = None
        self._given = GivenQuality(self.fs, self.targets)
        self._search: AnchorSearch | None = None  # the frame's distance search
        self.step_seconds = 0.0  # the last frame's time per iteration
        self._tail = 0.0  # the last frame's seconds after its iterations
        self.repair: RegionRepair | None = None  # the escalation (None: EEGT only)
        self.start_inverted = 0  # inverted faces at the drag's start
        self._valid: np.ndarray | None = None  # the last positions with no movable face
        #                                        inverted (a carried start's base) ...
        self._start: np.ndarray | None = None  # ... and the drag's start, when valid
        self._asked: np.ndarray | None = None  # where the cursor put the grabbed nodes last
        self._still_since: float | None = None  # when the cursor stopped there
        self._pull: GrabPull | None = None  # the rest's pull (``core.run.live_pull``) ...
        self._pull_at: tuple | None = None  # ... its base, centre, scale and the cursor's place
        self._pull_tried = False  # ... tried at this rest (its base had no room)
        self.pull_after = pull_after if escalate else None  # seconds of a tangled rest
        #                                                     before the pull (None: never)
        if not self.rigid:
            if escalate:
                self.repair = RegionRepair(self.fs, self.free, self.targets)
            self._prepare()

    def _kept_at(self, p: np.ndarray, grabbed: np.ndarray, targets) -> Kept | None:
        """The corners kept as given (``core.metrics.kept``) at the start, as the one-shot
        run decides them: straight or concave corners of fixed vertices only in simple faces.
        A corner with a grabbed node is never kept (the cursor moves it); prepared
        ``Targets`` keep every corner (the one-shot run's rule)."""
        if isinstance(targets, Targets):
            return None
        center, scale = normalisation(p, self.fs)
        return kept_corners(as_given(p, self.fs, center, scale), self.fs, self.free | grabbed)

    @property
    def held(self) -> int:
        """Faces the escalation gave up on (the largest region solved without progress: a
        fold no move it finds opens, e.g. a grabbed node outside the fixed border)."""
        return 0 if self.repair is None else int(self.repair.held.sum())

    def _engine_at(self, work: np.ndarray, key: tuple[float, float, float]) -> NumpyEngine:
        """The engine restarted at ``work`` (normalised) with the fixed nodes' search: the
        still nodes' distances are kept while the frame's centre and scale stay (a new
        normalisation measures them again)."""
        if self._engine is None:
            self._engine = NumpyEngine.initial_state(work, self.fs, self.free,
                                                     self._engine_params, self.targets)
        if self._frame_of != key:
            self._still = None
            if self._still_ids.size:
                _, min_edge = edge_lengths(work[:, 0], work[:, 1], self.fs.groups)
                cx = np.concatenate([work[g.nodes, 0].mean(0) for g in self.fs.groups])
                cy = np.concatenate([work[g.nodes, 1].mean(0) for g in self.fs.groups])
                self._still = StillDistances(NearestBoundary(
                    work[self._still_ids, 0], work[self._still_ids, 1], cx, cy,
                    min_cell=0.5 * min_edge))
                self._still.query(cx, cy)  # the centroids at the start, measured once
            self._frame_of = key
        self._search = AnchorSearch(self._still, work[self.grab, 0].copy(),
                                    work[self.grab, 1].copy())
        self._engine = self._engine.restarted(work, self._search, keep_quality=True)
        return self._engine

    def _base_ok(self, given: np.ndarray, n_inverted: int) -> bool:
        """Whether the positions ``given`` (``pipeline.as_given``; ``n_inverted`` faces
        inverted) may be a pull's or a carried start's base: no inverted face has a node
        that moves or is grabbed (a face of grabbed and fixed nodes only is frozen while
        the cursor holds them, not once a pull lets them go)."""
        return n_inverted == 0 or \
            n_inverted <= int(frozen_faces(given, self.fs, self._movable).sum())

    def _grab_folded(self, frame: LiveFrame) -> bool:
        """Whether ``frame`` has an inverted face of grabbed and fixed nodes only (frozen
        while the cursor holds them there: a fold only a pull, which lets them go, opens)."""
        if frame.status != "tangled" or not self.grab.size:
            return False
        center, scale = normalisation(frame.points, self.fs)
        return not self._base_ok(as_given(frame.points, self.fs, center, scale),
                                 frame.stats.n_inverted)

    def _stats(self, given: np.ndarray) -> Stats:
        """Stats of the positions as the caller has them (``pipeline.as_given``), the kept
        corners left out as the one-shot run measures them."""
        s = self._given.stats(given)
        if self.kept is None:
            return s
        return stats_of([self.kept.check(given, self._given.q)])

    def finishing(self, frame: LiveFrame | None, out_of_time: bool = False) -> str:
        """What a release (or Enter) after ``frame`` does (``FINISH_*``): keep the result
        (no face a move can change is inverted, and no pull under way), go on with frames
        (the escalation still has a fold to open, the rest's pull has yet to run, or it is
        still bringing the grabbed nodes towards the cursor: a release ends where the drag
        would, however fast the machine got there) or give up (only folds it held are left:
        kept when no more faces are inverted than at the drag's start, else every value
        goes back). ``out_of_time``: the release has gone on for FINISH_LIMIT seconds: a
        pull is kept where it got to, a fold still open gives up."""
        if frame is None:
            return FINISH_KEEP
        if frame.status != "tangled":
            return FINISH_GO_ON if self.pulling and not out_of_time else FINISH_KEEP
        if out_of_time:
            return FINISH_RESTORE
        if self.repair is not None and frame.n_tangled > self.held:
            return FINISH_GO_ON
        if (frame.n_tangled or self._grab_folded(frame)) and (self.pulling or (
                self._pull is None and self._pull_base() is not None)):
            return FINISH_GO_ON  # the rest's pull has not run yet, or runs
        return FINISH_KEEP if frame.stats.n_inverted <= self.start_inverted else FINISH_RESTORE

    @property
    def pulling(self) -> bool:
        """Whether the rest's pull is under way (started, not done)."""
        return self._pull is not None and not self._pull.done

    def released(self, points: np.ndarray) -> np.ndarray | None:
        """The drag's end ``points`` ((N, 2), this session's coordinates) repaired with the
        grabbed nodes let go: a release that cannot open the fold with them at the cursor
        (``finishing`` says restore) keeps the drag this way instead of putting every value
        back. It is the one-shot repair (``untangle_and_smooth``, region "folds": the
        folded faces and a margin grown while needed; the session's pins and targets; every
        other node keeps its bits), so the grabbed nodes move only as far as the fold needs.
        None when that run does not end valid either (or the drag is rigid)."""
        if self.rigid:
            return None
        params = replace(self.params, region="folds", target="regular")
        try:
            res = untangle_and_smooth(np.asarray(points, dtype=np.float64), self.faces,
                                      fixed=self._pins_given, params=params,
                                      targets=self._targets_given)
        except ValueError:
            return None
        if res.status not in ("valid", "untangled"):
            return None
        return np.asarray(res.points, dtype=np.float64)

    def _prepare(self) -> None:
        """The drag's set-up at the start positions: the engine's state and the still nodes'
        search with their distances, so that the first frame costs what later ones do."""
        center, scale = normalisation(self.points, self.fs)
        given = as_given(self.points, self.fs, center, scale)
        self.start_inverted = self._stats(given).n_inverted
        if self._base_ok(given, self.start_inverted):
            self._valid = self._start = self.points
        self._engine_at((self.points - center) / scale,
                        (float(center[0]), float(center[1]), float(scale)))

    def frame(self, grab_to=None, iterations: int = FRAME_ITERATIONS,
              budget: float | None = FRAME_BUDGET) -> LiveFrame:
        """Move the grabbed nodes to ``grab_to`` ((k, 2) in ``grab`` order; None: where the
        last frame was asked to put them), run at most ``iterations`` untangling then
        smoothing iterations from the last frame's positions, stopping once ``budget``
        seconds would be passed (after one iteration at least; None: no time limit; the
        work after the iterations counts, as long as the last frame's took), and keep the
        result as the next frame's start.

        Escalation (``core.run.live_repair``): when the EEGT untangling (half the frame's
        time) leaves a face inverted that a move can change, the rest of the frame goes to
        the foldover-free stage on the region around the inverted faces
        (``RegionRepair.solve``); while the frames start tangled, each gives EEGT its half
        again (a fold it opens ends the escalation) and the region's solve the rest, resuming
        the last one's; once a frame ends with no such face, EEGT smooths on and the
        escalation ends.

        A rest that yields (``core.run.live_pull``): when the cursor has stayed put for
        ``pull_after`` seconds (``PULL_AFTER``; None: never) and the frames still end with a
        movable face inverted, the next frames go back to the last layout with none (or the
        drag's start) and pull the grabbed nodes towards the cursor through valid layouts
        only, as far as the layout lets them (``LiveFrame.held_back``); a move of the
        cursor ends the pull."""
        t0 = time.perf_counter()
        if grab_to is not None:
            asked = np.asarray(grab_to, dtype=np.float64).reshape(-1, 2)
            if self._asked is None or not np.array_equal(asked, self._asked):
                self._asked, self._still_since = asked.copy(), t0  # the cursor moved
                self._pull, self._pull_tried = None, False
        if self._still_since is None:
            self._still_since = t0
        if self._pull is not None:
            return self._pulled(t0, budget)
        out = self._frame(grab_to, iterations, budget, t0)
        if self.pull_after is not None and t0 - self._still_since >= self.pull_after and \
                (out.n_tangled or self._grab_folded(out)):
            self._start_pull()
        return out

    def _start_pull(self) -> None:
        """The rest's pull from the last layout with no movable face inverted (else the
        drag's start) towards where the cursor holds the grabbed nodes; none when there is
        no such layout or no room in it (tried once a rest)."""
        base = self._pull_base()
        if base is None:
            return
        self._pull_tried = True
        center, scale = normalisation(self.points, self.fs)
        target = (self.points[self.grab] - center) / scale
        try:
            self._pull = GrabPull((base - center) / scale, self.fs, self.free, self.grab,
                                  target, self.targets)
        except ValueError:
            return
        self._pull_at = (base, center, scale, self.points[self.grab].copy())

    def _pull_base(self) -> np.ndarray | None:
        """Where a pull would start (the last layout with no movable face inverted, else
        the drag's start); None when no pull may start at this rest (off, tried already, no
        grabbed node or no such layout)."""
        if self.pull_after is None or self._pull_tried or not self.grab.size:
            return None
        return self._valid if self._valid is not None else self._start

    def _pulled(self, t0: float, budget: float | None) -> LiveFrame:
        """A frame of the rest's pull: its solves for the frame's time, the moved nodes
        written over the base (every other node keeps the base's bits); the grabbed nodes
        exactly where the cursor put them once the pull got them there (the pull ends and
        the frames smooth on from there)."""
        pull = self._pull
        base, center, scale, asked = self._pull_at
        step = pull.advance(None if budget is None else t0 + budget - self._tail)
        t_tail = time.perf_counter()
        out = base.copy()
        out[pull.moved] = step.positions * scale + center
        if step.snapped:
            out[self.grab] = asked
            self._pull = None
        given = as_given(out, self.fs, center, scale)
        after = self._stats(given)
        n_tangled = max(after.n_inverted - int(frozen_faces(given, self.fs, self.free).sum()),
                        0)
        if n_tangled == 0:
            self._valid = out
            if self.repair is not None:
                self.repair.reset()
        dx, dy = out[self.grab, 0] - asked[:, 0], out[self.grab, 1] - asked[:, 1]
        held = np.sqrt(dx * dx + dy * dy)
        self.points = out
        status = "tangled" if after.n_inverted else "untangled"
        t1 = time.perf_counter()
        self._tail = t1 - t_tail
        return LiveFrame(out, after, status, 0, 0, t1 - t0, n_tangled,
                         pull_iterations=0 if step.done and not step.iterations
                         else step.iterations, held_back=float(held.max()))

    def _frame(self, grab_to, iterations: int, budget: float | None, t0: float) -> LiveFrame:
        """``frame`` without the rest's pull."""
        p = self.points.copy()
        if grab_to is not None:
            p[self.grab] = np.asarray(grab_to, dtype=np.float64).reshape(-1, 2)
        if not np.isfinite(p).all():
            raise ValueError("grabbed positions must be finite")
        if self.rigid:
            return self._translated(p, t0)
        prm = live_params(self.params, iterations)
        fs, free = self.fs, self.free
        center, scale = normalisation(p, fs)
        work = (p - center) / scale
        given = as_given(p, fs, center, scale)
        frozen = frozen_faces(given, fs, free)
        n_frozen = int(frozen.sum())
        engine = self._engine_at(work, (float(center[0]), float(center[1]), float(scale)))
        clock = Deadline(None if budget is None else t0 + budget - self._tail)
        best = engine.stats()
        engine.save_best()
        current = best
        n_untangle = n_smooth = 0
        timed = clock.timed(lambda phase: self._engine.step(phase))

        def advance(phase: str) -> Stats:
            nonlocal best
            s = timed(phase)
            if s.better_than(best):
                best = s
                self._engine.save_best()
            return s

        def tangled(s: Stats) -> bool:
            return s.n_inverted > n_frozen

        repair = self.repair
        failed, fixed_by = False, None
        if tangled(current):  # EEGT first, also while escalated: a fold it can open (the
            late = clock.late  # region's solve stalled on one) ends the escalation
            if repair is not None and clock.at is not None:  # half the frame, the rest
                mid = t0 + 0.5 * (clock.at - t0)             # for the region if needed

                def late(_s: Stats | None = None) -> bool:
                    return time.perf_counter() + clock.step > mid
            last, n_untangle = untangle_loop(partial(advance, "untangle"), tangled,
                                             prm.max_untangle_iterations, late)
            current = current if last is None else last
            failed = tangled(best)
        if failed and repair is not None:
            # the foldover-free stage on the region: from the last valid frame with the
            # grabbed nodes' move carried around them when the cursor moved (or the
            # escalation starts), else from the last frame, resuming its solve
            start = work
            if grab_to is not None or not repair.active:
                start = self._carried_start(work, center, scale)
                repair.restart()
            fixed_by = repair.solve(start, frozen[repair.elem_face], clock.at)
            failed = fixed_by.n_bad > 0 or repair.held.any()
            if not failed:  # valid: EEGT smooths on from there
                self._engine = self._engine.restarted(fixed_by.points, self._search,
                                                      keep_quality=True)
                current = best = self._engine.stats()
                self._engine.save_best()
        if not failed and not clock.late():
            current, n_smooth = smooth_loop(partial(advance, "smooth"), current, prm,
                                            clock.late)
        engine = self._engine
        t_tail = time.perf_counter()
        before = self._stats(given)
        out, after = p.copy(), before
        # still tangled: the last iterate, so that the next frame goes on from there (the
        # best one may be the frame's start, and the untangling would never get further)
        if failed and fixed_by is not None:  # (its solve resumes from here)
            reached = fixed_by.points
        else:
            reached = engine.points() if failed else engine.best_points()
        changed = np.any(reached != work, axis=1) & free
        out[changed] = reached[changed] * scale + center
        given_out = given
        if changed.any():
            given_out = as_given(out, fs, center, scale)
            after = self._stats(given_out)
            if not failed and not accept(before, after):
                out, after, given_out = p.copy(), before, given
        self.points = out
        if n_untangle + n_smooth:
            self.step_seconds = clock.step
        if repair is not None and not failed and after.n_inverted <= n_frozen:
            repair.reset()
        if not failed and after.n_inverted <= n_frozen and \
                self._base_ok(given_out, after.n_inverted):
            self._valid = out
        status = "tangled" if after.n_inverted else (
            "untangled" if before.n_inverted else "valid")
        t1 = time.perf_counter()
        self._tail = t1 - t_tail
        return LiveFrame(out, after, status, n_untangle, n_smooth, t1 - t0,
                         max(after.n_inverted - n_frozen, 0), fixed_by)

    def _carried_start(self, work: np.ndarray, center: np.ndarray, scale: float
                       ) -> np.ndarray:
        """The region solve's start after a move of the grabbed nodes (normalised): the
        drag's start or the last frame that ended with no movable face inverted, its free
        nodes carried along with the grabbed ones (``live_repair.carried``), whichever has
        fewer inverted faces; ``work`` when there is none."""
        best, fewest = work, None
        for base in (self._start, self._valid):  # the drag's start first: its cells are
            if base is None:                      # as given (the last valid frame's may
                continue                          # be barely valid, flipped by any move)
            out = carried((base - center) / scale, self.grab, work[self.grab], self.free)
            if out is None:
                continue
            n_bad = int(self.repair.bad_elements(out, np.zeros(self.repair.elem_face.size,
                                                                 dtype=bool)).sum())
            if fewest is None or n_bad < fewest:
                best, fewest = out, n_bad
            if n_bad == 0:
                break
        return best

    def _translated(self, p: np.ndarray, t0: float) -> LiveFrame:
        """A rigid session's frame: the grabbed nodes where ``p`` has them, measured; no
        iteration (nothing else can move)."""
        center, scale = normalisation(p, self.fs)
        after = self._given.stats(as_given(p, self.fs, center, scale))
        self.points = p
        status = "tangled" if after.n_inverted else "valid"
        return LiveFrame(p, after, status, 0, 0, time.perf_counter() - t0)


@dataclass(frozen=True)
class UVRegion:
    """What one UV drag moves, as a planar mesh over its own nodes."""

    faces: FaceSet  # the region's faces over local nodes
    nodes: np.ndarray  # (n,) UV vertex of each local node
    face_ids: np.ndarray  # (f,) the region's faces in the UV map
    rows: np.ndarray  # (c,) corner row in the UV map's faces of each local corner
    points: np.ndarray  # (n, 2) oriented positions (mirrored islands reflected)
    mirrored: np.ndarray  # (n,) bool: the node's island is mirrored
    fixed: np.ndarray  # (n,) bool: pinned or on the border of the region
    grab: np.ndarray  # local ids of the grabbed UV vertices

    def to_uv(self, points: np.ndarray) -> np.ndarray:
        """Region positions back to UV values (mirrored islands reflected back)."""
        out = np.array(points, dtype=np.float64)
        out[self.mirrored, 0] *= -1.0
        return out

    def from_uv(self, uv: np.ndarray) -> np.ndarray:
        """UV values (of the region's nodes) to region positions."""
        return self.to_uv(uv)


def uv_region(layout: UVLayout, grab: np.ndarray, selected: np.ndarray | None = None,
              scope: str = "tangles", pins: np.ndarray | None = None,
              points: np.ndarray | None = None) -> UVRegion:
    """The region a drag of the UV vertices ``grab`` moves: the faces of their islands (scope
    "selection": only the ``selected`` faces of them); UV vertices used by a face outside the
    region and ``pins`` stay, as in ``core.uv.uv_untangle.untangle_uv``. ``points``: the UV
    vertices' current values (default the layout's). ValueError (one line) when a grabbed
    UV vertex is in no usable island."""
    grab = np.unique(np.asarray(grab, dtype=np.int64).ravel())
    if grab.size == 0:
        raise ValueError("no UV vertex to grab")
    side = layout.orientation()
    islands = np.unique(layout.node_island[grab])
    if (side[islands] == 0).any():
        raise ValueError("the grabbed UV vertex's island has no UV area: unwrap it first")
    region = np.isin(layout.island, islands)
    if scope == "selection" and selected is not None:
        region &= np.asarray(selected, dtype=bool)
    face_ids = np.flatnonzero(region)
    sub, nodes, rows = island_faces(layout.faces, face_ids)
    keep = np.zeros(layout.n_nodes, dtype=bool) if pins is None else np.array(pins, bool)
    keep[layout.faces.indices[np.repeat(~region, layout.faces.counts)]] = True
    local = np.full(layout.n_nodes, -1, dtype=np.int64)
    local[nodes] = np.arange(nodes.size)
    g = local[grab]
    if (g < 0).any():
        raise ValueError("a grabbed UV vertex is outside the faces that move (select it)")
    pos = layout.oriented_points(side, layout.points if points is None else points)[nodes]
    return UVRegion(sub, nodes, face_ids, rows, pos, side[layout.node_island[nodes]] < 0,
                    keep[nodes], g)


def uv_vertex_corners(layout: UVLayout, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                    np.ndarray]:
    """Every face corner (Blender loop) of the UV vertices ``nodes``: the loops of one mesh
    vertex that Blender's UV editor shows as one UV vertex (``layout.loop_node``), whichever
    face holds them (selected or not, in the region or not). Returns ``faces`` (m,), the
    faces holding one, ascending; ``pick`` (k,), where each such corner is among the corners
    of ``faces`` taken face by face in order; ``local`` (k,), the index in ``nodes`` of its
    UV vertex."""
    nodes = np.asarray(nodes, dtype=np.int64).ravel()
    lut = np.full(layout.n_nodes, -1, dtype=np.int64)
    lut[nodes] = np.arange(nodes.size)
    local = lut[layout.faces.indices]
    rows = np.flatnonzero(local >= 0)
    offsets = layout.faces.offsets
    faces = np.unique(np.searchsorted(offsets, rows, side="right") - 1)
    counts = offsets[faces + 1] - offsets[faces]
    every = np.repeat(offsets[faces] - (np.cumsum(counts) - counts), counts) \
        + np.arange(int(counts.sum()))  # the corner rows of ``faces``, face by face
    return faces, np.searchsorted(every, rows), local[rows]
