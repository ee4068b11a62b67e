# SPDX-License-Identifier: GPL-3.0-or-later
"""What runs read and write besides Blender's own meshes: solver mesh files and the report
schema. Plain Python and NumPy (meshio for the files), no bpy, no algorithm: the command,
the Export operator and the many-files batch all use it.

- `solver_formats`: the solver formats by name and extension (constants only).
- `solver_mesh`: read a solver mesh into arrays, write moved nodes back with everything
  else kept (docs/engineers.md).
- `run_stats`: the stats block of a run's report per kind of run (mesh, UV), read by the
  sidebar, the JSON reports and the batch summary.
"""
