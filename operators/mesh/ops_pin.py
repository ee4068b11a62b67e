# SPDX-License-Identifier: GPL-3.0-or-later
"""``mesh.eegt_pin`` / ``mesh.eegt_unpin``: mark vertices that the EEGT operator never moves.

Pins live in the boolean point attribute ``eegt_pinned`` (an existing float or integer one
is edited in place). A vertex group of that name also pins; Blender refuses an attribute
whose name equals a vertex group's, so when the group exists the pins are written to the
group instead.
"""

from __future__ import annotations

import bpy
import numpy as np
from bpy.props import BoolProperty

from ..shared import modes
from ..shared.refusal import refusal
from . import mesh_io


def set_pins(obj: bpy.types.Object, mask: np.ndarray, value: bool) -> str | None:
    """Pin (value=True) or unpin the vertices in ``mask``; returns an error line or None.

    A new attribute is boolean; an existing FLOAT / INT / INT8 point attribute (which the
    untangle operator also reads, nonzero = pinned) is edited in its own type (1 / 0).
    """
    me = obj.data
    idx = np.flatnonzero(mask)
    vg = obj.vertex_groups.get(mesh_io.PIN_NAME)
    attr = me.attributes.get(mesh_io.PIN_NAME)
    if attr is not None:
        try:
            cur = mesh_io.pin_attribute_values(me)
        except ValueError as exc:
            return str(exc)
    if vg is not None:
        if value:
            vg.add(idx.tolist(), 1.0, "REPLACE")
        else:
            vg.remove(idx.tolist())
    if attr is None and value and vg is None:
        attr = me.attributes.new(mesh_io.PIN_NAME, "BOOLEAN", "POINT")
        if attr is None:
            return f"Blender refused to create the attribute '{mesh_io.PIN_NAME}'"
        cur = np.zeros(len(me.vertices), dtype=bool)
    if attr is not None:
        cur[idx] = value  # 1 / 0 in a float or integer attribute; other values stay as they are
        attr.data.foreach_set("value", cur)
    me.update()
    return None


class _PinBase(modes.TargetObjectsMixin):
    value = True

    def _run(self, objs: list[bpy.types.Object]) -> set[str]:
        everything = bool(getattr(self, "all", False))
        todo = []
        for obj in objs:
            why = refusal(obj)
            if why:
                self.report({"WARNING"}, f"{obj.name}: {why}")
                continue
            n = len(obj.data.vertices)
            mask = np.ones(n, bool) if everything else mesh_io.read_vertex_selection(obj.data)
            if mask.any():
                todo.append((obj, mask))
        if not todo:
            self.report({"WARNING"}, "No vertices selected")
            return {"CANCELLED"}
        done = False
        for obj, mask in todo:
            err = set_pins(obj, mask, self.value)
            if err:
                self.report({"WARNING"}, f"{obj.name}: {err}")
                continue
            done = True
            total = int(mesh_io.read_pins(obj).sum())
            verb = "pinned" if self.value else "unpinned"
            self.report({"INFO"}, f"{obj.name}: {int(mask.sum())} vertices {verb}, "
                                  f"{total} pinned in all")
        return {"FINISHED"} if done else {"CANCELLED"}


class MESH_OT_eegt_pin(_PinBase, bpy.types.Operator):
    """Pin the selected vertices: EEGT never moves them (eegt_pinned attribute)"""

    bl_idname = "mesh.eegt_pin"
    bl_label = "Pin Selected"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012
    value = True


class MESH_OT_eegt_unpin(_PinBase, bpy.types.Operator):
    """Unpin the selected vertices (or all vertices)"""

    bl_idname = "mesh.eegt_unpin"
    bl_label = "Unpin"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012
    value = False

    all: BoolProperty(  # type: ignore[valid-type]
        name="All", default=False, description="Unpin every vertex, not only the selected ones")


classes = (MESH_OT_eegt_pin, MESH_OT_eegt_unpin)


# Register in order, unregister in reverse (Blender's own helper).
register, unregister = bpy.utils.register_classes_factory(classes)
