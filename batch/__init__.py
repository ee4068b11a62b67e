# SPDX-License-Identifier: GPL-3.0-or-later
"""Many files in one ``eegt`` command: input expansion, worker processes, Dask, reports.

Plain Python (no bpy, no algorithm): every file is run by the single-file command in its own
``blender -b`` process; this package only finds the files, starts and watches those processes
and sums their reports up. The command side (argument parsing, Blender's binary) is
``operators/command/batch.py``.
"""
