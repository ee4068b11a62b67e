# SPDX-License-Identifier: GPL-3.0-or-later
"""Live Untangle (docs/live.md): drag a vertex, the rest untangles and smooths as it goes.

Modal tools in the UV editor and the 3D View's Edit Mode (``ops_live``), the drags they run
(``drag``), a button in each EEGT sidebar tab, menu entries (UV, Mesh) and the shortcut
Ctrl+Alt+L in both editors.
"""

from __future__ import annotations

import bpy

from . import ops_live

SHORTCUT = {"type": "L", "value": "PRESS", "ctrl": True, "alt": True}
_keymaps: list[tuple[bpy.types.KeyMap, bpy.types.KeyMapItem]] = []


class IMAGE_PT_eegt_live(bpy.types.Panel):
    """Live Untangle in the UV editor's EEGT tab"""

    bl_space_type = "IMAGE_EDITOR"
    bl_region_type = "UI"
    bl_category = "EEGT"
    bl_label = "Live Untangle"
    bl_idname = "IMAGE_PT_eegt_live"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return context.mode == "EDIT_MESH" and getattr(context.space_data, "mode", "UV") == "UV"

    def draw(self, context: bpy.types.Context) -> None:
        row = self.layout.row()
        row.scale_y = 1.4
        row.operator(ops_live.UV_OT_eegt_live_untangle.bl_idname, icon="MOUSE_LMB_DRAG")
        self.layout.label(text="Drag a UV vertex (Ctrl Alt L)")


class VIEW3D_PT_eegt_live(bpy.types.Panel):
    """Live Untangle in the 3D View's EEGT tab"""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "EEGT"
    bl_label = "Live Untangle"
    bl_idname = "VIEW3D_PT_eegt_live"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return context.mode == "EDIT_MESH"

    def draw(self, context: bpy.types.Context) -> None:
        row = self.layout.row()
        row.scale_y = 1.4
        row.operator(ops_live.MESH_OT_eegt_live_untangle.bl_idname, icon="MOUSE_LMB_DRAG")
        self.layout.label(text="Drag a vertex (Ctrl Alt L)")


def _menu_uv(self: bpy.types.Menu, _context: bpy.types.Context) -> None:
    self.layout.operator(ops_live.UV_OT_eegt_live_untangle.bl_idname, icon="MOUSE_LMB_DRAG")


def _menu_mesh(self: bpy.types.Menu, _context: bpy.types.Context) -> None:
    self.layout.operator(ops_live.MESH_OT_eegt_live_untangle.bl_idname, icon="MOUSE_LMB_DRAG")


classes = (*ops_live.classes, IMAGE_PT_eegt_live, VIEW3D_PT_eegt_live)


def register() -> None:
    """Operators, panels, menu entries and the shortcut (the add-on keymap, when there is
    one: not in background mode)."""
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.IMAGE_MT_uvs.append(_menu_uv)
    bpy.types.VIEW3D_MT_edit_mesh.append(_menu_mesh)
    kc = bpy.context.window_manager.keyconfigs.addon if bpy.context.window_manager else None
    if kc is None:
        return
    for name, space, op in (("UV Editor", "EMPTY", ops_live.UV_OT_eegt_live_untangle),
                            ("Mesh", "EMPTY", ops_live.MESH_OT_eegt_live_untangle)):
        km = kc.keymaps.new(name=name, space_type=space)
        _keymaps.append((km, km.keymap_items.new(op.bl_idname, **SHORTCUT)))


def unregister() -> None:
    """Remove what :func:`register` added."""
    for km, kmi in _keymaps:
        km.keymap_items.remove(kmi)
    _keymaps.clear()
    bpy.types.VIEW3D_MT_edit_mesh.remove(_menu_mesh)
    bpy.types.IMAGE_MT_uvs.remove(_menu_uv)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
