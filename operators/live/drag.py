# SPDX-License-Identifier: GPL-3.0-or-later
"""One live drag in Edit Mode: set up from the edit mesh, step per cursor position, restore.

``UVDrag`` moves UV vertices of the active UV map (the UV editor), ``MeshDrag`` vertices of
a planar mesh (the 3D View). Both read the mesh once (bulk reads in Object Mode, then back
in Edit Mode), keep the cursor within ``core.run.live.cursor_bounds``, run
``core.run.live.LiveSession`` frames and write only the values that changed into the edit
mesh (BMesh: there is no bulk write in Edit Mode), never a non-finite one. A moved UV vertex
is written to every loop of it (``core.run.live.uv_vertex_corners``). ``restore`` writes every
value read at the start back, bit for bit. No operator logic here: the modal operators drive
these.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import bmesh
import bpy
import numpy as np

from ...core import EEGTParams, faces_from_csr
from ...core.metrics import face_shapes_2d
from ...core.run import (
    FRAME_BUDGET,
    FRAME_ITERATIONS,
    LiveFrame,
    LiveSession,
    clamp_cursor,
    cursor_bounds,
    storable_float32,
    uv_region,
    uv_vertex_corners,
)
from ...core.run.live import UVRegion
from ...core.uv import UVLayout, keep_shape_targets, weld_uv
from ..mesh import mesh_io, runner
from ..shared import modes
from ..shared.refusal import refusal
from ..uv import uv_mesh


@dataclass
class StepTimes:
    """Seconds of the last step: the core frame and the writes into the edit mesh."""

    core: float = 0.0
    write: float = 0.0


def core_budget(budget: float | None, last: StepTimes) -> float | None:
    """The core's share of a frame's ``budget``: what the last frame's writes left of it."""
    return None if budget is None else budget - last.write


def nearest_within(points: np.ndarray, at: np.ndarray, radius: float,
                   among: np.ndarray | None = None) -> int | None:
    """Row of ``points`` nearest to ``at`` within ``radius`` (only rows in the bool mask
    ``among``), or None."""
    d = np.hypot(points[:, 0] - at[0], points[:, 1] - at[1])
    if among is not None:
        d = np.where(among, d, np.inf)
    i = int(np.argmin(d)) if d.size else -1
    return i if i >= 0 and d[i] <= radius else None


def press_shapes(layout: UVLayout, region: UVRegion, pins: np.ndarray | None,
                 shapes3d: np.ndarray) -> np.ndarray:
    """Target "Keep Shapes" (``choices.UV_TARGET`` "KEEP") of a UV drag: (C, 2) per-corner
    targets in ``layout.faces`` order, the layout as it is at the press
    (``core.uv.keep_shape_targets``): each face its own shape (island orientation, as the
    region sees it), a face tangled at the press (among the region's faces, with the pins
    ``pins``; a grabbed UV vertex counts as free, as the session's corners kept as given
    have it) a same-arity neighbour's, else its 3D face's (``shapes3d``). Made once per
    drag: the frames pull towards the layout the drag started from."""
    faces = np.zeros(layout.faces.n_faces, dtype=bool)
    faces[region.face_ids] = True
    held = np.zeros(layout.n_nodes, dtype=bool) if pins is None else pins.copy()
    held[region.nodes[region.grab]] = False
    return keep_shape_targets(layout, layout.points, faces, held, shapes3d).targets


class UVDrag:
    """A drag of UV vertices of ``obj``'s active UV map (Edit Mode).

    ``grab``: UV vertex ids (of the welded map, ``self.layout``) or None to pick: the UV
    vertex nearest to ``cursor`` within ``radius`` (UV units), else the UV vertices of the
    selected faces. The grabbed vertices keep their offset to the cursor (both clamped into
    ``self.bounds``). A moved UV vertex moves with all its loops, also those of faces outside
    the region (scope "selection": unselected faces that share it), so nothing tears.

    ``target_shape`` (``choices.UV_TARGET``): "3D" each face's 3D face, "REGULAR" the
    regular polygon, "KEEP" the layout at the press (``press_shapes``); made once, sliced
    to the region's corners (``self.target_shapes``)."""

    def __init__(self, obj: bpy.types.Object, cursor: tuple[float, float], params: EEGTParams,
                 *, radius: float = 0.0, grab: np.ndarray | None = None, use_pins: bool = True,
                 target_shape: str = "3D", scope: str = "tangles", sync: bool = True,
                 select_mode: str = "VERTEX"):
        why = refusal(obj)
        if why:
            raise ValueError(why)
        me = obj.data
        with modes.object_mode(bpy.context):  # bulk reads need Object Mode's arrays
            layer = uv_mesh.uv_layer(me)
            layer_name = layer.name
            topo = mesh_io.read_topology(me)
            if topo.loop_start.size == 0:
                raise ValueError("mesh has no faces")
            uv = uv_mesh.read_uv(me, layer)
            selected = uv_mesh.read_uv_face_selection(me, layer, sync, select_mode)
            shown = ~mesh_io.read_face_hidden(me)
            pinned = uv_mesh.read_uv_pins(me, layer) if use_pins else None
            co = mesh_io.read_positions(me).astype(np.float64)
        lay = weld_uv(topo.loop_start, topo.loop_total, topo.corner_verts, uv)
        self.layout = lay
        if grab is None:
            seen = np.zeros(lay.n_nodes, dtype=bool)
            seen[lay.faces.indices[np.repeat(shown, lay.faces.counts)]] = True
            pick = nearest_within(lay.points, np.asarray(cursor, float), radius, seen)
            if pick is not None:
                grab = np.array([pick])
            elif selected.any():
                grab = np.unique(lay.faces.indices[np.repeat(selected, lay.faces.counts)])
            else:
                raise ValueError("no UV vertex under the cursor and no UV selected")
        pins = None
        if pinned is not None:
            pins = np.zeros(lay.n_nodes, dtype=bool)
            pins[lay.loop_node[pinned]] = True
        region = uv_region(lay, grab, selected, scope, pins)
        targets = None
        if target_shape in ("3D", "KEEP"):
            fs3d = faces_from_csr(topo.loop_start, topo.loop_total, topo.corner_verts,
                                  len(me.vertices))
            targets = face_shapes_2d(co, fs3d)
            if target_shape == "KEEP":
                targets = press_shapes(lay, region, pins, targets)
            targets = targets[region.rows]
        self.target_shapes = targets  # (c, 2) the region's corners' targets; None: regular
        self.region = region
        self.session = LiveSession(region.points, region.faces, region.grab,
                                   fixed=region.fixed, params=params, targets=targets)
        self.start = region.points[region.grab].copy()
        self.mirrored_grab = region.mirrored[region.grab]
        self.bounds = cursor_bounds(lay.points[region.nodes])
        cursor0 = clamp_cursor(cursor, self.bounds)
        if cursor0 is None:
            raise ValueError("the cursor is at no place (NaN)")
        self.cursor0 = cursor0
        # every loop of the region's UV vertices (faces outside the region too), face by face
        faces, pick, self.loop_local = uv_vertex_corners(lay, region.nodes)
        self._corners = (faces, pick)
        self.me, self.layer_name = me, layer_name
        self._attach()
        self.original = np.array([lp[self.uvl].uv[:] for lp in self.loops], dtype=np.float32)
        self.written = self.original.copy()
        self.frame: LiveFrame | None = None
        self.times = StepTimes()

    def _attach(self) -> None:
        """The edit mesh's loops of the region, in the order of their values (again after a
        mode switch made new edit data)."""
        self.bm = bmesh.from_edit_mesh(self.me)
        self.bm.faces.ensure_lookup_table()
        self.uvl = self.bm.loops.layers.uv[self.layer_name]
        faces = self.bm.faces
        face, pick = self._corners  # faces with a loop to write; those loops among theirs
        every = [lp for f in face.tolist() for lp in faces[f].loops]
        self.loops = [every[i] for i in pick.tolist()]

    def targets_for(self, cursor: tuple[float, float] | None) -> np.ndarray | None:
        """The grabbed vertices' places (region coordinates) for a cursor in UV space
        (clamped into ``self.bounds``; None or NaN: None, where they are)."""
        at = clamp_cursor(cursor, self.bounds)
        if at is None:
            return None
        d = at - self.cursor0
        out = self.start.copy()
        out[:, 0] += np.where(self.mirrored_grab, -d[0], d[0])
        out[:, 1] += d[1]
        return out

    def step(self, cursor: tuple[float, float] | None, budget: float | None = FRAME_BUDGET,
             iterations: int = FRAME_ITERATIONS) -> LiveFrame:
        """One frame: the grabbed vertices at ``cursor`` (None: where they are), the core
        warm from the last frame, the changed UVs written into the edit mesh."""
        t0 = time.perf_counter()
        frame = self.session.frame(self.targets_for(cursor), iterations=iterations,
                                   budget=core_budget(budget, self.times))
        t1 = time.perf_counter()
        self.write_points(frame.points)
        self.frame = frame
        self.times = StepTimes(t1 - t0, time.perf_counter() - t1)
        return frame

    def write_points(self, points: np.ndarray) -> None:
        """The region's UV vertices at ``points`` (the session's coordinates) into the edit
        mesh: only the loops of UV vertices that moved (a loop a float32 step away from its
        UV vertex's value, welded, keeps its own bits, as Untangle & Smooth UVs keeps them)."""
        moved = np.any(points != self.region.points, axis=1)[self.loop_local]
        values = self.original.copy()
        values[moved] = storable_float32(self.region.to_uv(points)[self.loop_local[moved]])
        self._write(values)

    def _write(self, values: np.ndarray) -> None:
        if not self.bm.is_valid:
            self._attach()
        change = np.flatnonzero(np.any(values != self.written, axis=1))
        loops, uvl = self.loops, self.uvl
        for i, v in zip(change.tolist(), values[change].tolist(), strict=True):
            loops[i][uvl].uv = v
        self.written[change] = values[change]
        bmesh.update_edit_mesh(self.me, loop_triangles=False, destructive=False)

    def restore(self) -> None:
        """Every UV of the region back to its value at the start, bit for bit."""
        self._write(self.original)


class MeshDrag:
    """A drag of vertices of a planar mesh (Edit Mode): the whole mesh moves as Untangle &
    Smooth moves it (boundary, loose and ``eegt_pinned`` vertices stay), in its plane.

    ``grab``: vertex indices, or None to pick with ``pick`` (a function from (N, 3) vertex
    positions to (N, 2) screen positions, the cursor and a radius in pixels): the vertex
    under the cursor, else the selected vertices. Cursor places are clamped into
    ``self.bounds`` (plane coordinates)."""

    def __init__(self, obj: bpy.types.Object, params: EEGTParams, *,
                 grab: np.ndarray | None = None,
                 pick: tuple[Callable[[np.ndarray], np.ndarray], np.ndarray, float] | None = None,
                 use_pinned: bool = True):
        with modes.object_mode(bpy.context):  # bulk reads need Object Mode's arrays
            job = runner.prepare(obj, use_pinned=use_pinned)
            selection = mesh_io.read_vertex_selection(obj.data)
        if job.error:
            raise ValueError(job.error)
        if job.key_name:
            raise ValueError("live untangle works on the base mesh, not on shape keys")
        me = obj.data
        lut = np.full(len(me.vertices), -1, dtype=np.int64)
        lut[job.nodes] = np.arange(job.nodes.size)
        if grab is None:
            at = None if pick is None else nearest_within(
                pick[0](job.co.astype(np.float64)), pick[1], pick[2], lut >= 0)
            if at is not None:
                grab = np.array([at])
            else:
                grab = np.flatnonzero(selection & (lut >= 0))
                if grab.size == 0:
                    raise ValueError("no vertex under the cursor and none selected")
        local = lut[np.asarray(grab, dtype=np.int64)]
        if (local < 0).any():
            raise ValueError("a grabbed vertex is in no face")
        self.job, self.grab = job, local
        self.session = LiveSession(job.points2d, job.faces, local, fixed=job.fixed,
                                   params=params)
        self.start = job.points2d[local].copy()
        self.bounds = cursor_bounds(job.points2d)
        self.me = me
        self._attach()
        self.original = np.array([v.co[:] for v in self.verts], dtype=np.float32)
        self.written = self.original.copy()
        self.anchor: np.ndarray | None = None
        self.frame: LiveFrame | None = None
        self.times = StepTimes()

    def _attach(self) -> None:
        """The edit mesh's vertices of the run's nodes (again after a mode switch)."""
        self.bm = bmesh.from_edit_mesh(self.me)
        self.bm.verts.ensure_lookup_table()
        self.verts = [self.bm.verts[i] for i in self.job.nodes.tolist()]

    def plane_point(self, world_point: np.ndarray, matrix_world) -> np.ndarray:
        """A world-space point (on the mesh's plane) in the plane's 2D coordinates."""
        inv = np.array(matrix_world.inverted())
        local = inv[:3, :3] @ np.asarray(world_point, float) + inv[:3, 3]
        return self.job.frame.to_2d(local[None, :])[0]

    def step(self, at: np.ndarray | None, budget: float | None = FRAME_BUDGET,
             iterations: int = FRAME_ITERATIONS) -> LiveFrame:
        """One frame with the grabbed vertices moved by ``at`` minus the first ``at`` (plane
        coordinates, clamped into ``self.bounds``; None or NaN: where they are)."""
        t0 = time.perf_counter()
        targets = None
        at = clamp_cursor(at, self.bounds)
        if at is not None:
            if self.anchor is None:
                self.anchor = np.asarray(at, dtype=np.float64)
            targets = self.start + (np.asarray(at, dtype=np.float64) - self.anchor)
        frame = self.session.frame(targets, iterations=iterations,
                                   budget=core_budget(budget, self.times))
        t1 = time.perf_counter()
        self.write_points(frame.points)
        self.frame = frame
        self.times = StepTimes(t1 - t0, time.perf_counter() - t1)
        return frame

    def write_points(self, points: np.ndarray) -> None:
        """The mesh's nodes at ``points`` (plane coordinates) into the edit mesh: only the
        vertices that moved."""
        moved = points != self.job.points2d
        co = self.original.copy()
        rows = np.flatnonzero(moved.any(axis=1))
        co[rows] = storable_float32(self.job.frame.to_3d(points[rows]))
        self._write(co)

    def _write(self, co: np.ndarray) -> None:
        if not self.bm.is_valid:
            self._attach()
        change = np.flatnonzero(np.any(co != self.written, axis=1))
        verts = self.verts
        for i, c in zip(change.tolist(), co[change].tolist(), strict=True):
            verts[i].co = c
        self.written[change] = co[change]
        bmesh.update_edit_mesh(self.me, loop_triangles=True, destructive=False)

    def restore(self) -> None:
        """Every vertex back to its position at the start, bit for bit."""
        self._write(self.original)
