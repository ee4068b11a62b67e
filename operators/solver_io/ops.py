# SPDX-License-Identifier: GPL-3.0-or-later
"""File > Import / Export > Solver mesh: read a solver mesh into a mesh object, write one
back into its file's blocks and data (docs/engineers.md)."""

from __future__ import annotations

import os

import bpy
from bpy.props import StringProperty
from bpy_extras.io_utils import ExportHelper, ImportHelper

from ...fileio import solver_mesh
from ...fileio.solver_formats import SOLVER_EXTENSIONS, SOLVER_LABEL, solver_format
from . import blender_mesh

_GLOB = ";".join("*" + e for e in SOLVER_EXTENSIONS)


class EEGT_OT_import_solver_mesh(bpy.types.Operator, ImportHelper):
    """Import a solver mesh: 2D cells as faces, point data as attributes, groups as vertex
    groups, a pin field as eegt_pinned"""

    bl_idname = "eegt.import_solver_mesh"
    bl_label = "Import Solver Mesh"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012

    filter_glob: StringProperty(default=_GLOB, options={"HIDDEN"})  # type: ignore[valid-type]
    pin_field: StringProperty(  # type: ignore[valid-type]
        name="Pin Field", default="",
        description="Point-data array whose non-zero nodes are pinned (eegt_pinned)")

    def execute(self, context: bpy.types.Context) -> set[str]:
        try:
            sm = solver_mesh.read(self.filepath)
            pinned = sm.pin_field(self.pin_field) if self.pin_field else None
        except solver_mesh.SolverMeshError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        name = os.path.splitext(os.path.basename(self.filepath))[0] or "mesh"
        obj = blender_mesh.build_object(sm, name, pinned)
        for other in context.view_layer.objects:
            other.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
        self.report({"INFO"}, f"{name}: {sm.n_points} points, {sm.n_faces} faces")
        return {"FINISHED"}


class EEGT_OT_export_solver_mesh(bpy.types.Operator, ExportHelper):
    """Write the active imported solver mesh back into its file's blocks and data, with the
    moved vertices' positions"""

    bl_idname = "eegt.export_solver_mesh"
    bl_label = "Export Solver Mesh"

    filename_ext = ".msh"
    filter_glob: StringProperty(default=_GLOB, options={"HIDDEN"})  # type: ignore[valid-type]
    check_extension = False  # the format is the file name's extension

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        obj = context.active_object
        return obj is not None and obj.type == "MESH" and bool(
            obj.data.get(blender_mesh.SOURCE))

    def invoke(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        src = context.active_object.data.get(blender_mesh.SOURCE, "")
        if src and not self.filepath:
            stem, ext = os.path.splitext(src)
            self.filepath = stem + "_eegt" + ext
        return super().invoke(context, event)

    def execute(self, context: bpy.types.Context) -> set[str]:
        if solver_format(self.filepath) is None:
            self.report({"ERROR"}, f"'{self.filepath}': use {', '.join(SOLVER_EXTENSIONS)}")
            return {"CANCELLED"}
        try:
            moved = blender_mesh.write_object(context.active_object, self.filepath)
        except (solver_mesh.SolverMeshError, OSError) as exc:  # the file at `filepath` is
            self.report({"ERROR"}, str(exc))  # as it was: written beside, then replaced
            return {"CANCELLED"}
        self.report({"INFO"}, f"wrote {self.filepath} ({moved} nodes moved)")
        return {"FINISHED"}


def _menu_import(self: bpy.types.Menu, context: bpy.types.Context) -> None:
    self.layout.operator(EEGT_OT_import_solver_mesh.bl_idname, text=SOLVER_LABEL)


def _menu_export(self: bpy.types.Menu, context: bpy.types.Context) -> None:
    self.layout.operator(EEGT_OT_export_solver_mesh.bl_idname, text=SOLVER_LABEL)


CLASSES = (EEGT_OT_import_solver_mesh, EEGT_OT_export_solver_mesh)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(_menu_import)
    bpy.types.TOPBAR_MT_file_export.append(_menu_export)


def unregister() -> None:
    bpy.types.TOPBAR_MT_file_export.remove(_menu_export)
    bpy.types.TOPBAR_MT_file_import.remove(_menu_import)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
