# SPDX-License-Identifier: GPL-3.0-or-later
"""Add-on preferences: default backend and OpenCL device."""

from __future__ import annotations

from typing import Any

import bpy
from bpy.props import EnumProperty

from ... import __package__ as base_package
from ...core.choices import BACKEND, ids
from .props import enum_items

# The core's backends in the order the preferences have always listed them (Blender saves an
# enum by its index, so a saved preference keeps its meaning).
PREFS_ORDER = ("numpy", "auto", "opencl")
DEFAULT_BACKEND_ITEMS = enum_items(tuple(c for i in PREFS_ORDER for c in BACKEND if c.id == i),
                                   upper=True)

# Blender needs Python to keep the strings of dynamic enum items alive.
_device_items_cache: list[tuple[str, str, str]] = []


_devices_found: list[tuple[str, str]] | None = None


def _list_devices() -> list[tuple[str, str]]:
    """(id, label) of the OpenCL devices the core sees; [] without the OpenCL backend.

    Asked once per session: enumerating OpenCL platforms can take a while and the enum
    callback runs on every redraw.
    """
    global _devices_found
    if _devices_found is None:
        try:
            from ...core.eegt import engine_opencl
            _devices_found = [(str(i), str(label)) for i, label in engine_opencl.list_devices()]
        except Exception:  # no backend module, no pyopencl, or a broken driver: "Automatic" only
            _devices_found = []
    return _devices_found


def device_items(_self: Any, _context: Any) -> list[tuple[str, str, str]]:
    """Enum items: Automatic, then every OpenCL device the core can see."""
    items = [("AUTO", "Automatic", "GPU first, then any other OpenCL device")]
    items += [(ident, label, label) for ident, label in _list_devices()]
    _device_items_cache[:] = items
    return _device_items_cache


class EEGT_AddonPreferences(bpy.types.AddonPreferences):
    """Defaults used by the sidebar and the batch command."""

    bl_idname = base_package

    default_backend: EnumProperty(  # type: ignore[valid-type]
        name="Default Backend", items=DEFAULT_BACKEND_ITEMS, default="NUMPY",
        description="Backend used when the operator's backend is 'Default'")
    opencl_device: EnumProperty(  # type: ignore[valid-type]
        name="OpenCL Device", items=device_items,
        description="OpenCL device for the OpenCL backend")

    def draw(self, _context: bpy.types.Context) -> None:
        layout = self.layout
        layout.prop(self, "default_backend")
        layout.prop(self, "opencl_device")


def get_prefs(context: bpy.types.Context | None = None) -> Any | None:
    """The add-on preferences, or None when the code runs outside the extension system."""
    ctx = context or bpy.context
    addon = ctx.preferences.addons.get(base_package)
    return addon.preferences if addon is not None else None


def _device_choice(prefs: Any) -> str | None:
    """The preferences' OpenCL device; "AUTO" when it was never set, without listing the
    devices (reading the enum lists them: that imports pyopencl and asks every driver, a
    tenth of a second that a fresh ``blender -b`` process then spends before its work)."""
    if not prefs.is_property_set("opencl_device"):
        return "AUTO"
    try:
        return prefs.opencl_device
    except (TypeError, ValueError):
        return None


def resolve_backend(
    choice: str, context: bpy.types.Context | None = None
) -> tuple[str, str | None]:
    """Map a backend enum value to the core's name, plus the OpenCL device (or None)."""
    prefs = get_prefs(context)
    if choice == "PREFS":
        choice = prefs.default_backend if prefs is not None else "NUMPY"
    device = None
    if prefs is not None and choice in ("OPENCL", "AUTO"):
        device = _device_choice(prefs)
    name = choice.lower()
    return (name if name in ids(BACKEND) else "numpy"), device


classes = (EEGT_AddonPreferences,)


# Register in order, unregister in reverse (Blender's own helper).
register, unregister = bpy.utils.register_classes_factory(classes)
