# SPDX-License-Identifier: GPL-3.0-or-later
"""The registered ``-c eegt`` command: a batch command line goes to ``batch.py``, any other
to the single-file command of ``cli.py``."""

from __future__ import annotations

from typing import Any

import bpy

from . import batch, cli


def execute(argv: list[str]) -> int:
    """The registered command handler: the process exit code. Many inputs, a folder, a
    glob pattern, an output folder or a batch flag make it a batch (batch.py),
    whose workers run this single-file command."""
    argv = list(argv)
    if batch.is_batch(argv):
        return batch.run(argv)
    return cli.run(argv)[0]


_handle: Any = None


def register() -> None:
    """Register ``-c eegt`` (Blender 4.2+)."""
    global _handle
    if _handle is None:
        _handle = bpy.utils.register_cli_command("eegt", execute)


def unregister() -> None:
    """Remove ``-c eegt``."""
    global _handle
    if _handle is not None:
        bpy.utils.unregister_cli_command(_handle)
        _handle = None

