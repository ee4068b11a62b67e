# SPDX-License-Identifier: GPL-3.0-or-later
"""EEGT Untangle & Smooth: Blender extension entry point.

Only registers and unregisters; the operators live in ``operators/`` and the NumPy engine in
``core/`` (which never imports bpy).
"""

# The operators are imported when Blender registers the extension, not when this file is
# imported: pytest imports it as the package of the checkout's folder, whose name (e.g.
# mktemp's tmp.XXXXXXXXXX) need not be importable as a parent for relative imports.


def register() -> None:
    """Register every class, property and the ``eegt`` command-line command."""
    from . import operators

    operators.register()


def unregister() -> None:
    """Undo :func:`register`."""
    from . import operators

    operators.unregister()
