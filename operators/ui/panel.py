# SPDX-License-Identifier: GPL-3.0-or-later
"""The "EEGT" tab of the 3D View sidebar."""

from __future__ import annotations

import bpy

from ..shared.result import draw_last_run
from . import props


class _EEGTTab:
    """Where every panel of the extension lives: the 3D View sidebar's EEGT tab."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "EEGT"


def draw_boundary_target(layout: bpy.types.UILayout, owner, obj) -> None:
    """Boundary mode, feature angle (slide), target shape, region (whole mesh or folds
    only) and, for target 'reference', its shape key (searched among ``obj``'s keys) or
    object: the scene settings or an operator's own properties (its reference object is a
    name there)."""
    col = layout.column(align=True)
    col.prop(owner, "boundary")
    if owner.boundary == "slide":
        col.prop(owner, "feature_angle")
    col = layout.column(align=True)
    col.prop(owner, "target", text="Target")
    layout.prop(owner, "region")
    if owner.target != "reference":
        return
    keys = obj.data.shape_keys if obj is not None and obj.type == "MESH" else None
    if keys is not None:
        col.prop_search(owner, "reference_key", keys, "key_blocks", text="Key")
    else:
        col.prop(owner, "reference_key", text="Key")
    if isinstance(owner.bl_rna.properties["reference_object"], bpy.types.PointerProperty):
        col.prop(owner, "reference_object", text="Object")
    else:
        col.prop_search(owner, "reference_object", bpy.data, "objects", text="Object")


class VIEW3D_PT_eegt(_EEGTTab, bpy.types.Panel):
    """Parameters, pins, analysis and the Untangle & Smooth button"""

    bl_label = "EEGT Untangle & Smooth"
    bl_idname = "VIEW3D_PT_eegt"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        settings = context.scene.eegt_settings
        col = layout.column(align=True)
        row = col.row(align=True)
        row.scale_y = 1.4
        row.operator("mesh.eegt_untangle_smooth", icon="MOD_SMOOTH")
        row = col.row(align=True)
        analyze = row.operator("mesh.eegt_analyze", icon="VIEWZOOM")
        analyze.measure = settings.quality_measure
        row.operator("mesh.eegt_select_inverted", text="Select Inverted",
                     icon="RESTRICT_SELECT_OFF")
        col.prop(settings, "quality_measure", text="Measure")
        layout.prop(settings, "backend")
        draw_boundary_target(layout, settings, context.active_object)
        row = layout.row(align=True)
        row.operator("mesh.eegt_pin", icon="PINNED")
        row.operator("mesh.eegt_unpin", icon="UNPINNED")
        row = layout.row(align=True)
        row.prop(settings, "use_pinned")
        row.prop(settings, "project")


class VIEW3D_PT_eegt_params(_EEGTTab, bpy.types.Panel):
    """Every EEGT parameter (defaults of the operator)"""

    bl_label = "Parameters"
    bl_idname = "VIEW3D_PT_eegt_params"
    bl_parent_id = "VIEW3D_PT_eegt"
    bl_options = {"DEFAULT_CLOSED"}  # noqa: RUF012

    def draw(self, context: bpy.types.Context) -> None:
        props.draw_param_fields(self.layout, context.scene.eegt_settings,
                                skip=props.MAIN_PANEL_FIELDS)


class VIEW3D_PT_eegt_last_run(_EEGTTab, bpy.types.Panel):
    """Statistics of the last run on the active object"""

    bl_label = "Last Run"
    bl_idname = "VIEW3D_PT_eegt_last_run"
    bl_parent_id = "VIEW3D_PT_eegt"

    def draw(self, context: bpy.types.Context) -> None:
        obj = context.active_object
        draw_last_run(self.layout, obj, "mesh", obj.name if obj is not None else "")


classes = (VIEW3D_PT_eegt, VIEW3D_PT_eegt_params, VIEW3D_PT_eegt_last_run)


# Register in order, unregister in reverse (Blender's own helper).
register, unregister = bpy.utils.register_classes_factory(classes)
