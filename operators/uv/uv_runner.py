# SPDX-License-Identifier: GPL-3.0-or-later
"""Glue between one mesh object's UV map and the core: prepare, compute, apply.

``prepare`` reads the UV map, its pins and selection (main thread, Object Mode),
``compute`` welds nothing and writes nothing: it runs ``core.uv.uv_untangle`` on arrays (safe in
a worker thread), ``apply`` writes the UV map back (main thread, Object Mode). Only the
loops of UV vertices that moved are given new values; every other value of the UV map, and
every other UV map and attribute, keeps its bits.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import ClassVar

import bpy
import numpy as np

from ...core import EEGTParams, faces_from_csr
from ...core.choices import UV_TARGET, ids
from ...core.metrics import face_shapes_2d
from ...core.uv import (
    UVLayout,
    UVMeasures,
    UVResult,
    keep_shape_targets,
    keeps_corners,
    measure,
    overlaps_around,
    tangled_faces,
    untangle_uv,
    weld_uv,
)
from ..mesh import mesh_io, runner
from ..shared.progress import Progress
from ..shared.refusal import refusal
from ..shared.result import RunResult
from . import uv_mesh

TARGETS = ids(UV_TARGET)  # target shape of a UV face: its 3D face, the regular polygon, or
# its own as laid out ("KEEP": the core's keep_shape_targets, a repair under scope "tangles")
UNIT = {"3D": "as in 3D", "REGULAR": "regular", "KEEP": "as laid out"}  # what 1 means
SHAPES = {"KEEP": "target (laid-out, a neighbour's or 3D)"}  # the core's fallback note


@dataclass
class UVObjectResult(RunResult):
    """Outcome of one object's UV run (``result.RunResult``, stats kind "uv": flipped /
    inverted / overlapping faces, distortion mean and worst; ``n_faces``: the faces
    worked on). ``ok``: the selection ended with no flipped or inverted face."""

    KIND: ClassVar[str] = "uv"

    uv_map: str = ""
    targets: str = "3D"
    islands: int = 0
    islands_run: int = 0
    mirrored_islands: int = 0
    n_uv_vertices: int = 0
    target_fallback: int = 0

    def line(self) -> str:
        """The one report line of this object."""
        name = f"{self.object} UV '{self.uv_map}'" if self.uv_map else self.object
        unchanged = self.unchanged_line(name)
        if unchanged:
            return unchanged
        text = (f"{name}: {self.stats_text()} "
                f"(1 = {UNIT.get(self.targets, 'regular')}), "
                f"{self.islands_run}/{self.islands} islands, {self.seconds:.2f} s, {self.backend}")
        if self.status == "failed":
            text += f"; FAILED: {self.message}" if self.message else \
                "; FAILED to untangle every island"
        if not self.written:
            text += "; nothing written"
        if self.notes:
            text += "; " + "; ".join(self.notes)
        return text


@dataclass
class UVJob:
    """Everything the core needs for one UV map, read on the main thread."""

    object: str
    mesh: str
    uv_map: str = ""
    uv: np.ndarray | None = None  # (L, 2) float32 input values
    layout: UVLayout | None = None
    selected: np.ndarray | None = None  # (F,) faces to work on
    fixed: np.ndarray | None = None  # (V,) pinned UV vertices
    targets: np.ndarray | None = None  # (C, 2) or None (regular polygons)
    target_kind: str = "3D"  # TARGETS
    shapes3d: np.ndarray | None = None  # (C, 2) 3D face shapes (targets "3D" and "KEEP")
    scope: str = "tangles"  # core.uv.uv_untangle.SCOPES
    notes: list[str] = field(default_factory=list)
    error: str | None = None
    result: UVResult | None = None
    before: UVMeasures | None = None
    after: UVMeasures | None = None
    new_uv: np.ndarray | None = None  # (L, 2) float32 to write, None when nothing changed


def _fail(job: UVJob, message: str) -> UVJob:
    job.error = message
    return job


def prepare(obj: bpy.types.Object, uv_name: str | None = None, *, selected_only: bool = False,
            sync: bool = True, select_mode: str = "VERTEX", use_pins: bool = True,
            targets: str = "3D", scope: str = "tangles") -> UVJob:
    """Read one object's UV map (``uv_name``, default the active one) into a :class:`UVJob`
    (``job.error`` set for bad input). ``selected_only``: only the faces selected in the UV
    editor (see ``uv_mesh.read_uv_face_selection``); else every face. ``scope``: see
    ``core.uv.uv_untangle.untangle_uv``. ``targets``: an id of TARGETS ("KEEP": the targets
    are made in ``compute``, from the map and the run's rule for corners kept as given)."""
    me = obj.data
    job = UVJob(object=obj.name, mesh=me.name, target_kind=targets, scope=scope)
    why = refusal(obj)
    if why:
        return _fail(job, why)
    try:
        layer = uv_mesh.uv_layer(me, uv_name)
    except ValueError as exc:
        return _fail(job, str(exc))
    job.uv_map = layer.name
    topo = mesh_io.read_topology(me)
    if topo.loop_start.size == 0:
        return _fail(job, "mesh has no faces")
    job.uv = uv_mesh.read_uv(me, layer)
    try:
        job.layout = weld_uv(topo.loop_start, topo.loop_total, topo.corner_verts, job.uv)
    except ValueError as exc:
        return _fail(job, f"UV map '{layer.name}': {exc}")
    if selected_only:
        job.selected = uv_mesh.read_uv_face_selection(me, layer, sync, select_mode)
        if not job.selected.any():
            hint = "" if sync else " (select them in the UV editor)"
            return _fail(job, f"no UV faces selected{hint}")
    else:
        job.selected = np.ones(topo.loop_start.size, dtype=bool)
    side = job.layout.orientation()
    if not (side[job.layout.island[job.selected]] != 0).any():
        return _fail(job, f"UV map '{layer.name}' has no area where selected (every island "
                          "collapsed to a point or a line): unwrap it first")
    job.fixed = np.zeros(job.layout.n_nodes, dtype=bool)
    if use_pins:
        job.fixed[job.layout.loop_node[uv_mesh.read_uv_pins(me, layer)]] = True
    if targets not in TARGETS:
        return _fail(job, f"target must be one of {', '.join(TARGETS)}, got {targets!r}")
    if targets in ("3D", "KEEP"):
        co = mesh_io.read_positions(me)
        if not np.isfinite(co[topo.corner_verts]).all():
            return _fail(job, "vertices with NaN or infinite coordinates")
        try:
            fs3d = faces_from_csr(topo.loop_start, topo.loop_total, topo.corner_verts,
                                  len(me.vertices))
            job.shapes3d = face_shapes_2d(co.astype(np.float64), fs3d)
        except ValueError as exc:
            return _fail(job, str(exc).splitlines()[0])
        if targets == "3D":
            job.targets = job.shapes3d
    return job


def compute(job: UVJob, params: EEGTParams, backend: str = "numpy",
            progress: Progress | None = None, device: str | None = None) -> None:
    """Run the core on a prepared job (no bpy here: safe in a worker thread)."""
    if job.error:
        return
    if backend in ("opencl", "auto"):
        runner.select_opencl_device(device)
    lay = job.layout
    side = lay.orientation()
    keep = keeps_corners(params)  # corners kept as given: the run's rule (core.metrics.kept)
    over = overlaps_around(lay, lay.points, job.selected, side, job.fixed, keep)
    tangled = tangled_faces(lay, lay.points, job.selected, side, over, job.fixed, keep)
    repair = job.target_kind == "KEEP"
    if repair:  # each face its own shape, a tangled one a neighbour's or its 3D face's
        shapes = keep_shape_targets(lay, lay.points, job.selected, job.fixed, job.shapes3d,
                                    side, keep, tangled)
        job.targets = shapes.targets
        note = shapes.note()
        if note and note not in job.notes:
            job.notes.append(note)
    job.before = measure(lay, lay.points, job.selected, job.targets, side, over, job.fixed,
                         keep)
    try:
        res = untangle_uv(lay, job.selected, fixed=job.fixed, targets=job.targets,
                          params=params, backend=backend, progress=progress,
                          scope=job.scope, tangled=tangled, repair=repair,
                          shapes=SHAPES.get(job.target_kind, "3D"))
    except ValueError as exc:
        job.error = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return
    job.result = res
    if res.status == "cancelled":
        return
    job.after = measure(lay, res.points, job.selected, job.targets, side, None, job.fixed,
                        keep) if res.moved.any() else job.before
    if res.moved.any():
        loops = res.moved[lay.loop_node]
        new = job.uv.copy()
        new[loops] = res.points[lay.loop_node[loops]].astype(np.float32)
        job.new_uv = new
    elif res.status != "failed":
        job.notes.append("no improvement over the input: UVs unchanged")


def apply(obj: bpy.types.Object, job: UVJob, *, write: bool = True) -> UVObjectResult:
    """Write a computed job back (Object Mode) and describe the outcome."""
    out = UVObjectResult(object=job.object, mesh=job.mesh, uv_map=job.uv_map,
                         targets=job.target_kind, notes=list(job.notes))
    if job.error:
        out.message = job.error
        return out
    res, lay = job.result, job.layout
    out.islands = lay.n_islands
    out.n_uv_vertices = lay.n_nodes
    out.n_faces = int(np.count_nonzero(job.selected))
    out.status = res.status
    if res.status == "failed":
        out.message = res.message
    out.seconds, out.backend = res.seconds, res.backend
    out.islands_run = sum(1 for r in res.islands if r.n_free)
    out.mirrored_islands = sum(1 for r in res.islands if r.mirrored)
    out.untangle_iterations, out.global_iterations, out.smooth_iterations = res.iterations
    out.n_free = res.n_free
    out.target_fallback = res.n_target_fallback
    out.notes += res.notes
    out.before = job.before.as_dict()
    out.after = (job.after or job.before).as_dict()
    if res.status == "cancelled":
        out.after = out.before
        return out
    if job.new_uv is not None and write:
        me = obj.data
        layer = me.uv_layers.get(job.uv_map)
        if layer is None or len(me.loops) != job.new_uv.shape[0]:
            out.status, out.message = "error", "mesh changed during the run, not written"
            return out
        uv_mesh.write_uv(me, layer, job.new_uv)
        out.written = True
    if not out.written:
        out.after = out.before
    left = int(out.after.get("inverted", 0))
    if left and out.status in ("valid", "untangled"):  # never claim more than the map holds
        out.status = "failed"
        out.message = f"{left} faces stay inverted" + ("" if out.written else
                                                       " (nothing written)")
    if (job.after or job.before).overlapping and res.status in ("valid", "untangled"):
        out.notes.append("overlaps left inside islands come from their fixed borders (a "
                         "border that crosses itself)")
    return out


def run_object(obj: bpy.types.Object, params: EEGTParams, uv_name: str | None = None, *,
               backend: str = "numpy", device: str | None = None, selected_only: bool = False,
               sync: bool = True, select_mode: str = "VERTEX", use_pins: bool = True,
               targets: str = "3D", scope: str = "tangles",
               progress: Progress | None = None, write: bool = True,
               write_on_fail: bool = True) -> UVObjectResult:
    """Prepare, compute and apply in one call (Object Mode, main thread); with
    ``write_on_fail`` off a map that keeps flipped faces is left as it was."""
    t0 = time.perf_counter()
    job = prepare(obj, uv_name, selected_only=selected_only, sync=sync,
                  select_mode=select_mode, use_pins=use_pins, targets=targets, scope=scope)
    compute(job, params, backend, progress, device)
    ok = job.error is None and job.result is not None and \
        job.result.status in ("valid", "untangled")
    result = apply(obj, job, write=write and (ok or write_on_fail))
    if result.seconds == 0.0:
        result.seconds = time.perf_counter() - t0
    return result


def objects_with_uv_map(objs: list[bpy.types.Object],
                        name: str | None) -> tuple[list[bpy.types.Object], list[dict[str, str]]]:
    """The objects that have the UV map ``name`` (default: any UV map) and the skipped
    others with their reason; ValueError (one line) when none has it."""
    kept, skipped = [], []
    for obj in objs:
        try:
            uv_mesh.uv_layer(obj.data, name)
            kept.append(obj)
        except ValueError as exc:
            skipped.append({"object": obj.name, "reason": str(exc)})
    if not kept:
        maps = sorted({uv.name for o in objs for uv in o.data.uv_layers})
        have = f" (UV maps: {', '.join(maps)})" if maps else ""
        what = f"a UV map named '{name}'" if name else "a UV map"
        raise ValueError(f"no chosen mesh object has {what}{have}")
    return kept, skipped
