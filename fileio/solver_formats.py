# SPDX-License-Identifier: GPL-3.0-or-later
"""The solver mesh formats the command reads and writes through meshio (docs/engineers.md).

Constants only (no NumPy, no meshio), so that the batch's input scan and the command's
argument checks can name the formats without loading a reader.
"""

from __future__ import annotations

# --format name -> (file extension, meshio's reader/writer name)
SOLVER_FORMATS = {
    "msh": (".msh", "gmsh"),
    "vtk": (".vtk", "vtk"),
    "vtu": (".vtu", "vtu"),
    "inp": (".inp", "abaqus"),
    "mesh": (".mesh", "medit"),
    "su2": (".su2", "su2"),
}
SOLVER_EXTENSIONS = tuple(ext for ext, _ in SOLVER_FORMATS.values())
SOLVER_LABEL = "Solver mesh (" + ", ".join(SOLVER_EXTENSIONS) + ")"


def solver_format(path: str) -> str | None:
    """The --format name of a solver mesh path (by its extension, any case), or None."""
    lower = path.lower()
    for name, (ext, _) in SOLVER_FORMATS.items():
        if lower.endswith(ext):
            return name
    return None
