# SPDX-License-Identifier: GPL-3.0-or-later
"""The "EEGT" tab of the UV editor's sidebar, and entries in its UV and Select menus."""

from __future__ import annotations

import bpy

from ..shared.result import draw_last_run
from ..ui import props


class _EEGTUVTab:
    """The UV editor's sidebar (Image Editor in UV mode), tab EEGT."""

    bl_space_type = "IMAGE_EDITOR"
    bl_region_type = "UI"
    bl_category = "EEGT"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        space = context.space_data
        return context.mode == "EDIT_MESH" and getattr(space, "mode", "UV") == "UV"


class IMAGE_PT_eegt_uv(_EEGTUVTab, bpy.types.Panel):
    """Untangle & Smooth UVs, selection of flipped and overlapping UVs, settings"""

    bl_label = "EEGT Untangle & Smooth UVs"
    bl_idname = "IMAGE_PT_eegt_uv"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        settings = context.scene.eegt_settings
        uv_settings = context.scene.eegt_uv_settings
        col = layout.column(align=True)
        row = col.row(align=True)
        row.scale_y = 1.4
        row.operator("uv.eegt_untangle_smooth", icon="MOD_SMOOTH")
        row = col.row(align=True)
        row.operator("uv.eegt_select_flipped", text="Select Flipped",
                     icon="RESTRICT_SELECT_OFF").kind = "FLIPPED"
        row.operator("uv.eegt_select_flipped", text="Overlapping",
                     icon="SELECT_INTERSECT").kind = "OVERLAPPING"
        layout.prop(uv_settings, "scope")
        layout.prop(uv_settings, "target_shape", text="Target")
        layout.prop(uv_settings, "use_pins")
        layout.prop(settings, "backend")


class IMAGE_PT_eegt_uv_params(_EEGTUVTab, bpy.types.Panel):
    """Every EEGT parameter (shared with the 3D View's EEGT tab)"""

    bl_label = "Parameters"
    bl_idname = "IMAGE_PT_eegt_uv_params"
    bl_parent_id = "IMAGE_PT_eegt_uv"
    bl_options = {"DEFAULT_CLOSED"}  # noqa: RUF012

    def draw(self, context: bpy.types.Context) -> None:
        props.draw_param_fields(self.layout, context.scene.eegt_settings)


class IMAGE_PT_eegt_uv_last_run(_EEGTUVTab, bpy.types.Panel):
    """Statistics of the last UV run on the active object"""

    bl_label = "Last UV Run"
    bl_idname = "IMAGE_PT_eegt_uv_last_run"
    bl_parent_id = "IMAGE_PT_eegt_uv"

    def draw(self, context: bpy.types.Context) -> None:
        obj = context.active_object
        lr = getattr(obj, "eegt_last_uv_run", None) if obj is not None else None
        title = f"{obj.name} '{lr.uv_map}'" if lr is not None else ""
        draw_last_run(self.layout, obj, "uv", title)


def _menu_uv(self: bpy.types.Menu, _context: bpy.types.Context) -> None:
    self.layout.separator()
    self.layout.operator("uv.eegt_untangle_smooth", icon="MOD_SMOOTH")


def _menu_select(self: bpy.types.Menu, _context: bpy.types.Context) -> None:
    self.layout.separator()
    self.layout.operator("uv.eegt_select_flipped", text="Select Flipped UVs").kind = "FLIPPED"
    self.layout.operator("uv.eegt_select_flipped",
                         text="Select Overlapping UVs").kind = "OVERLAPPING"


classes = (IMAGE_PT_eegt_uv, IMAGE_PT_eegt_uv_params, IMAGE_PT_eegt_uv_last_run)


def register() -> None:
    """Register the panels and add the menu entries."""
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.IMAGE_MT_uvs.append(_menu_uv)
    bpy.types.IMAGE_MT_select.append(_menu_select)


def unregister() -> None:
    """Remove the menu entries and the panels."""
    bpy.types.IMAGE_MT_select.remove(_menu_select)
    bpy.types.IMAGE_MT_uvs.remove(_menu_uv)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
