# SPDX-License-Identifier: GPL-3.0-or-later
"""Solver meshes in Blender: File > Import / Export > Solver mesh and the command's solver
mesh input and output (docs/engineers.md). Formats and file handling: ``batch/solver_mesh``."""

from __future__ import annotations

from . import ops


def register() -> None:
    ops.register()


def unregister() -> None:
    ops.unregister()
