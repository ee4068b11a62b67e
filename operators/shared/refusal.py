# SPDX-License-Identifier: GPL-3.0-or-later
"""Whether an object's mesh may be written: every run, the pins and the quality attributes
ask this before they read or write a mesh, and report its reason as it is."""

from __future__ import annotations

import bpy


def refusal(obj: bpy.types.Object) -> str | None:
    """Why this object's mesh cannot be written (linked, library override), or None."""
    me = obj.data
    if obj.library is not None or me.library is not None:
        lib = (me.library or obj.library).filepath
        return f"mesh is linked from a library ({lib}), make it local first"
    if me.override_library is not None:
        return "mesh is a library override (its geometry cannot be saved), make it local first"
    if not me.is_editable:
        return "mesh data is not editable"
    return None
