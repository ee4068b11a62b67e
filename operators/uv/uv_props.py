# SPDX-License-Identifier: GPL-3.0-or-later
"""Settings of the UV tools (scene) and the statistics of the last UV run (object).

The EEGT parameters and the backend are shared with the mesh operator (``eegt_settings``);
only what is UV-specific lives here.
"""

from __future__ import annotations

from typing import Any

import bpy
from bpy.props import BoolProperty, EnumProperty, StringProperty

from ...core.choices import UV_SCOPE, UV_TARGET
from ...fileio.run_stats import UV
from ..ui.props import enum_items, last_run_class

TARGET_ITEMS = enum_items(UV_TARGET)
SCOPE_ITEMS = enum_items(UV_SCOPE, upper=True)

SELECT_ITEMS: tuple[tuple[str, str, str], ...] = (
    ("FLIPPED", "Flipped", "Faces whose area is reversed (or zero) against their island"),
    ("INVERTED", "Inverted", "Flipped faces and faces with a corner turned inside out (the "
                             "faces Untangle & Smooth UVs removes)"),
    ("OVERLAPPING", "Overlapping", "Faces that cover part of another face of their island "
                                   "(overlap between islands is layout: not counted)"),
)


def option_annotations(options: set[str] | None = None) -> dict[str, Any]:
    """The UV-specific options (scene settings and the operator's redo panel)."""
    opt = {"options": options} if options is not None else {}
    return {
        "use_pins": BoolProperty(name="Keep Pinned UVs", default=True, **opt,
                                 description="UVs pinned in the UV editor (P) stay fixed"),
        "target_shape": EnumProperty(name="Target Shape", items=TARGET_ITEMS,
                                     default=UV_TARGET[0].id,
                                     description="The shape each UV face is pulled towards",
                                     **opt),
        "scope": EnumProperty(name="Move", items=SCOPE_ITEMS, default=UV_SCOPE[0].id.upper(),
                              description="Which of the selected faces move", **opt),
    }


OPTION_NAMES = tuple(option_annotations())

EEGT_PG_uv_settings = type("EEGT_PG_uv_settings", (bpy.types.PropertyGroup,), {
    "__annotations__": option_annotations(),
    "__doc__": "UV settings of Untangle & Smooth UVs (defaults of the operator)",
})


EEGT_PG_uv_last_run = last_run_class(
    "EEGT_PG_uv_last_run",
    "Statistics of the last UV run on an object (shown in the UV editor's sidebar)",
    UV, {"uv_map": StringProperty(default="")})


classes = (EEGT_PG_uv_settings, EEGT_PG_uv_last_run)


def register() -> None:
    """Register the property groups and attach them to Scene and Object."""
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.eegt_uv_settings = bpy.props.PointerProperty(type=EEGT_PG_uv_settings)
    bpy.types.Object.eegt_last_uv_run = bpy.props.PointerProperty(type=EEGT_PG_uv_last_run)


def unregister() -> None:
    """Remove what :func:`register` added."""
    del bpy.types.Object.eegt_last_uv_run
    del bpy.types.Scene.eegt_uv_settings
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
