# SPDX-License-Identifier: GPL-3.0-or-later
"""Solver meshes in Blender: a solver mesh file as a mesh object and back
(``blender_mesh``), and File > Import / Export > Solver mesh (``ops``); docs/engineers.md.
Formats and file handling: ``fileio/solver_mesh``; the command's solver run:
``command/solver_run``."""
