# SPDX-License-Identifier: GPL-3.0-or-later
"""The single-file command's solver mesh part (docs/engineers.md): the checks of the solver
flags and paths, then the whole run on the file's own numbers, with no Blender mesh between:

read (``fileio.solver_mesh``) -> nodes the flags pin -> the core's 3D entry in float64 on
the file's points (a 2D file gets z = 0; the plane and its orientation are the mesh's vector
area, as everywhere) -> write through ``fileio.checked_write`` to a temporary file beside the
output -> read back -> judged by ``core.run.accept`` on the numbers read back (a result no
better than the input is written unchanged) -> the caller renames it into place.

The run sees the faces consistently oriented: FEM files often store element nodes
clockwise, or some clockwise and some not, and the core needs every interior edge walked
once each way. `plan` reverses, in memory only, the faces that go against their
component's orientation, each component counterclockwise (``core.mesh.orient_faces``: by
topology, so folded faces stay folded), and says in the report how many faces were read
clockwise; the written file keeps its own cells and node order. A surface that cannot be
oriented (a Moebius-like strip) is refused.

Everything is decided before the work (`plan`): the input read, the groups and the pin
field, the reference, that some node can move, that the mesh is planar, and that the output
format can hold the input (a dry write of the input mesh to a temporary file beside the
output, read back and removed). Every problem there is a :class:`UsageError` of one line
(exit 2), nothing written. The report's before / after are the input file's and the written
file's own counts (each measured in float64, centred and scaled by a power of two, so any
finite coordinates from 1e-300 to 1e300, far from the origin or not, are measured alike).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
from typing import Any

import numpy as np

from ...core import (
    EEGTParams,
    FaceSet,
    PlaneFrame,
    Stats,
    boundary_nodes,
    faces_from_csr,
    free_nodes,
    mesh_stats,
    summaries,
)
from ...core.mesh import orient_faces
from ...core.metrics import reference_targets, reference_to_2d
from ...core.run import accept, folded_faces, frozen_note, keep_targets, untangle_and_smooth_3d
from ...fileio import checked_write, solver_mesh
from ...fileio.solver_formats import SOLVER_EXTENSIONS, solver_format
from ..mesh import reference_mesh, runner
from ..shared.progress import Progress
from .usage import UsageError

PLANE_TOL = runner.PLANE_TOL


def is_solver(path: str | None) -> bool:
    """Whether `path` names a solver mesh by its extension."""
    return bool(path) and solver_format(path) is not None


def check_paths(ns: argparse.Namespace) -> None:
    """Solver flags only with a solver input, and never empty; a solver output only from a
    solver input (its blocks and data come from there); --pin-field not with --no-pinned;
    no --uv."""
    solver_in = is_solver(ns.input)
    given = [(f, v) for f, v in (("--pin-field", ns.pin_field),
                                 ("--fixed-groups", ns.fixed_groups),
                                 ("--slide-groups", ns.slide_groups)) if v is not None]
    if given and not solver_in:
        raise UsageError(f"eegt: {given[0][0]} needs a solver mesh input "
                         f"({', '.join(SOLVER_EXTENSIONS)})")
    for flag, value in given:
        empty = not value.strip() if flag == "--pin-field" else \
            not solver_mesh.parse_groups(value)
        if empty:
            what = "a point-data array name" if flag == "--pin-field" else \
                "a comma list of group names or tags"
            raise UsageError(f"eegt: {flag} '{value}' names nothing: give {what}")
    if ns.pin_field is not None and ns.no_pinned:
        raise UsageError("eegt: give --pin-field or --no-pinned, not both")
    if is_solver(ns.output) and not solver_in:
        raise UsageError(f"eegt: a solver mesh output ('{ns.output}') needs a solver mesh "
                         "input: its other blocks, data and groups come from there")
    if solver_in and ns.uv is not None:
        raise UsageError("eegt: --uv works on .blend, .obj, .ply and .stl meshes")
    if solver_in and ns.reference_key:
        raise UsageError("eegt: --reference-key names a Blender shape key: a solver mesh takes "
                         "--reference FILE")


@dataclasses.dataclass
class Plane:
    """How a file's points are measured: centred and scaled by a power of two (exact for
    the scale; any finite coordinates), then seen in the mesh's plane."""

    center: np.ndarray  # (3,)
    scale: float
    frame: PlaneFrame

    def to_2d(self, points3d: np.ndarray) -> np.ndarray:
        """(N, 2) float64 in-plane coordinates of (N, 3) points."""
        return self.frame.to_2d((np.asarray(points3d, dtype=np.float64) - self.center)
                                / self.scale)


def _normalised(points3d: np.ndarray, fs: FaceSet) -> tuple[np.ndarray, float]:
    """(centre, power-of-two scale) mapping the faces' nodes into [-1, 1]^3, without
    overflow up to 1e308."""
    used = points3d[fs.used_nodes(points3d.shape[0])]
    lo, hi = used.min(axis=0), used.max(axis=0)
    center = 0.5 * lo + 0.5 * hi
    half = float(np.max(0.5 * hi - 0.5 * lo))
    return center, (math.ldexp(1.0, math.frexp(half)[1]) if half > 0.0 else 1.0)


def fit_plane(points3d: np.ndarray, fs: FaceSet, fixed: np.ndarray | None = None,
              project: bool = False) -> Plane:
    """The `Plane` of a mesh (ValueError, one line, when it is not planar or has no
    area)."""
    center, scale = _normalised(points3d, fs)
    frame = PlaneFrame.fit((points3d - center) / scale, fs, tol=PLANE_TOL, project=project,
                           fixed=fixed)
    return Plane(center, scale, frame)


REPAIR = {"target": "keep", "region": "folds"}  # a solver mesh's defaults: a repair that
# keeps every cell as built outside the folds (--target regular --region mesh: the paper's)


def judge_targets(points2d: np.ndarray, fs: FaceSet, movable: np.ndarray,
                  reference2d: np.ndarray | None = None) -> np.ndarray:
    """Target "keep"'s per-corner targets for judging the file: the run's own rule
    (core.run.keep_targets: each face's own corners, the folded faces and those they drag
    a neighbour's or the reference's shape)."""
    return keep_targets(points2d, fs, movable, folded_faces(points2d, fs, movable),
                        reference2d)


@dataclasses.dataclass
class SolverPlan:
    """Everything the run needs, decided before it starts."""

    sm: solver_mesh.SolverMesh
    name: str
    faces: FaceSet  # the file's 2D cells, consistently oriented (counterclockwise)
    fixed: np.ndarray | None  # (N,) pinned nodes (None: --no-pinned)
    plane: Plane
    points2d: np.ndarray  # (N, 2) the input in its plane
    before: Stats  # the input file's own counts
    reference: np.ndarray | None = None  # (N, 3) normalised reference positions
    targets: np.ndarray | None = None  # their face-corner targets (the stats' targets)
    clockwise: int = 0  # faces read clockwise (reversed in `faces`, not in the file)


def _refuse(message: str) -> UsageError:
    return UsageError(f"eegt: {message}")


def plan(ns: argparse.Namespace, params: EEGTParams
         ) -> tuple[EEGTParams, dict[str, Any], SolverPlan]:
    """Read and check the solver mesh input and decide everything before the run: (the run's
    parameters, the report's "solver_mesh", the plan). UsageError (exit 2, one line,
    nothing written) for anything that cannot work."""
    path = ns.input
    try:
        sm = solver_mesh.read(path)
        fs = faces_from_csr(sm.offsets[:-1], sm.counts(), sm.corners, sm.n_points)
        on_boundary = boundary_nodes(sm.n_points, fs)  # whatever way round the faces run
        choice = solver_mesh.node_choice(
            sm, params.boundary, on_boundary, ns.pin_field,
            solver_mesh.parse_groups(ns.fixed_groups),
            solver_mesh.parse_groups(ns.slide_groups))
    except ValueError as exc:
        raise _refuse(str(exc)) from None
    name = os.path.splitext(os.path.basename(path))[0] or "mesh"
    for wanted in ns.object:
        if wanted != name:
            raise _refuse(f"no mesh object named '{wanted}' (mesh objects: {name})")
    if choice.boundary != params.boundary:
        params = dataclasses.replace(params, boundary=choice.boundary)
    fixed = None if ns.no_pinned else choice.pinned
    points3d = sm.points3d()
    try:
        fs, clockwise = oriented_faces(sm, fs)
        movable = free_nodes(sm.n_points, fs, fixed)
        if params.boundary != "fixed":
            movable |= on_boundary if fixed is None else on_boundary & ~fixed
        plane = fit_plane(points3d, fs, fixed, ns.project)
    except ValueError as exc:
        raise _refuse(f"'{path}': {str(exc).splitlines()[0]}") from None
    if not movable.any():
        raise _refuse(f"'{path}': every node is pinned or on the fixed boundary: nothing can "
                      "move")
    p = SolverPlan(sm, name, fs, fixed, plane, plane.to_2d(points3d), Stats(0, 0.0, 0.0),
                   clockwise=clockwise)
    ref2d = _plan_reference(p, ns.reference) if ns.reference else None
    if params.target == "keep":
        p.targets = judge_targets(p.points2d, fs, movable, ref2d)
    elif ref2d is not None:
        p.targets = reference_targets(ref2d, fs, sm.n_points)
    p.before = mesh_stats(p.points2d, fs, p.targets)
    if ns.output:
        try:  # the output format can hold this mesh: the same check as the real write
            tmp, _ = checked_write.stage(sm, ns.output)
            checked_write.discard(tmp)
        except checked_write.WriteError as exc:
            raise UsageError(f"eegt: cannot write output '{ns.output}': {exc.reason}",
                             unwritable=ns.output) from None
    notes = list(choice.notes)
    if clockwise:
        notes.insert(0, clockwise_note(clockwise, sm.n_faces))
    info = {"format": sm.fmt, "points": sm.n_points, "faces": sm.n_faces,
            "pinned": int(np.count_nonzero(choice.pinned)), "boundary": choice.boundary,
            "clockwise_faces": clockwise, "notes": notes}
    return params, info, p


def oriented_faces(sm: solver_mesh.SolverMesh, fs: FaceSet | None = None
                   ) -> tuple[FaceSet, int]:
    """(the file's 2D cells as faces (`fs`: as read, when the caller has them),
    consistently oriented, each connected component counterclockwise; how many were read
    clockwise and are reversed). The orientation is decided on the points centred and
    scaled (`_normalised`), seen from the side of the mesh's normal whose largest coordinate
    is positive (+z for a 2D file). ValueError (one line) for faces no orientation fits."""
    if fs is None:
        fs = faces_from_csr(sm.offsets[:-1], sm.counts(), sm.corners, sm.n_points)
    points3d = sm.points3d()
    center, scale = _normalised(points3d, fs)
    orientation = orient_faces(fs, sm.n_points, (points3d - center) / scale)
    return orientation.apply(fs), orientation.n_flipped


def clockwise_note(clockwise: int, n_faces: int) -> str:
    """The report's note on faces read clockwise."""
    which = f"all {n_faces} faces were" if clockwise == n_faces else \
        f"{clockwise} of {n_faces} faces were"
    return (f"{which} read clockwise: the run takes them counterclockwise; the file keeps "
            "its own node order")


def _plan_reference(p: SolverPlan, path: str) -> np.ndarray:
    """--reference with a solver mesh: an .obj or a solver mesh of the input's topology
    (same points, same faces in the same order), normalised into ``p.reference``; returns
    its points in the input's plane (N, 2), checked as reference shapes."""
    sm, fs = p.sm, p.faces
    try:
        if is_solver(path):
            ref = solver_mesh.read(path)
            points = ref.points3d()
            same = ref.n_points == sm.n_points and np.array_equal(ref.offsets, sm.offsets) \
                and np.array_equal(ref.corners, sm.corners)
            n_ref, f_ref = ref.n_points, ref.n_faces
        else:
            src = reference_mesh.from_file(path)
            points = np.asarray(src.file_points, dtype=np.float64)
            same = points.shape[0] == sm.n_points and \
                np.array_equal(src.file_faces.offsets, fs.offsets) and \
                np.array_equal(src.file_faces.indices, sm.corners[:fs.n_corners])
            n_ref, f_ref = points.shape[0], src.file_faces.n_faces
    except ValueError as exc:
        raise _refuse(str(exc).splitlines()[0]) from None
    if not same:
        raise _refuse(f"--reference '{path}' ({n_ref} points, {f_ref} faces) does not fit "
                      f"'{sm.path}' ({sm.n_points} points, {sm.n_faces} faces): a reference "
                      "has the same nodes and faces, in the same order")
    center, scale = _normalised(points, fs)
    p.reference = (points - center) / scale
    try:
        ref2d = reference_to_2d(p.reference, fs, sm.n_points, PLANE_TOL)
    except ValueError as exc:
        raise _refuse(f"reference '{path}': {str(exc).splitlines()[0]}") from None
    reference_targets(ref2d, fs, sm.n_points)  # its one-line checks
    return ref2d


@dataclasses.dataclass
class SolverOutcome:
    """A finished run: its result line, the staged output (None: nothing to write) and
    the written mesh's 2D points (the input's when unchanged)."""

    result: runner.ObjectResult
    staged: str | None
    after2d: np.ndarray


def run(p: SolverPlan, ns: argparse.Namespace, params: EEGTParams, backend: str,
        device: str | None, progress: Progress | None) -> SolverOutcome:
    """Run the core in float64 on the file's points, stage the output (when asked) and
    judge what was written; UsageError (exit 2) when the core refuses the mesh or the
    output cannot be written."""
    sm = p.sm
    if backend in ("opencl", "auto"):
        runner.select_opencl_device(device)
    points3d = sm.points3d()
    try:
        res = untangle_and_smooth_3d(points3d, p.faces, fixed=p.fixed, params=params,
                                     backend=backend, progress=progress, tol=PLANE_TOL,
                                     project=ns.project, reference_points=p.reference,
                                     stored=np.float64)
    except ValueError as exc:
        raise _refuse(f"'{sm.path}': {str(exc).splitlines()[0]}") from None
    out = runner.ObjectResult(object=p.name, mesh=p.name, status=res.status,
                              message=str(res.message), n_faces=sm.n_faces,
                              n_free=int(np.count_nonzero(np.asarray(res.moved))),
                              untangle_iterations=int(res.untangle_iterations),
                              smooth_iterations=int(res.smooth_iterations),
                              global_iterations=int(res.global_iterations),
                              seconds=float(res.seconds), backend=str(res.backend))
    out.n_nodes = int(np.count_nonzero(p.faces.used_nodes(sm.n_points)))
    if res.n_frozen and res.status != "failed":
        out.notes.append(frozen_note(res.n_frozen))
    positions = np.asarray(res.points, dtype=np.float64)
    moved = (positions != points3d).any(axis=1)
    keep = bool(moved.any()) and (out.ok or not ns.no_write_on_fail)
    staged, after2d = _write(p, ns.output, positions if keep else None, moved)
    after = mesh_stats(after2d, p.faces, p.targets)
    if keep and not accept(p.before, after):  # the written numbers lost what the run won
        checked_write.discard(staged)
        staged, after2d = _write(p, ns.output, None, moved)
        after = mesh_stats(after2d, p.faces, p.targets)
        keep = False
        out.notes.append("the result as written was no better than the input: unchanged")
    elif not moved.any() and res.status != "failed":
        out.notes.append("no improvement over the input: mesh unchanged")
    out.written = keep
    out.before, out.after = runner.stats_dict(p.before), runner.stats_dict(after)
    if p.targets is not None:
        out.regular = runner.regular_stats(p.points2d, after2d, p.faces)
    out.claim_no_more_than_result()
    return SolverOutcome(out, staged, after2d)


def _write(p: SolverPlan, output: str | None, positions: np.ndarray | None,
           moved: np.ndarray) -> tuple[str | None, np.ndarray]:
    """(the staged output or None, the 2D points of what is written: read back from the
    staged file, else the float64 positions themselves)."""
    if not output:
        if positions is None:
            return None, p.points2d
        return None, p.plane.to_2d(_pad(p.sm.with_positions(positions, moved).points))
    try:
        tmp, back = checked_write.stage(p.sm, output, positions,
                                        None if positions is None else moved)
    except checked_write.WriteError as exc:
        raise UsageError(f"eegt: cannot write output '{output}': {exc.reason}",
                         unwritable=output) from None
    if not (np.array_equal(back.offsets, p.sm.offsets)
            and np.array_equal(back.corners, p.sm.corners)):
        checked_write.discard(tmp)
        raise UsageError(f"eegt: cannot write output '{output}': the written file orders its "
                         "2D cells differently", unwritable=output)
    return tmp, p.plane.to_2d(back.points3d())


def _pad(points: np.ndarray) -> np.ndarray:
    out = np.zeros((points.shape[0], 3), dtype=np.float64)
    out[:, :points.shape[1]] = points
    return out


def object_metrics(p: SolverPlan, after2d: np.ndarray,
                   names: tuple[str, ...]) -> dict[str, Any]:
    """measure -> {"before", "after"} of the whole mesh (the input file, the written one)."""
    b, a = summaries(p.points2d, p.faces, names), summaries(after2d, p.faces, names)
    return {n: {"before": b[n].as_dict(), "after": a[n].as_dict()} for n in names}


def group_metrics(p: SolverPlan, after2d: np.ndarray,
                  names: tuple[str, ...]) -> dict[str, Any]:
    """group -> measure -> {"before", "after"} over the faces of every group of 2D cells in
    the input file (the summaries as ``core.MeasureSummary.as_dict``; its faces as the run
    oriented them)."""
    sm = p.sm
    counts = sm.counts()
    out = {}
    for group, mask in sm.face_groups().items():
        corner_mask = np.repeat(mask, counts)
        sub = faces_from_csr(np.cumsum(counts[mask]) - counts[mask], counts[mask],
                             p.faces.indices[corner_mask], sm.n_points)
        b, a = summaries(p.points2d, sub, names), summaries(after2d, sub, names)
        out[group] = {"faces": int(np.count_nonzero(mask)),
                      **{n: {"before": b[n].as_dict(), "after": a[n].as_dict()}
                         for n in names}}
    return out
