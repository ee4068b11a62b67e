# SPDX-License-Identifier: GPL-3.0-or-later
"""Glue between one Blender mesh object and the core: prepare, compute, apply.

``prepare`` reads the mesh (main thread), ``compute`` only runs the core on NumPy arrays (safe
in a worker thread: no bpy), ``apply`` writes the result back (main thread, Object Mode).
No algorithm lives here.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, ClassVar

import bpy
import numpy as np

from ...core import EEGTParams, faces_from_csr, mesh_stats
from ...core.mesh import EdgeInfo, PlaneFrame, ragged_arange
from ...core.metrics import reference_targets, reference_to_2d
from ...core.run import frozen_note, untangle_and_smooth_3d
from ..shared.progress import Progress
from ..shared.refusal import refusal
from ..shared.result import RunResult
from . import mesh_io, reference_mesh
from .reference_mesh import ReferenceSource

PLANE_TOL = 1e-5


def stats_dict(stats: Any) -> dict[str, Any] | None:
    """Core Stats as a JSON-ready dict."""
    if stats is None:
        return None
    return {"n_inverted": int(stats.n_inverted), "q_min": float(stats.q_min),
            "q_avg": float(stats.q_avg)}


def regular_stats(before2d: np.ndarray, after2d: np.ndarray, faces: Any
                  ) -> dict[str, Any]:
    """The `ObjectResult.regular` block: the mesh's stats against regular polygons at the
    input's and at the result's 2D points (a run with target shapes reports these beside
    its own)."""
    return {"before": stats_dict(mesh_stats(before2d, faces)),
            "after": stats_dict(mesh_stats(after2d, faces))}


def stats_from_quality(q: np.ndarray) -> dict[str, Any]:
    """n_inverted / q_min / q_avg of per-face mean ratios (inverted faces count as 0)."""
    return {"n_inverted": int(np.count_nonzero(q <= 0.0)),
            "q_min": float(q.min()) if q.size else 0.0,
            "q_avg": float(q.mean()) if q.size else 0.0}


@dataclass
class ObjectResult(RunResult):
    """Outcome of one object's mesh run (``result.RunResult``, stats kind "mesh":
    n_inverted / q_min / q_avg)."""

    KIND: ClassVar[str] = "mesh"

    n_nodes: int = 0
    # with target shapes (keep, reference): the mean ratio against the regular polygon
    # beside them, {"before": stats, "after": stats} (`regular_stats`); None: regular targets
    regular: dict[str, Any] | None = None

    def as_dict(self) -> dict[str, Any]:
        """The JSON report's entry (`RunResult.as_dict`); "regular" only for runs with
        target shapes."""
        out = super().as_dict()
        if out.get("regular") is None:
            out.pop("regular", None)
        return out

    def claim_no_more_than_result(self) -> None:
        """Make a 'valid' / 'untangled' status 'failed' when the kept or written positions
        still have an inverted face (float32 round-off can fold a face the core left valid;
        a result not better than the input keeps the input's folds)."""
        left = int((self.after or {}).get("n_inverted", 0))
        if self.ok and left > 0:
            where = "written" if self.written else "kept"
            self.status = "failed"
            self.message = f"{left} faces stay inverted in the {where} positions"

    def line(self) -> str:
        """The one report line of this object."""
        unchanged = self.unchanged_line(self.object)
        if unchanged:
            return unchanged
        text = (f"{self.object}: {self.stats_text()}, {self.iterations_text()}, "
                f"{self.seconds:.2f} s, {self.backend}")
        if self.status == "failed":
            text += f"; FAILED to untangle: {self.message}"
        if not self.written:
            text += "; nothing written" if self.status != "failed" else "; not written"
        if self.regular:
            b, a = self.regular["before"], self.regular["after"]
            text += (f"; against regular polygons: q_min {b['q_min']:.4f} -> {a['q_min']:.4f}, "
                     f"q_avg {b['q_avg']:.4f} -> {a['q_avg']:.4f}")
        if self.notes:
            text += "; " + "; ".join(self.notes)
        return text

    def iterations_text(self) -> str:
        """'U+S iterations', or 'U+G+S iterations (untangle+optimize+smooth)' with the
        global optimization stage."""
        if self.global_iterations:
            return (f"{self.untangle_iterations}+{self.global_iterations}+"
                    f"{self.smooth_iterations} iterations (untangle+optimize+smooth)")
        return f"{self.untangle_iterations}+{self.smooth_iterations} iterations"


@dataclass
class Job:
    """Everything the core needs for one mesh, read from Blender on the main thread."""

    object: str
    mesh: str
    co: np.ndarray  # (N, 3) float32, the positions being edited (mesh or active shape key)
    key_name: str | None = None
    nodes: np.ndarray | None = None  # (n,) global indices of the nodes used by the faces
    faces: Any = None  # core FaceSet over local node numbers
    edges: EdgeInfo | None = None  # their edge analysis (from the mesh's edge table if it fits)
    fixed: np.ndarray | None = None  # (n,) extra pinned nodes (boundary is added by the core)
    frame: Any = None
    points3d: np.ndarray | None = None  # (n, 3) float64 node positions (float32 values)
    points2d: np.ndarray | None = None  # (n, 2) in ``frame`` (live drags, measures)
    project: bool = False  # put every free node on the fixed nodes' plane (PlaneFrame.fit)
    reference2d: np.ndarray | None = None  # (n, 2) reference positions (target "reference")
    targets: np.ndarray | None = None  # (n_corners, 2) their face corners: the stats' targets
    notes: list[str] = field(default_factory=list)
    error: str | None = None
    result: Any = None
    new_co: np.ndarray | None = None  # (N, 3) float32 to write, None when nothing changed
    after: dict[str, Any] | None = None
    regular: dict[str, Any] | None = None  # `regular_stats` (runs with target shapes)


def _fail(job: Job, message: str) -> Job:
    job.error = message
    return job


def prepare(obj: bpy.types.Object, *, selected_only: bool = False, use_pinned: bool = True,
            project: bool = False, reference: ReferenceSource | None = None) -> Job:
    """Read one mesh object into a :class:`Job` (sets ``job.error`` for bad input).

    ``selected_only``: only the selected faces move; vertices of unselected faces (the
    selection border and everything outside) stay fixed. Loose vertices and the vertices of
    loose edges never move. ``reference`` (target "reference"): where the reference shapes
    come from (``reference_mesh``); a missing, mismatched or non-planar one is an error.
    """
    me = obj.data
    job = Job(object=obj.name, mesh=me.name, co=np.zeros((0, 3), np.float32))
    why = refusal(obj)
    if why:
        return _fail(job, why)
    _read_positions(obj, job)
    topo = mesh_io.read_topology(me)
    if topo.loop_start.size == 0:
        return _fail(job, "mesh has no faces")
    face_mask = np.ones(topo.loop_start.size, dtype=bool)
    if selected_only:
        face_mask = mesh_io.read_face_selection(me)
        if not face_mask.any():
            return _fail(job, "no faces selected")
    if topo.corner_verts.size and (topo.corner_verts.min() < 0
                                   or topo.corner_verts.max() >= topo.n_verts):
        return _fail(job, "a face uses a vertex index out of range")
    sub = sub_mesh(topo, face_mask, job.co)
    job.nodes = sub.nodes
    job.points3d = sub.points3d
    if not np.isfinite(sub.points3d).all():
        bad = int(np.count_nonzero(~np.isfinite(sub.points3d).all(axis=1)))
        return _fail(job, f"{bad} vertices have NaN or infinite coordinates")
    pins = None
    if use_pinned:
        try:
            pins = mesh_io.read_pins(obj)
        except ValueError as exc:
            return _fail(job, str(exc))
    fixed_all, edges = _fixed_vertices(obj, topo, face_mask, pins, selected_only)
    job.fixed = fixed_all[sub.nodes]
    try:
        _fit_plane(job, sub, topo, edges, project)
    except ValueError as exc:
        return _fail(job, _first_line(exc))
    job.project = project
    if reference is not None:
        try:
            what = _read_reference(job, obj, reference, sub.nodes)
        except ValueError as exc:
            return _fail(job, _first_line(exc))
        job.notes.append(f"quality against the face shapes of {what}")
    if project and job.frame.fixed_offset > PLANE_TOL * job.frame.size:
        job.notes.append(f"boundary/pinned vertices up to {job.frame.fixed_offset:.3g} off the "
                         f"plane were kept where they are (they never move)")
    return job


def _first_line(exc: ValueError) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def _read_positions(obj: bpy.types.Object, job: Job) -> None:
    """The positions being edited (the active shape key's, else the mesh's) into ``job.co``,
    with a note for a shape key and for modifiers the run does not see."""
    me = obj.data
    key = obj.active_shape_key if me.shape_keys is not None else None
    if key is not None:
        job.key_name = key.name
        job.co = mesh_io.read_key_positions(key)
        job.notes.append(f"acted on shape key '{key.name}'")
    else:
        job.co = mesh_io.read_positions(me)
    if any(m.show_viewport for m in obj.modifiers):
        job.notes.append("base mesh (modifiers not applied)")


@dataclass
class SubMesh:
    """The chosen faces as their own mesh over local node numbers."""

    nodes: np.ndarray  # (n,) mesh vertex of each node
    lut: np.ndarray  # (N,) node of each mesh vertex (the identity when every vertex is a node)
    local: np.ndarray  # corners of the chosen faces, face by face, in node numbers
    corners: np.ndarray | slice  # those corners' numbers in the mesh
    offsets: np.ndarray  # (faces + 1,) where each chosen face's corners start
    totals: np.ndarray  # (faces,) corners per chosen face
    points3d: np.ndarray  # (n, 3) float64 node positions


def sub_mesh(topo: mesh_io.MeshArrays, face_mask: np.ndarray, co: np.ndarray) -> SubMesh:
    """The faces of ``face_mask`` (in the mesh's corner order) and the vertices they use,
    renumbered (every corner a vertex index in range)."""
    order = np.argsort(topo.loop_start[face_mask], kind="stable")
    starts = topo.loop_start[face_mask][order]
    totals = topo.loop_total[face_mask][order]
    n_all = topo.n_verts
    offsets = np.zeros(totals.size + 1, dtype=np.int64)
    np.cumsum(totals, out=offsets[1:])
    # Corner numbers of the chosen faces, face by face (offsets are sorted in Blender): all
    # corners in order when every face is chosen.
    if np.array_equal(starts, offsets[:-1]):
        idx: np.ndarray | slice = slice(0, int(offsets[-1]))
    else:
        idx = ragged_arange(starts, totals)
    sub_corners = topo.corner_verts[idx].astype(np.int64)
    used = np.zeros(n_all, dtype=bool)
    used[sub_corners] = True
    if used.all():  # every vertex in a chosen face: nodes are the vertices
        nodes = lut = np.arange(n_all)
        local = sub_corners
        pts3d = co.astype(np.float64)
    else:
        nodes = np.flatnonzero(used)  # = np.unique(sub_corners), by a lookup, not a sort
        lut = np.zeros(n_all, dtype=np.int64)
        lut[nodes] = np.arange(nodes.size)
        local = lut[sub_corners]
        pts3d = co[nodes].astype(np.float64)
    return SubMesh(nodes=nodes, lut=lut, local=local, corners=idx, offsets=offsets,
                   totals=totals, points3d=pts3d)


def _fixed_vertices(obj: bpy.types.Object, topo: mesh_io.MeshArrays, face_mask: np.ndarray,
                    pins: np.ndarray | None, selected_only: bool
                    ) -> tuple[np.ndarray, mesh_io.EdgeArrays]:
    """(mesh vertices that never move, the mesh's edge table): the pins, the vertices of
    unchosen faces with ``selected_only``, loose vertices and loose edges."""
    me = obj.data
    fixed_all = np.zeros(topo.n_verts, dtype=bool)
    if pins is not None:
        fixed_all |= pins
    if selected_only:
        fixed_all[topo.corner_verts[~face_mask[mesh_io.corner_faces(topo)]]] = True
    edges = mesh_io.read_edges(me)
    loose = mesh_io.loose_edge_vertices(topo.n_verts, edges)
    if loose is not None:
        fixed_all |= loose
    return fixed_all, edges


def _fit_plane(job: Job, sub: SubMesh, topo: mesh_io.MeshArrays, edges: mesh_io.EdgeArrays,
               project: bool) -> None:
    """The job's faces, edge analysis, plane and 2D points; ValueError for a mesh that is
    not planar (or cannot be projected)."""
    n = sub.nodes.size
    job.faces = faces_from_csr(sub.offsets[:-1], sub.totals, sub.local.reshape(-1), n)
    job.edges = _edge_info(sub.corners, sub.offsets, topo, edges, sub.lut, n)
    if job.edges is None:  # a table that does not fit: one sorted analysis for both
        job.edges = EdgeInfo(job.faces, n)
    job.frame = PlaneFrame.fit(sub.points3d, job.faces, tol=PLANE_TOL, project=project,
                               fixed=job.fixed, edges=job.edges)
    job.points2d = job.frame.to_2d(sub.points3d)


def _read_reference(job: Job, obj: bpy.types.Object, reference: ReferenceSource,
                    nodes: np.ndarray) -> str:
    """Target "reference": the reference's 2D positions and face-corner targets into the
    job; what the reference is (for the note). ValueError when it does not fit."""
    ref3d, what = reference_mesh.reference_positions(obj, reference, job.key_name)
    job.reference2d = reference_to_2d(ref3d[nodes].astype(np.float64), job.faces,
                                      nodes.size, PLANE_TOL)
    job.targets = reference_targets(job.reference2d, job.faces, nodes.size)
    return what


def _edge_info(corners: np.ndarray | slice, offsets: np.ndarray, topo: mesh_io.MeshArrays,
               edges: mesh_io.EdgeArrays, lut: np.ndarray, n_nodes: int) -> EdgeInfo | None:
    """The chosen faces' edge analysis (in node numbers) from Blender's edge table
    (``EdgeInfo.from_table``: one count per edge, no sort of every corner), or None when
    the table does not fit them (the caller then sorts). ``corners``: the chosen faces'
    corners face by face (``offsets``); ``lut`` maps mesh vertices to nodes, in order."""
    ev, ce = edges.edge_verts, edges.corner_edges
    if offsets[-1] == 0 or ev.size == 0 or ev.min() < 0 or ev.max() >= lut.size:
        return None
    a = topo.corner_verts[corners]
    nxt = np.arange(1, a.size + 1, dtype=np.int64 if a.size >= 2**31 else np.int32)
    nxt[offsets[1:] - 1] = offsets[:-1]  # a face's last corner goes back to its first
    info = EdgeInfo.from_table(a, a[nxt], ce[corners], ev, lut.size)
    if info is None or n_nodes == lut.size:  # every vertex is a node: lut is the identity
        return info
    return info.renumbered(lut, n_nodes)


def select_opencl_device(device: str | None) -> None:
    """Tell the core's OpenCL backend which device to use ("AUTO"/None: automatic)."""
    from ...core.eegt import engine_opencl  # imports pyopencl only when a device is used

    engine_opencl.select_device(None if device in (None, "", "AUTO") else device)


def compute(job: Job, params: EEGTParams, backend: str = "numpy", progress: Progress | None = None,
            device: str | None = None) -> None:
    """Run the core's 3D entry on a prepared job (no bpy here: safe in a worker thread): it
    fits the plane, runs, and judges the float32 positions Blender will store
    (``untangle_and_smooth_3d`` with ``stored=np.float32``)."""
    if job.error:
        return
    if backend in ("opencl", "auto"):
        select_opencl_device(device)
    try:
        res = untangle_and_smooth_3d(job.points3d, job.faces, fixed=job.fixed, params=params,
                                     backend=backend, progress=progress, tol=PLANE_TOL,
                                     project=job.project, reference_points=job.reference2d,
                                     edges=job.edges, stored=np.float32)
    except ValueError as exc:
        job.error = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return
    job.result = res
    if res.status == "cancelled":
        return
    new_co = _positions_to_write(job, res.points)
    if params.target != "regular":
        after2d = job.points2d if new_co is None else written_2d(job, new_co)
        job.regular = regular_stats(job.points2d, after2d, job.faces)
    if new_co is None:
        job.after = stats_dict(res.before)
        if res.status != "failed":
            job.notes.append("no improvement over the input: mesh unchanged")
        return
    job.new_co = new_co
    job.after = stats_dict(res.after)
    if job.project:
        job.notes.append(f"projected onto the plane of the fixed vertices (largest offset "
                         f"{job.frame.max_offset:.3g})")


def _positions_to_write(job: Job, points: np.ndarray) -> np.ndarray | None:
    """(N, 3) float32 positions to write: ``job.co`` with the job's nodes at the core's
    float32 ``points``, or None when no position changes."""
    given = node_rows(job, job.co)
    changed = np.any(points != given, axis=1)
    if not changed.any():
        return None
    if given is job.co:  # every vertex is a node
        return np.array(points, dtype=np.float32)
    out = job.co.copy()
    out[job.nodes[changed]] = points[changed]
    return out


def node_rows(job: Job, co: np.ndarray) -> np.ndarray:
    """The rows of a per-vertex array that are the job's nodes (the array itself when every
    vertex is one: no copy)."""
    return co if job.nodes.size == co.shape[0] else co[job.nodes]


def written_2d(job: Job, co: np.ndarray) -> np.ndarray:
    """The job's nodes of float32 vertex positions ``co``, in its plane's 2D coordinates."""
    return job.frame.to_2d(node_rows(job, co).astype(np.float64))


def apply(obj: bpy.types.Object, job: Job, *, write: bool = True) -> ObjectResult:
    """Write a computed job back (Object Mode) and describe the outcome."""
    out = ObjectResult(object=job.object, mesh=job.mesh, notes=list(job.notes))
    if job.error:
        out.message = job.error
        return out
    res = job.result
    out.n_nodes = int(job.nodes.size)
    out.n_faces = int(job.faces.n_faces)
    out.n_free = int(np.count_nonzero(np.asarray(res.moved)))
    out.status = res.status
    out.message = str(res.message)
    if res.n_frozen and res.status != "failed":  # a failed run's message names them already
        out.notes.append(frozen_note(res.n_frozen))
    out.before = stats_dict(res.before)
    out.after = job.after if job.after is not None else stats_dict(res.after)
    out.untangle_iterations = int(res.untangle_iterations)
    out.smooth_iterations = int(res.smooth_iterations)
    out.global_iterations = int(res.global_iterations)
    out.seconds = float(res.seconds)
    out.backend = str(res.backend)
    if res.status == "cancelled":
        out.after = out.before
        return out
    if job.new_co is not None and write:
        me = obj.data
        if len(me.vertices) != len(job.co):
            out.status, out.message = "error", "mesh changed during the run, not written"
            return out
        if job.key_name is not None:
            key = me.shape_keys.key_blocks[job.key_name]
            mesh_io.write_key_positions(key, job.new_co)
            if key == me.shape_keys.reference_key:
                mesh_io.write_positions(me, job.new_co)
            me.update()
        else:
            mesh_io.write_positions(me, job.new_co)
        out.written = True
    if not out.written:
        out.after = out.before if job.new_co is not None else out.after
    if job.regular is not None:
        out.regular = dict(job.regular, after=job.regular["after"] if out.written else
                           job.regular["before"])
    out.claim_no_more_than_result()
    return out


def run_object(obj: bpy.types.Object, params: EEGTParams, *, backend: str = "numpy",
               device: str | None = None, selected_only: bool = False, use_pinned: bool = True,
               project: bool = False, progress: Progress | None = None,
               write: bool = True, reference: ReferenceSource | None = None) -> ObjectResult:
    """Prepare, compute and apply in one call (Object Mode, main thread)."""
    t0 = time.perf_counter()
    if params.target == "reference" and reference is None:
        reference = ReferenceSource()
    job = prepare(obj, selected_only=selected_only, use_pinned=use_pinned, project=project,
                  reference=reference if params.target == "reference" else None)
    compute(job, params, backend, progress, device)
    result = apply(obj, job, write=write)
    if result.seconds == 0.0:
        result.seconds = time.perf_counter() - t0
    return result
