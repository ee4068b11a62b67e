# SPDX-License-Identifier: GPL-3.0-or-later
"""EEGT Untangle & Smooth: Blender extension entry point.

Only registers and unregisters; the operators live in ``operators/`` and the NumPy engine in
``core/`` (which never imports bpy).
"""

from . import operators


def register() -> None:
    """Register every class, property and the ``eegt`` command-line command."""
    operators.register()


def unregister() -> None:
    """Undo :func:`register`."""
    operators.unregister()
