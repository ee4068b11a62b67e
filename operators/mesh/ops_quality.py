# SPDX-License-Identifier: GPL-3.0-or-later
"""``mesh.eegt_analyze`` and ``mesh.eegt_select_inverted``: per-face quality measures (the mean
ratio by default, or any measure of ``core.metrics.measures``) and their heat map."""

from __future__ import annotations

import bpy
import numpy as np
from bpy.props import BoolProperty, FloatProperty

from ...core import MEASURES, faces_from_csr, quality, summarize
from ...core.mesh import PlaneFrame
from ...core.metrics import goodness
from ...fileio.run_stats import MESH
from ..shared import modes
from ..shared.refusal import refusal
from ..shared.report_lines import stat_values
from ..ui import props
from . import mesh_io, runner


def attribute_name(measure: str) -> str:
    """The face attribute a measure is stored in: ``eegt_quality`` for the mean ratio,
    ``eegt_<measure>`` for the others."""
    return mesh_io.QUALITY_NAME if measure == "mean_ratio" else f"eegt_{measure}"


def face_quality(obj: bpy.types.Object, measure: str = "mean_ratio") -> np.ndarray:
    """``measure`` (default: the mean ratio) of every face of ``obj`` (Blender face order);
    ValueError on bad input."""
    me = obj.data
    topo = mesh_io.read_topology(me)
    if topo.loop_start.size == 0:
        raise ValueError("mesh has no faces")
    key = obj.active_shape_key if me.shape_keys is not None else None
    co = mesh_io.read_key_positions(key) if key is not None else mesh_io.read_positions(me)
    pts3d = co.astype(np.float64)
    used = np.zeros(len(co), dtype=bool)
    used[topo.corner_verts] = True
    if not np.isfinite(pts3d[used]).all():
        raise ValueError("vertices with NaN or infinite coordinates")
    faces = faces_from_csr(topo.loop_start, topo.loop_total, topo.corner_verts)
    frame = PlaneFrame.fit(pts3d, faces, used=used, tol=runner.PLANE_TOL)
    return np.asarray(quality(frame.to_2d(pts3d), faces, measure=measure), dtype=np.float64)


def heat_colors(q: np.ndarray) -> np.ndarray:
    """RGBA per face from a heat-map position (the mean ratio itself, else
    ``core.metrics.measures.goodness``): pure red at 0 (inverted, or at/past the measure's worst),
    then red -> yellow (the threshold) -> green as it goes 0 -> 1."""
    q = np.clip(q, 0.0, 1.0)
    rgba = np.empty((q.size, 4), dtype=np.float32)
    rgba[:, 0] = np.clip(2.0 * (1.0 - q), 0.0, 1.0)
    rgba[:, 1] = np.clip(2.0 * q, 0.0, 1.0)
    rgba[:, 2] = 0.1
    rgba[:, 3] = 1.0
    rgba[q <= 0.0] = (1.0, 0.0, 0.0, 1.0)
    return rgba


def quality_layout(measure: str = "mean_ratio") -> dict[str, tuple[str, str]]:
    """Name -> (type, domain) of the two attributes Analyze writes for ``measure``."""
    return {attribute_name(measure): ("FLOAT", "FACE"),
            mesh_io.QUALITY_COLOR_NAME: ("FLOAT_COLOR", "CORNER")}


def quality_name_clash(obj: bpy.types.Object, measure: str = "mean_ratio") -> str | None:
    """Why the attributes of ``measure`` cannot be stored on ``obj``'s mesh, or None.

    An existing measure attribute (``eegt_quality`` for the mean ratio, ``eegt_<measure>``
    otherwise) or ``eegt_quality_color`` of the add-on's own type and domain
    is ours from an earlier run and is overwritten. One of another type or domain is the
    user's data (named so by hand, or by a script or geometry nodes): replacing it would
    delete it, and "attributes stay identical" (docs/method.md 7) is the promise, so storing is
    refused, with the attribute and the mesh left exactly as they were. A vertex group of
    either name blocks it too (Blender refuses the attribute); both are checked before
    anything is written, so a refusal never leaves half the pair.
    """
    me = obj.data
    for name, (data_type, domain) in quality_layout(measure).items():
        if obj.vertex_groups.get(name) is not None:
            return (f"a vertex group is named '{name}': rename it to store quality "
                    f"(nothing written)")
        attr = me.attributes.get(name)
        if attr is not None and (attr.data_type, attr.domain) != (data_type, domain):
            return (f"attribute '{name}' exists as {attr.data_type} on {attr.domain} (not the "
                    f"quality's {data_type} on {domain}): rename or remove it to store "
                    f"quality; it was left untouched")
    return None


def _attribute(me: bpy.types.Mesh, name: str, layout: dict[str, tuple[str, str]]):
    """The quality attribute ``name`` (ours: reused, else created), or None if refused."""
    attr = me.attributes.get(name)
    if attr is None:
        attr = me.attributes.new(name, *layout[name])
    return attr


def write_quality_attributes(obj: bpy.types.Object, q: np.ndarray,
                             measure: str = "mean_ratio") -> str | None:
    """Store the per-face values ``q`` of ``measure`` (face float: ``eegt_quality`` for the
    mean ratio, ``eegt_<measure>`` otherwise) and their heat map ``eegt_quality_color``
    (corner color, good -> bad in the measure's own direction and range).

    Returns an error line, with nothing written, when a user attribute of another type or
    domain has one of these names (see ``quality_name_clash``); an error line also when
    Blender refuses a name (a vertex group of the same name).
    """
    me = obj.data
    clash = quality_name_clash(obj, measure)
    if clash:
        return clash
    layout = quality_layout(measure)
    name = attribute_name(measure)
    had_colors = len(me.color_attributes) > 0
    attr = _attribute(me, name, layout)
    if attr is None:
        return f"cannot create attribute '{name}' (name in use)"
    attr.data.foreach_set("value", q.astype(np.float32))
    col = _attribute(me, mesh_io.QUALITY_COLOR_NAME, layout)
    if col is None:
        return f"cannot create attribute '{mesh_io.QUALITY_COLOR_NAME}' (name in use)"
    topo = mesh_io.read_topology(me)
    corner_face = mesh_io.corner_faces(topo)
    t = goodness(measure, q, topo.loop_total)
    col.data.foreach_set("color", heat_colors(t)[corner_face].ravel())
    if not had_colors:
        me.color_attributes.active_color = col
    me.update()
    return None


def _qualities(op: bpy.types.Operator, objs: list[bpy.types.Object],
               measure: str = "mean_ratio"):
    """(object, per-face values of ``measure``) of every object that can be measured; one
    warning line for each that cannot."""
    found: list[tuple[bpy.types.Object, np.ndarray]] = []
    for obj in objs:
        try:
            found.append((obj, face_quality(obj, measure)))
        except ValueError as exc:
            op.report({"WARNING"}, f"{obj.name}: {str(exc).splitlines()[0]}")
    return found


def _stats_line(obj: bpy.types.Object, q: np.ndarray, measure: str = "mean_ratio") -> str:
    """The report line: min / mean / max and the count beyond the threshold (the mean
    ratio keeps its inverted count, q_min and q_avg first)."""
    summary = summarize(measure, q, mesh_io.read_topology(obj.data).loop_total)
    if measure != "mean_ratio":
        return f"{obj.name}: {summary.line()}"
    s = runner.stats_from_quality(q)
    poor = MEASURES["mean_ratio"].threshold(3)  # the same for every arity
    return (f"{obj.name}: {q.size} faces, {stat_values(MESH, s, counts_first=True)}, "
            f"q_max {summary.max:.3f}, {summary.n_beyond} below {poor:g}")


class MESH_OT_eegt_analyze(modes.TargetObjectsMixin, bpy.types.Operator):
    """Measure the quality of every face (mean ratio, angles, aspect ratio, scaled Jacobian or skewness); store it as a face attribute and a heat-map color attribute"""  # noqa: E501

    bl_idname = "mesh.eegt_analyze"
    bl_label = "Analyze Quality"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012

    measure: props.measure_property(options={"SKIP_SAVE"})  # type: ignore[valid-type]
    store: BoolProperty(  # type: ignore[valid-type]
        name="Store Attributes", default=True,
        description="Write the measure's face attribute (eegt_quality for the mean ratio, "
                    "eegt_<measure> otherwise) and the eegt_quality_color heat map")

    def _run(self, objs: list[bpy.types.Object]) -> set[str]:
        found = _qualities(self, objs, self.measure)
        for obj, q in found:
            self.report({"INFO"}, _stats_line(obj, q, self.measure))
        written = False
        if self.store and found:
            for obj, q in found:
                if refusal(obj):
                    self.report({"WARNING"}, f"{obj.name}: {refusal(obj)}")
                    continue
                err = write_quality_attributes(obj, q, self.measure)
                if err:
                    self.report({"ERROR"}, f"{obj.name}: {err}")
                else:
                    written = True
        return {"FINISHED"} if written else {"CANCELLED"}


class MESH_OT_eegt_select_inverted(modes.TargetObjectsMixin, bpy.types.Operator):
    """Select the faces whose mean ratio quality is at most the threshold (0 = inverted faces only)"""  # noqa: E501

    bl_idname = "mesh.eegt_select_inverted"
    bl_label = "Select Inverted / Poor"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012

    threshold: FloatProperty(  # type: ignore[valid-type]
        name="Threshold", default=0.0, min=0.0, max=1.0,
        description="Select faces with quality <= this (0 selects inverted faces only)")
    extend: BoolProperty(  # type: ignore[valid-type]
        name="Extend", default=False, description="Keep the current selection")

    def execute(self, context: bpy.types.Context) -> set[str]:
        objs = modes.target_objects(context)
        if modes.is_edit_mode(context):
            # Face select mode keeps exactly the chosen faces (vertex mode would also select
            # every face whose vertices all happen to be selected).
            context.tool_settings.mesh_select_mode = (False, False, True)
        with modes.object_mode(context):
            return self._run(objs)

    def _run(self, objs: list[bpy.types.Object]) -> set[str]:
        found = [(obj, q <= self.threshold) for obj, q in _qualities(self, objs)]
        if not found:
            return {"CANCELLED"}
        for obj, sel in found:
            me = obj.data
            if self.extend:
                sel = sel | mesh_io.read_face_selection(me)
            sel &= ~mesh_io.read_face_hidden(me)
            topo = mesh_io.read_topology(me)
            vsel = np.zeros(len(me.vertices), dtype=bool)
            vsel[topo.corner_verts[sel[mesh_io.corner_faces(topo)]]] = True
            if self.extend:
                vsel |= mesh_io.read_vertex_selection(me)
            ev = np.empty(2 * len(me.edges), dtype=np.int32)
            me.edges.foreach_get("vertices", ev)
            esel = vsel[ev.reshape(-1, 2)].all(axis=1) if ev.size else np.zeros(0, bool)
            me.polygons.foreach_set("select", sel)
            me.vertices.foreach_set("select", vsel)
            me.edges.foreach_set("select", esel)
            me.update()
            self.report({"INFO"}, f"{obj.name}: {int(sel.sum())} faces with quality <= "
                                  f"{self.threshold:g} selected")
        return {"FINISHED"}


classes = (MESH_OT_eegt_analyze, MESH_OT_eegt_select_inverted)


# Register in order, unregister in reverse (Blender's own helper).
register, unregister = bpy.utils.register_classes_factory(classes)
