"""A repair: untangle the folded faces and a margin around them, nothing else.

Region "folds" (`EEGTParams.region`) runs the whole pipeline on a region: the faces with a
corner that is not positive (and a free node), grown by `FIRST_RINGS` rings of faces. The
region's rim (its nodes on faces outside it) is held, so every node outside keeps its bits
and the cost follows the region, not the mesh. When the fold cannot be opened inside the
region, the margin doubles (`rings` 2, 4, 8, ...) and the run starts again from the input,
until the region is the whole mesh; an attempt on a region smaller than the mesh gets a
budget proportional to its size (`attempt_budget`) and gives up after two untangling rounds
that open too little of the fold (`untangle_and_smooth(attempt=REGION)`: neither the
inverted count nor the worst det halved), with no second start, so a margin too tight for
the fold costs little. Every attempt's untangling rounds end on a plateau of the inverted
count and the worst det (`GlobalOptions.end_round_on_plateau`) instead of at their cap.

Target "keep" (`keep_targets`): every face is pulled towards its own shape as given, so that
the grading, the anisotropy and the sizes the user built survive; a folded face has no shape
of its own to keep, and the faces around it (DRAGGED_RINGS) have the fold's: they take their
reference shape when a reference mesh is given, else a neighbour's across an edge
(`neighbour_shapes`), else the shape their corners have at the harmonic fill of the rest
(a face still unusable there falls back to the regular polygon and is counted). Details:
docs/repair.md.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..fpmath import add_reduce
from ..mesh.csr import ragged_arange
from ..mesh.faces import FaceSet, face_subset, next_corner
from ..metrics.face_quality import inverted_corners, signed_face_areas
from ..params import EEGTParams
from .harmonic import harmonic_positions

__all__ = ["DRAGGED_RINGS", "FIRST_RINGS", "REGION", "WHOLE", "Repaired", "attempt_budget",
           "folded_faces", "grow_region", "keep_targets", "neighbour_shapes", "repair_folds",
           "touching"]

NEIGHBOUR_PASSES = 64  # rings a folded patch takes its shapes across (`neighbour_shapes`)
FIRST_RINGS = 3  # the first margin around the folded faces, in rings of faces
DRAGGED_RINGS = 1  # target "keep": faces this near a folded one lose their own shape too
BUDGET_PER_FACE = 2  # an attempt on a region below the whole mesh: this many optimizer and
BUDGET_MIN = 400  # EEGT iterations per face of the region, at least BUDGET_MIN, at most the
# run's max_untangle_iterations (a margin that is too tight fails in a fraction of a second)
# a repair's attempts, as `untangle_and_smooth(attempt=...)` takes them: on a region smaller
# than the mesh (gives up early, `attempt_budget`), on the whole mesh
REGION, WHOLE = "region", "whole"
ROOM = 0.4  # a region below the whole mesh is tried only when its inverted faces' area is
# at most this x its other faces' (`_has_room`); else the margin doubles first (no first
# margin over 0.36 opened its fold on the repair benchmark: docs/repair.md)


def touching(fs: FaceSet, nodes: np.ndarray) -> np.ndarray:
    """(F,) bool: faces with at least one node in the (N,) bool mask `nodes`."""
    out = np.zeros(fs.n_faces, dtype=bool)
    for g in fs.groups:
        out[g.ids] = nodes[g.nodes].any(axis=0)
    return out


def folded_faces(p: np.ndarray, fs: FaceSet, free: np.ndarray) -> np.ndarray:
    """(F,) bool: faces with a corner that does not turn left and at least one free node
    (the faces a move can change)."""
    return inverted_corners(p, fs) & touching(fs, free)


def grow_region(fs: FaceSet, n_nodes: int, seed: np.ndarray, rings: int) -> np.ndarray:
    """(F,) bool: the faces `seed` and every face within `rings` rings of them (a ring: the
    faces sharing a node with the region)."""
    region = seed.copy()
    for _ in range(rings):
        nodes = np.zeros(n_nodes, dtype=bool)
        for g in fs.groups:
            nodes[g.nodes[:, region[g.ids]]] = True
        grown = region.copy()
        for g in fs.groups:
            grown[g.ids] |= nodes[g.nodes].any(axis=0)
        if np.array_equal(grown, region):
            break
        region = grown
    return region


def attempt_budget(params: EEGTParams, n_region: int, whole: bool) -> int:
    """The iteration budget of one attempt: the run's own on the whole mesh, else
    BUDGET_PER_FACE per face of the region within [BUDGET_MIN, the run's]."""
    top = params.max_untangle_iterations
    if whole:
        return top
    return min(top, max(BUDGET_MIN, BUDGET_PER_FACE * n_region))


def keep_targets(p: np.ndarray, fs: FaceSet, free: np.ndarray, folded: np.ndarray,
                 reference: np.ndarray | None = None) -> np.ndarray:
    """(n_corners, 2) targets of target "keep": every face's own corners as given, except
    the folded faces and those within DRAGGED_RINGS of them (a fold drags the faces around
    it over each other: valid, but their shapes are the fold's, not the user's; kept, they
    fight the repair). Those take their corners from `reference` ((N, 2), same topology)
    when given, else the shape of a neighbour across an edge (`neighbour_shapes`: in a
    boundary layer, the cell beside it has its size and aspect), and a face no neighbour of
    its arity reaches, its corners once their free nodes are at the harmonic fill of the
    rest."""
    corners = np.asarray(p, dtype=np.float64)[fs.indices, :2].copy()
    if not folded.any():
        return corners
    folded = grow_region(fs, p.shape[0], folded, DRAGGED_RINGS)
    rows = np.repeat(folded, fs.counts)
    if reference is not None:
        corners[rows] = np.asarray(reference, dtype=np.float64)[fs.indices[rows], :2]
        return corners
    reached = neighbour_shapes(corners, fs, folded)
    left = folded & ~reached
    if left.any():
        movable = np.zeros(p.shape[0], dtype=bool)
        movable[fs.indices[np.repeat(folded, fs.counts)]] = True
        movable &= free
        filled = harmonic_positions(np.asarray(p, dtype=np.float64)[:, :2], fs, movable)
        lrows = np.repeat(left, fs.counts)
        corners[lrows] = filled[fs.indices[lrows]]
    return corners


def neighbour_shapes(corners: np.ndarray, fs: FaceSet, missing: np.ndarray,
                     passes: int = NEIGHBOUR_PASSES) -> np.ndarray:
    """Give each face in `missing` ((F,) bool) the shape of a face of its arity across one
    of its edges that has one, in place in `corners` ((n_corners, 2) per-corner targets),
    spreading from the faces that have theirs for up to `passes` rings. The neighbour's
    shape is turned half a turn (a point reflection keeps the orientation): its corner that
    starts the shared edge maps to the one that starts it in the face, the rest in cyclic
    order, so a cell of a structured layer gets its neighbour's size and aspect. Returns
    (F,) bool: the faces of `missing` that got one."""
    n = int(fs.indices.max()) + 1 if fs.indices.size else 0
    counts = fs.counts
    face = np.repeat(np.arange(fs.n_faces), counts)
    start = fs.offsets[:-1]
    local = np.arange(fs.indices.size) - start[face]
    a, b = fs.indices.astype(np.int64), fs.indices[next_corner(fs)].astype(np.int64)
    key = a * n + b
    order = np.argsort(key, kind="stable")
    rev = b * n + a
    pos = np.minimum(np.searchsorted(key[order], rev), key.size - 1)
    twin = np.where(key[order][pos] == rev, order[pos], -1)  # the row walking it back
    has = ~missing.copy()
    got = np.zeros(fs.n_faces, dtype=bool)
    for _ in range(passes):
        want = ~has[face] & (twin >= 0)
        ok = want.copy()
        ok[want] = has[face[twin[want]]] & (counts[face[twin[want]]] == counts[face[want]])
        cand = np.flatnonzero(ok)
        if cand.size == 0:
            break
        fsel, first = np.unique(face[cand], return_index=True)
        r, t = cand[first], twin[cand[first]]
        m = counts[fsel]
        step = ragged_arange(np.zeros_like(m), m)
        rr, tt = np.repeat(r, m), np.repeat(t, m)
        ff, gg = np.repeat(fsel, m), face[tt]
        dst = start[ff] + (local[rr] + step) % counts[ff]
        src = start[gg] + (local[tt] + step) % counts[gg]
        corners[dst] = -corners[src]
        has[fsel] = True
        got[fsel] = True
    return got


def _has_room(p: np.ndarray, fs: FaceSet) -> bool:
    """Whether the faces' inverted area is at most ROOM x their valid area. Their signed
    areas add up to the area their rim encloses whatever their free nodes do, so with the
    inverted area as large as the valid one no positions make them all valid
    (core/run/hopeless_groups.py); well before that the valid faces cannot take the fold
    in: on the repair benchmark's 40 cases, every first margin that opened its fold was at
    0.36 or less and every one tried from 0.37 up failed, after 725-3 079 optimizer
    iterations (docs/repair.md)."""
    a = signed_face_areas(p, fs)
    valid = add_reduce(np.maximum(a, 0.0))
    return valid > 0.0 and -add_reduce(np.minimum(a, 0.0)) <= ROOM * valid


Run = Callable[..., Any]


@dataclass(frozen=True)
class Repaired:
    """What `repair_folds` did: the whole mesh's points, the last attempt's result (core
    result of the region), the region's faces (F,) bool, its margin in rings, its FaceSet,
    nodes (its local node -> the mesh's), targets (None: regular polygons) and held
    nodes."""

    points: np.ndarray
    result: Any
    region: np.ndarray
    rings: int
    faces: FaceSet
    nodes: np.ndarray
    targets: np.ndarray | None
    held: np.ndarray  # (n,) bool over the region's nodes: those the run could not move


def repair_folds(p: np.ndarray, fs: FaceSet, free: np.ndarray, params: EEGTParams,
                 targets: np.ndarray | None, run: Run, keep_from: np.ndarray | None = None,
                 seed: np.ndarray | None = None, **run_args: Any) -> Repaired:
    """The loop of region "folds": `run(points, faces, fixed=..., params=...,
    targets=..., attempt=REGION or WHOLE, **run_args)` (core.run.pipeline.untangle_and_smooth
    with region "mesh") on the folded faces grown by FIRST_RINGS, 2 x, 4 x ... rings until an
    attempt leaves no face of the region inverted or the region is the whole mesh.

    `p` (N, 2) float64, `fs` and `free` (N,) bool: the nodes a move may change; `targets`:
    the whole mesh's (n_corners, 2) targets or None (regular polygons), used unless
    `params.target` is "keep"; `keep_from`: with target "keep", the reference mesh or None
    (the folded faces' targets: `keep_targets`, computed on each region); `seed`: the
    folded faces when the caller has them (`folded_faces`)."""
    n = p.shape[0]
    seed = folded_faces(p, fs, free) if seed is None else seed
    sub_params = replace(params, region="mesh", target="regular")
    uses = np.bincount(fs.indices, minlength=n)  # corners at each node: the rim's test
    rings = FIRST_RINGS
    while True:
        region = grow_region(fs, n, seed, rings)
        whole = bool(region.all())
        ids = np.flatnonzero(region)
        sub, nodes, rows = face_subset(fs, ids)
        # the rim: the region's nodes with a corner outside it (in a face not in the region)
        rim = uses[nodes] > np.bincount(sub.indices, minlength=nodes.size)
        held = ~free[nodes] | rim
        if not whole and not _has_room(p[nodes], sub):
            rings *= 2  # the fold's area would not fit in the valid faces' (`_has_room`)
            continue
        if params.target == "keep":
            ref = None if keep_from is None else keep_from[nodes]
            tg = keep_targets(p[nodes], sub, ~held, seed[ids], ref)
        else:
            tg = None if targets is None else targets[rows]
        prm = replace(sub_params, max_untangle_iterations=attempt_budget(params, ids.size,
                                                                          whole))
        res = run(p[nodes], sub, fixed=held, params=prm, targets=tg,
                  attempt=WHOLE if whole else REGION, **run_args)
        if whole or res.status in ("valid", "untangled", "cancelled"):
            out = p.copy()
            if res.status != "cancelled":
                moved = ~held
                out[nodes[moved]] = np.asarray(res.points, dtype=np.float64)[moved, :2]
            return Repaired(out, res, region, rings, sub, nodes, tg, held)
        rings *= 2
