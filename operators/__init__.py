# SPDX-License-Identifier: GPL-3.0-or-later
"""Everything that touches bpy: mesh I/O, operators, properties, panels, preferences, CLI.

Thin by design: the algorithm lives in ``core`` (NumPy only).
"""

from __future__ import annotations

from . import (
    cli,
    live,
    ops_pin,
    ops_quality,
    ops_untangle,
    ops_uv,
    panel,
    panel_uv,
    prefs,
    props,
    uv_props,
)

_modules = (props, prefs, ops_untangle, ops_quality, ops_pin, panel, cli,
            uv_props, ops_uv, panel_uv, live)


def register() -> None:
    """Register every module in dependency order."""
    for mod in _modules:
        mod.register()


def unregister() -> None:
    """Unregister in reverse order."""
    for mod in reversed(_modules):
        mod.unregister()
