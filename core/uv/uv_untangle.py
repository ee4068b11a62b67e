"""Untangle and smooth the selected faces of a UV map, island by island.

The core (``untangle_and_smooth``) runs on the selected faces of each island that has
something free to move: the island's border (seams, mesh borders), the border of the
selection, every UV vertex also used by an unselected face and the pinned UV vertices stay
where they are. A mirrored island is reflected (u -> -u, exact) before the runs and back after
them, so the core always sees counterclockwise faces. With scope "tangles" only the tangled
faces and a few rings around them run first, grown until they untangle (see
``untangle_uv``); a repair (``repair``: target "Keep Shapes", ``uv_targets``) moves nothing
else. Results are rounded to the UV map's storage type and an island is only
changed when its rounded result is accepted over its input (``core.run.accept`` with the
storage type's ties). A run never claims more than its result: an island whose selected
faces are still inverted at the end is ``failed``, with the reason (``UVResult.message``: how
many faces stay inverted, and whether every corner of them is fixed, so that no move could
change them).

Measures of a selection (``measure``): flipped faces (zero area or against their island's
orientation), inverted faces (flipped, or a reflex or crossed corner: what the core removes),
overlapping faces (share area with another face of the same island, ``uv_overlap``) and the
distortion against the targets (the mean ratio of each face against its target shape: 1 =
similar to its 3D face).

Corners kept as given (``core.metrics.kept``, the mesh path's rule): a straight corner, or a
concave corner of a simple counterclockwise n-gon, whose three UV vertices are all fixed
(island border, pinned, border of the selection) is how the map was made (a knife cut, a
partial loop cut or a bevel, then unwrapped), not a fold: the face is valid and measured
without those vertices, in every measure here, the runs' acceptance, the report and the
overlap check (``kept_as_given``). Decided once from the map as stored (fixed UV vertices
never move). The paper's mode (``untangle="eegt"``, ``keeps_corners``) counts every corner.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from .. import choices
from ..mesh.faces import FaceSet
from ..mesh.topology import boundary_nodes, free_nodes, pinched_faces
from ..metrics.face_quality import Stats, quality, signed_face_areas, stats_of
from ..metrics.kept import Kept, kept_corners, kept_note
from ..params import EEGTParams
from ..run import acceptance
from ..run.pipeline import untangle_and_smooth
from ..run.repair import grow_region
from .uv_layout import UVLayout, island_faces
from .uv_overlap import overlapping_faces

__all__ = [
    "IslandRun",
    "KeptFaces",
    "UVMeasures",
    "UVResult",
    "fixed_uv_vertices",
    "flipped_faces",
    "keeps_corners",
    "kept_as_given",
    "kept_face_mask",
    "measure",
    "overlaps_around",
    "tangled_faces",
    "untangle_uv",
]

Accept = Callable[[Stats, Stats], bool]  # (before, after) -> keep after


@dataclass(frozen=True)
class UVMeasures:
    """What a UV artist asks of a set of faces."""

    n_faces: int
    flipped: int  # signed area against the island's orientation (or zero)
    inverted: int  # no valid shape in the island's orientation: flipped or a reflex corner
    overlapping: int  # share area with another face of their island
    distortion_mean: float  # mean ratio against the targets (flipped count as 0)
    distortion_worst: float  # the lowest one
    zero_area: int = 0  # faces of islands with no area (side unknown: not measured)
    kept: int = 0  # valid faces with a corner kept as given (core.metrics.kept)

    def as_dict(self) -> dict[str, Any]:
        return {"n_faces": self.n_faces, "flipped": self.flipped, "inverted": self.inverted,
                "overlapping": self.overlapping,
                "distortion_mean": self.distortion_mean,
                "distortion_worst": self.distortion_worst, "zero_area": self.zero_area,
                "kept": self.kept}


def keeps_corners(params: EEGTParams | None) -> bool:
    """Whether a run with ``params`` keeps corners as given (``core.metrics.kept``): every
    mode but the paper's (untangle "eegt"), as ``core.run.untangle_and_smooth`` decides."""
    return (params if params is not None else EEGTParams()).untangle != "eegt"


def fixed_uv_vertices(layout: UVLayout, faces: np.ndarray,
                      fixed: np.ndarray | None = None) -> np.ndarray:
    """(V,) bool: the UV vertices a run on the faces ``faces`` (bool (F,)) holds besides the
    borders of its faces: the pins ``fixed`` and every UV vertex of a face outside
    ``faces`` (the border of the selection)."""
    keep = np.zeros(layout.n_nodes, dtype=bool) if fixed is None else \
        np.array(fixed, dtype=bool)
    keep[layout.faces.indices[np.repeat(~np.asarray(faces, dtype=bool),
                                        layout.faces.counts)]] = True
    return keep


def _kept(points: np.ndarray, sub: FaceSet, held: np.ndarray) -> Kept | None:
    """The corners kept as given of the faces ``sub`` at their (oriented) UV vertices
    ``points``: fixed are ``held`` and the nodes of the faces' own border."""
    n = points.shape[0]
    free = sub.used_nodes(n) & ~boundary_nodes(n, sub) & ~held
    return kept_corners(points, sub, free)


class KeptFaces(NamedTuple):
    """Faces of a UV map as one FaceSet (``island_faces``: face ids, UV vertices, corner
    rows; None when there are no faces) and their corners kept as given (None: none, or
    the paper's mode)."""

    ids: np.ndarray
    sub: FaceSet | None
    nodes: np.ndarray
    rows: np.ndarray
    kept: Kept | None


def kept_as_given(layout: UVLayout, faces: np.ndarray | None = None,
                  fixed: np.ndarray | None = None, side: np.ndarray | None = None,
                  keep: bool = True, among: np.ndarray | None = None) -> KeptFaces:
    """The faces of the mask ``among`` (default ``faces``) in islands with area, and their
    corners kept as given (``core.metrics.kept.kept_corners``) for a run on the faces
    ``faces`` (default every face) with the pins ``fixed``: fixed are the island borders,
    the border of ``faces`` and the pins. Judged at the map's own points (oriented): the
    fixed UV vertices are the ones no run moves. ``keep`` False (the paper's mode): none."""
    side = layout.orientation() if side is None else side
    n_faces = layout.faces.n_faces
    faces = np.ones(n_faces, dtype=bool) if faces is None else np.asarray(faces, dtype=bool)
    among = faces if among is None else np.asarray(among, dtype=bool)
    ids = np.flatnonzero(among & (side[layout.island] != 0))
    if ids.size == 0:
        empty = np.zeros(0, dtype=np.int64)
        return KeptFaces(ids, None, empty, empty, None)
    sub, nodes, rows = island_faces(layout.faces, ids)
    kept = None
    if keep:
        held = fixed_uv_vertices(layout, faces, fixed)[nodes]
        kept = _kept(layout.oriented_points(side)[nodes], sub, held)
    return KeptFaces(ids, sub, nodes, rows, kept)


def kept_face_mask(layout: UVLayout, found: KeptFaces) -> np.ndarray:
    """(F,) bool: the faces of ``found`` with a corner kept as given."""
    out = np.zeros(layout.faces.n_faces, dtype=bool)
    if found.kept is not None:
        out[found.ids[found.kept.ids]] = True
    return out


def overlaps_around(layout: UVLayout, points: np.ndarray, faces: np.ndarray,
                    side: np.ndarray | None = None, fixed: np.ndarray | None = None,
                    keep: bool = True) -> np.ndarray:
    """(F,) bool: faces of the islands that ``faces`` touch that overlap another face of
    their island (selected or not), at UV vertex ``points`` (as stored). Faces with a corner
    kept as given (``kept_as_given`` for a run on ``faces`` with the pins ``fixed``) are
    covered by their own polygon (a concave n-gon is not fanned across its notch)."""
    side = layout.orientation() if side is None else side
    faces = np.asarray(faces, dtype=bool)
    around = np.isin(layout.island, np.unique(layout.island[faces]))
    exact = kept_face_mask(layout, kept_as_given(layout, faces, fixed, side, keep, around))
    return overlapping_faces(layout.oriented_points(side, points), layout.faces, layout.island,
                             faces=around, exact=exact)


def measure(layout: UVLayout, points: np.ndarray, faces: np.ndarray,
            targets: np.ndarray | None = None, side: np.ndarray | None = None,
            overlap: np.ndarray | None = None, fixed: np.ndarray | None = None,
            keep: bool = True) -> UVMeasures:
    """Measures of the faces in the bool mask ``faces`` at UV vertex ``points`` (as stored,
    unmirrored). ``targets``: (C, 2) rows in ``layout.faces`` corner order, or None;
    ``overlap``: ``overlaps_around`` of the same points when already known. Corners kept as
    given (``kept_as_given`` for a run on ``faces`` with the pins ``fixed``; ``keep`` False:
    the paper's mode, none) are left out of the distortion and do not make a face inverted."""
    side = layout.orientation() if side is None else side
    faces = np.asarray(faces, dtype=bool)
    zero = faces & (side[layout.island] == 0)
    found = kept_as_given(layout, faces, fixed, side, keep)
    ids, sub, nodes, rows, kept = found
    if ids.size == 0:
        return UVMeasures(0, 0, 0, 0, 0.0, 0.0, int(zero.sum()))
    p = layout.oriented_points(side, points)
    q = quality(p[nodes], sub, targets=None if targets is None else targets[rows], kept=kept)
    s = stats_of([q])
    over = overlaps_around(layout, points, faces, side, fixed, keep) if overlap is None \
        else overlap
    flipped = int(np.count_nonzero(signed_face_areas(p[nodes], sub) <= 0.0))
    chosen = np.zeros(layout.faces.n_faces, dtype=bool)
    chosen[ids] = True
    return UVMeasures(int(ids.size), flipped, int(s.n_inverted),
                      int(np.count_nonzero(over & chosen)), float(s.q_avg), float(s.q_min),
                      int(zero.sum()), 0 if kept is None else kept.n_faces)


def flipped_faces(layout: UVLayout, points: np.ndarray, side: np.ndarray | None = None,
                  corners: bool = False, fixed: np.ndarray | None = None,
                  faces: np.ndarray | None = None, keep: bool = True) -> np.ndarray:
    """(F,) bool: faces whose signed area is zero or against their island's orientation;
    with ``corners`` also those with a reflex or crossed corner (the inverted faces the core
    removes), but for the corners kept as given (``kept_as_given`` for a run on ``faces``,
    default every face, with the pins ``fixed``; ``keep`` False: the paper's mode, none).
    Islands without area have none."""
    side = layout.orientation() if side is None else side
    p = layout.oriented_points(side, points)
    bad = signed_face_areas(p, layout.faces) <= 0.0
    if corners:
        ids, sub, nodes, _, kept = kept_as_given(layout, faces, fixed, side, keep,
                                                 np.ones(layout.faces.n_faces, dtype=bool))
        if sub is not None:
            bad[ids] |= quality(p[nodes], sub, kept=kept) <= 0.0
    return bad & (side[layout.island] != 0)


@dataclass
class IslandRun:
    """One island's run."""

    island: int
    n_faces: int
    mirrored: bool
    status: str  # valid | untangled | failed | error | skipped
    message: str = ""
    n_free: int = 0
    before: Stats | None = None
    after: Stats | None = None
    changed: bool = False
    untangle_iterations: int = 0
    smooth_iterations: int = 0
    global_iterations: int = 0
    n_frozen: int = 0
    n_target_fallback: int = 0
    n_kept: int = 0  # selected faces with a corner kept as given (core.metrics.kept)
    seconds: float = 0.0
    inverted_left: int = 0  # selected faces still inverted at the end
    stuck: int = 0  # ... of them with every corner fixed (pinned, border): no move helps


@dataclass
class UVResult:
    """Outcome of ``untangle_uv``: the UV vertex positions to store and what happened."""

    points: np.ndarray  # (V, 2) float64 holding values of the storage type
    moved: np.ndarray  # (V,) bool: UV vertices whose stored value changes
    status: str  # valid | untangled | failed | cancelled
    islands: list[IslandRun] = field(default_factory=list)
    seconds: float = 0.0
    backend: str = ""
    notes: list[str] = field(default_factory=list)
    message: str = ""  # why it failed: the faces that stay inverted and why
    kept: Kept | None = None  # the selection's corners kept as given (``kept_as_given``)

    @property
    def n_kept(self) -> int:
        """Selected faces with a corner kept as given: valid, measured without it."""
        return 0 if self.kept is None else self.kept.n_faces

    @property
    def n_free(self) -> int:
        return sum(r.n_free for r in self.islands)

    @property
    def n_target_fallback(self) -> int:
        return sum(r.n_target_fallback for r in self.islands)

    @property
    def iterations(self) -> tuple[int, int, int]:
        """(untangle, global, smooth) iterations summed over the islands."""
        return (sum(r.untangle_iterations for r in self.islands),
                sum(r.global_iterations for r in self.islands),
                sum(r.smooth_iterations for r in self.islands))


SCOPES = choices.ids(choices.UV_SCOPE)


def tangled_faces(layout: UVLayout, points: np.ndarray, faces: np.ndarray,
                  side: np.ndarray | None = None, overlap: np.ndarray | None = None,
                  fixed: np.ndarray | None = None, keep: bool = True) -> np.ndarray:
    """(F,) bool: the faces (among the mask ``faces``) that are inverted in their island's
    orientation (corners kept as given are not, as in ``flipped_faces``) or overlap another
    face of their island (``overlap``: ``overlaps_around`` when known): where untangling has
    to work."""
    side = layout.orientation() if side is None else side
    faces = np.asarray(faces, dtype=bool)
    bad = flipped_faces(layout, points, side, corners=True, fixed=fixed, faces=faces,
                        keep=keep)
    bad |= overlaps_around(layout, points, faces, side, fixed, keep) if overlap is None \
        else overlap
    return bad & faces


REGION_SHARE = 0.75  # a region over this share of the island's faces: run the whole island


def _regions(sub: FaceSet, bad: np.ndarray | None, rings: int) -> list[np.ndarray]:
    """The face sets to try, smallest first: the tangled faces grown by ``rings``, 4
    ``rings``, 16 ``rings``, ... rings while under REGION_SHARE of the island, then every face
    (the only one for an island without tangles, or with tangles nearly everywhere)."""
    every = np.ones(sub.n_faces, dtype=bool)
    if bad is None or not bad.any():
        return [every]
    n_nodes = int(sub.indices.max()) + 1
    out, r = [], rings
    while True:
        region = grow_region(sub, n_nodes, bad, r)
        if region.sum() > REGION_SHARE * sub.n_faces:
            break
        out.append(region)
        r *= 4
    return [*out, every]


@dataclass
class _Attempt:
    """One core run on part of an island, as island coordinates and island stats."""

    points: np.ndarray  # (n, 2) island UV vertices (oriented), storable values
    after: Stats
    result: Any
    free: np.ndarray
    improved: bool = True  # fewer inverted faces than the attempt before
    part: str = ""  # " (k of n faces)" for a run on part of the island


def untangle_uv(layout: UVLayout, selected: np.ndarray, fixed: np.ndarray | None = None,
                targets: np.ndarray | None = None, params: EEGTParams | None = None,
                backend: str = "numpy", progress: Callable[[int, str, Any], Any] | None = None,
                store: type = np.float32, accept: Accept | None = None,
                scope: str = "tangles", tangled: np.ndarray | None = None,
                rings: int = 2, repair: bool = False, shapes: str = "3D") -> UVResult:
    """Untangle and smooth the ``selected`` faces (bool (F,)) of a welded UV map.

    ``fixed``: (V,) extra UV vertices that must not move (pins). ``targets``: (C, 2) target
    corner rows in ``layout.faces`` order, or None for regular polygons. ``scope``:
    "tangles" (an island with tangled faces, ``tangled_faces`` or the mask ``tangled``, only
    moves them and the faces within ``rings`` rings of them, the rings doubled until it
    untangles or the whole selection of the island is in; an island without tangles is
    smoothed as a whole) or "selection" (every selected face moves). Results are rounded to
    ``store`` and an island changes only when its rounded stats are accepted over its input
    stats, both over its selected faces: ``core.run.accept(before, after, store)`` (float32:
    qualities within 1e-6 tie and keep the input), or ``accept(before, after)`` when given.
    Corners kept as given (``kept_as_given``: straight or concave corners of fixed UV
    vertices only; not in the paper's mode, ``keeps_corners``) leave their faces valid in
    every measure, as the core's runs do (``keep_as_given``).
    ``repair`` (target "Keep Shapes", ``uv_targets.keep_shape_targets``) with scope
    "tangles": only the tangled faces and their margin move, nothing else: an island without
    tangles is left as it is and an untangled island is not smoothed as a whole afterwards,
    so every UV vertex outside the region keeps its bits. ``shapes`` names the targets'
    shapes in the note on targets that fell back to the regular polygon.
    ValueError (one line) when nothing can move: no face selected, only islands without area,
    or every selected UV vertex fixed.
    """
    t0 = time.perf_counter()
    selected = _checked_selection(layout, selected, scope)
    side = layout.orientation()
    keep = fixed_uv_vertices(layout, selected, fixed)
    keep_corners = keeps_corners(params)
    if scope == "tangles" and tangled is None:
        tangled = tangled_faces(layout, layout.points, selected, side, fixed=fixed,
                                keep=keep_corners)
    work = layout.oriented_points(side, layout.points)
    out = layout.points.copy()
    moved = np.zeros(layout.n_nodes, dtype=bool)
    runs: list[IslandRun] = []
    groups = _selected_by_island(layout, selected)
    backend_name = ""
    spared = 0  # islands without tangles a repair leaves as they are
    for k, ids in enumerate(groups):
        isl = int(layout.island[ids[0]])
        run = IslandRun(isl, int(ids.size), bool(side[isl] < 0), "skipped")
        runs.append(run)
        if side[isl] == 0:
            run.message = "no UV area (collapsed to a point or a line): unwrap it first"
            continue
        sub, nodes, rows = island_faces(layout.faces, ids)
        tk = None if targets is None else targets[rows]
        start = work[nodes]
        kept = _kept(start, sub, keep[nodes]) if keep_corners else None
        run.n_kept = 0 if kept is None else kept.n_faces
        run.before = run.after = stats_of([quality(start, sub, targets=tk, kept=kept)])
        label = f"island {k + 1}/{len(groups)}"
        bad = None if scope == "selection" else tangled[ids]
        if repair and bad is not None and not bad.any():
            run.status, run.message = "valid", "no tangles: island kept as laid out"
            spared += 1
            continue
        try:
            best = _island(sub, start, keep[nodes], tk, _regions(sub, bad, rings), params,
                           backend, progress, label, store, run, scope == "tangles", kept,
                           smooth_whole=not repair)
        except _Cancel:
            result = UVResult(layout.points.copy(), np.zeros_like(moved), "cancelled", runs,
                              time.perf_counter() - t0, backend_name or backend)
            return result
        if best is None:
            continue
        backend_name = backend_name or str(best.result.backend)
        change = np.any(best.points != start, axis=1)
        if not change.any():
            continue
        kept = acceptance.accept(run.before, best.after, store) if accept is None else \
            accept(run.before, best.after)
        if not kept:
            run.message += "; no improvement once stored: island unchanged"
            if run.status == "untangled":  # the stored result would keep a flipped face
                run.status = "failed"
            continue
        run.after, run.changed = best.after, True
        back = best.points.copy()
        if side[isl] < 0:
            back[:, 0] *= -1.0
        out[nodes[change]] = back[change]
        moved[nodes[change]] = True
    result = UVResult(out, moved, "cancelled", runs, time.perf_counter() - t0,
                      backend_name or backend)
    if not spared and not any(r.n_free for r in runs):
        reasons = {r.message for r in runs if r.message}
        raise ValueError("nothing to move: " + "; ".join(sorted(reasons))
                         if reasons else "nothing to move")
    found = kept_as_given(layout, selected, fixed, side, keep_corners)
    result.kept = found.kept
    result.message = _settle(layout, out, found, side, keep, fixed, targets, runs)
    result.status = _overall(runs)
    result.notes = _notes(runs, shapes)
    if found.kept is not None:
        result.notes.append(kept_note(found.kept))
    return result


def _checked_selection(layout: UVLayout, selected, scope: str) -> np.ndarray:
    """The selection as a (F,) bool array; ValueError (one line) for a wrong shape, an empty
    selection or an unknown scope."""
    selected = np.asarray(selected, dtype=bool)
    if selected.shape != (layout.faces.n_faces,):
        raise ValueError(f"selected must be a ({layout.faces.n_faces},) bool array")
    if not selected.any():
        raise ValueError("no UV faces selected")
    if scope not in SCOPES:
        raise ValueError(f"scope must be one of {', '.join(SCOPES)}, got {scope!r}")
    return selected


def _selected_by_island(layout: UVLayout, selected: np.ndarray) -> list[np.ndarray]:
    """The selected face ids, one array per island, islands in increasing order."""
    sel_ids = np.flatnonzero(selected)
    sel_ids = sel_ids[np.argsort(layout.island[sel_ids], kind="stable")]
    return np.split(sel_ids, np.flatnonzero(np.diff(layout.island[sel_ids])) + 1)


def _settle(layout: UVLayout, points: np.ndarray, found: KeptFaces, side: np.ndarray,
            keep: np.ndarray, pins: np.ndarray | None, targets: np.ndarray | None,
            runs: list[IslandRun]) -> str:
    """Mark ``failed`` every island whose selected faces (with area: ``found``, with their
    corners kept as given) are still inverted at the final ``points``, measured as
    ``measure`` does; the reason, "" when none is left.
    Why a face stays: every corner of it is fixed (``keep``: pins and the selection's
    border, or an island border), so no move changes it; or a corner of it inside the island
    is used by two faces only, which cannot both be convex there (their angles at it add up
    to a full turn); else the engine could not untangle it."""
    ids, sub, nodes, rows, kept = found
    q = quality(layout.oriented_points(side, points)[nodes], sub,
                targets=None if targets is None else targets[rows], kept=kept)
    bad = q == 0.0  # what stats_of counts as inverted
    if not bad.any():
        return ""
    border = boundary_nodes(layout.n_nodes, layout.faces)
    corner = nodes[sub.indices]  # global UV vertex of every corner of ``sub``
    face_of = np.repeat(np.arange(sub.n_faces), sub.counts)
    loose = np.zeros(sub.n_faces, dtype=bool)  # a corner that could move
    np.logical_or.at(loose, face_of, ~(keep | border)[corner])
    pair = pinched_faces(layout.faces, layout.n_nodes, border)[ids]  # inner corner of two faces
    stuck = bad & ~loose
    pair &= bad & ~stuck
    isl = layout.island[ids]
    left = np.bincount(isl[bad], minlength=layout.n_islands)
    held = np.bincount(isl[stuck], minlength=layout.n_islands)
    for r in runs:
        r.inverted_left, r.stuck = int(left[r.island]), int(held[r.island])
        if r.inverted_left and r.status != "error":
            r.status = "failed"
    pinned = np.zeros(layout.n_nodes, dtype=bool) if pins is None else np.asarray(pins, bool)
    at = corner[np.repeat(stuck, sub.counts)]
    kinds = [name for name, on in (
        ("pinned", pinned[at].any()), ("on an island border", border[at].any()),
        ("on the border of the selection", (keep & ~pinned & ~border)[at].any())) if on]
    fixed = ", ".join(kinds[:-1]) + " or " + kinds[-1] if len(kinds) > 1 else "".join(kinds)
    n_stuck, n_pair = int(stuck.sum()), int(pair.sum())
    parts = [(n_stuck, f"every corner of them is {fixed}", f"with every corner {fixed}"),
             (n_pair, "a corner of them is used by two faces only (both cannot be convex)",
              "with a corner used by two faces only (both cannot be convex)"),
             (int(bad.sum()) - n_stuck - n_pair, "the engine could not untangle them",
              "the engine could not untangle")]
    parts = [p for p in parts if p[0]]
    why = parts[0][1] if len(parts) == 1 else ", ".join(f"{k} {short}" for k, _, short in parts)
    n = int(bad.sum())
    if n == 1:
        return f"1 face stays inverted: {why.replace(' of them', ' of it').replace(' them', ' it')}"
    return f"{n} faces stay inverted: {why}"


class _Cancel(Exception):
    pass


WHOLE_ROUNDS = 3  # runs on a whole island that keeps inverted faces, while they decrease


def _both_better(after: Stats, before: Stats) -> bool:
    """No more inverted faces, and neither the worst nor the mean quality lower, one higher:
    what a smoothing-only run must reach under scope "tangles"."""
    return (after.n_inverted <= before.n_inverted and after.q_min >= before.q_min
            and after.q_avg >= before.q_avg and (after.q_min, after.q_avg)
            != (before.q_min, before.q_avg))


class _Island:
    """The runs of the core on one island's selected faces (island coordinates, oriented)."""

    def __init__(self, sub: FaceSet, start: np.ndarray, pin: np.ndarray,
                 tk: np.ndarray | None, params: EEGTParams | None, backend: str,
                 progress: Callable[[int, str, Any], Any] | None, label: str, store: type,
                 run: IslandRun, kept: Kept | None = None) -> None:
        self.sub, self.start, self.pin, self.tk = sub, start, pin, tk
        self.params, self.backend, self.progress, self.label = params, backend, progress, label
        self.store, self.run, self.kept = store, run, kept

    def attempt(self, region: np.ndarray, base: np.ndarray) -> _Attempt | None:
        """One core run on the faces ``region`` from ``base``, the rest fixed; None when
        nothing in it is free. ValueError (one line) from the core; _Cancel when stopped."""
        sub, run = self.sub, self.run
        whole = bool(region.all())
        part = "" if whole else f" ({int(region.sum())} of {sub.n_faces} faces)"
        part_fs, local, prow = island_faces(sub, np.flatnonzero(region))
        out_nodes = np.zeros(base.shape[0], dtype=bool)
        out_nodes[sub.indices[np.repeat(~region, sub.counts)]] = True
        part_pin = self.pin[local] | out_nodes[local]
        free = free_nodes(local.size, part_fs, part_pin)
        if not free.any():
            return None
        progress = self.progress

        def relay(it: int, phase: str, stats: Any, _label: str = self.label + part) -> Any:
            return progress(it, f"{_label} {phase}", stats)

        res = untangle_and_smooth(base[local], part_fs, fixed=part_pin, params=self.params,
                                  backend=self.backend, progress=relay if progress else None,
                                  targets=None if self.tk is None else self.tk[prow],
                                  keep_as_given=self.kept is not None)
        if res.status == "cancelled":
            raise _Cancel
        run.untangle_iterations += int(res.untangle_iterations)
        run.smooth_iterations += int(res.smooth_iterations)
        run.global_iterations += int(getattr(res, "global_iterations", 0))
        run.n_target_fallback = max(run.n_target_fallback,
                                    int(getattr(res, "n_target_fallback", 0)))
        run.seconds += float(res.seconds)
        pts = base.copy()
        rounded = np.asarray(res.points).astype(self.store).astype(np.float64)
        pts[local[free]] = rounded[free]
        after = stats_of([quality(pts, sub, targets=self.tk, kept=self.kept)])
        attempt = _Attempt(pts, after, res, free)
        attempt.part = part
        return attempt

    def keep(self, attempt: _Attempt) -> None:
        """Make ``attempt`` the island's result in its run record."""
        run, res = self.run, attempt.result
        run.status, run.message = str(res.status), str(res.message) + attempt.part
        run.n_free = int(attempt.free.sum())
        run.n_frozen = int(getattr(res, "n_frozen", 0))


def _island(sub: FaceSet, start: np.ndarray, pin: np.ndarray, tk: np.ndarray | None,
            regions: list[np.ndarray], params: EEGTParams | None, backend: str,
            progress: Callable[[int, str, Any], Any] | None, label: str, store: type,
            run: IslandRun, smooth_both: bool = False, kept: Kept | None = None,
            smooth_whole: bool = True) -> _Attempt | None:
    """Run the core on one island's selected faces, region after region, each from the best
    result so far, until one ends untangled; a whole island that still has inverted faces
    runs again from its best while their number decreases (up to WHOLE_ROUNDS runs). With
    ``smooth_both`` (scope "tangles") a run that only smooths (an island without inverted
    faces, or the whole island once more after its tangles were undone) is kept only when
    neither the worst nor the mean quality drops (``_both_better``); ``smooth_whole`` False
    (a repair) leaves out that last run on the whole island. The best attempt
    (island stats, the corners ``kept`` as given left out), or None when nothing changes.
    Fills ``run``; _Cancel when stopped."""
    isl = _Island(sub, start, pin, tk, params, backend, progress, label, store, run, kept)
    initial = run.before
    best: _Attempt | None = None
    whole_runs = 0
    try:
        for region in [*regions[:-1], *[regions[-1]] * WHOLE_ROUNDS]:
            whole = bool(region.all())
            if whole and whole_runs and best is not None and (
                    best.after.n_inverted <= run.n_frozen or not best.improved):
                break
            whole_runs += whole
            attempt = isl.attempt(region, start if best is None else best.points)
            if attempt is None:
                continue
            if best is None or attempt.after.better_than(best.after):
                attempt.improved = best is None or (attempt.after.n_inverted
                                                    < best.after.n_inverted)
                best = attempt
                isl.keep(best)
            elif whole:
                best.improved = False
            if attempt.result.status in ("valid", "untangled") and \
                    attempt.after.n_inverted <= run.n_frozen:
                break
        if best is None and not run.n_free:
            run.message = ("every UV vertex is fixed (on an island border, pinned or on the "
                           "border of the selection: grow the selection, Select > More)")
            return None
        if smooth_both and best is not None:
            if initial.n_inverted == 0:  # only smoothed: both qualities must hold
                if not _both_better(best.after, initial):
                    run.status, run.message = "valid", "smoothing would lower the worst or " \
                        "the mean quality: island unchanged"
                    return None
            elif best.after.n_inverted <= run.n_frozen and smooth_whole:
                # untangled: smooth it all again
                whole = isl.attempt(np.ones(sub.n_faces, dtype=bool), best.points)
                if whole is not None and _both_better(whole.after, best.after):
                    where = "in a region" if best.part else "first"
                    best = whole
                    isl.keep(best)
                    run.status = "untangled"
                    run.message += f" (untangled {where}, then smoothed whole)"
    except ValueError as exc:
        run.status, run.message = "error", _line(exc)
        return best
    if best is not None and best.after.n_inverted > run.n_frozen:
        run.status = "failed"
    return best


def _line(exc: Exception) -> str:
    text = str(exc)
    return text.splitlines()[0] if text else type(exc).__name__


def _overall(runs: list[IslandRun]) -> str:
    """failed when an island ends with an inverted selected face (``_settle``) or errs;
    untangled when some island had inverted faces; else valid."""
    if any(r.status in ("failed", "error") for r in runs):
        return "failed"
    if any(r.before is not None and r.before.n_inverted > 0 for r in runs):
        return "untangled"
    return "valid"


def _notes(runs: list[IslandRun], shapes: str = "3D") -> list[str]:
    """One note per kind of island problem (counts, not one line per island); ``shapes``
    names the targets' shapes."""
    notes = []
    skipped = [r for r in runs if r.status == "skipped" and r.n_free == 0 and r.before is None]
    if skipped:
        notes.append(f"{len(skipped)} island(s) without UV area skipped (unwrap them first)")
    for r in runs:
        if r.status == "error":
            notes.append(f"island {r.island}: {r.message}")
    failed = [r for r in runs if r.status == "failed"]
    if len(failed) > 1:
        notes.append("inverted faces left in islands " + ", ".join(
            f"{r.island} ({r.inverted_left})" for r in failed))
    mirrored = sum(1 for r in runs if r.mirrored)
    if mirrored:
        notes.append(f"{mirrored} mirrored island(s)")
    fallback = sum(r.n_target_fallback for r in runs)
    if fallback:
        notes.append(f"{fallback} faces with a concave or degenerate {shapes} shape used "
                     "the regular polygon as target")
    return notes
