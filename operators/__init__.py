# SPDX-License-Identifier: GPL-3.0-or-later
"""Everything that touches bpy, by role: ``mesh/`` (vertex-position runs and their
operators), ``uv/`` (UV runs), ``command/`` (the ``eegt`` command line), ``ui/`` (settings,
preferences, panel), ``solver_io/`` (solver meshes as Blender objects, File > Import /
Export > Solver mesh), ``live/`` (Live Untangle: drag a vertex, the rest follows) and
``shared/`` (run result, modes).

Thin by design: the algorithm lives in ``core`` (NumPy only).
"""

from __future__ import annotations

from . import live
from .command import entry
from .mesh import ops_pin, ops_quality, ops_untangle
from .solver_io import ops as solver_ops
from .ui import panel, prefs, props
from .uv import ops_uv, panel_uv, uv_props

_modules = (props, prefs, ops_untangle, ops_quality, ops_pin, panel, entry,
            uv_props, ops_uv, panel_uv, solver_ops, live)


def register() -> None:
    """Register every module in dependency order."""
    for mod in _modules:
        mod.register()


def unregister() -> None:
    """Unregister in reverse order."""
    for mod in reversed(_modules):
        mod.unregister()
