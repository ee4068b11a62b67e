"""In Blender (its Python, the installed extension's meshio): compare a solver mesh with the
one written from it. Run as: blender -b --python bl_solver_check.py -- IN OUT [MOVED.txt]
Prints one line "SOLVER-CHECK {json}": where meshio was imported from, inverted faces before
and after (meshcheck's own count), whether every non-2D block, cell/point/field data array
and cell set is unchanged, the file's first two lines, the nodes whose coordinates differ,
and (with MOVED.txt, one vertex index a line) whether exactly those nodes differ."""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import meshcheck
import meshio  # from the extension's wheels: Blender's Python has no other copy

FACES = ("triangle", "quad")


def faces_of(m):
    return [row for c in m.cells if c.type in FACES for row in np.asarray(c.data)]


def xyz(points):
    """(N, 3) points: 2D formats (Medit, SU2) get z = 0, as meshcheck measures in 3D."""
    points = np.asarray(points, dtype=np.float64)
    return points if points.shape[1] == 3 else np.column_stack([points, np.zeros(len(points))])


def same_arrays(a, b):
    return all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(a, b)) and \
        len(a) == len(b)


def head(path):
    with open(path, "rb") as fh:
        return [fh.readline().strip().decode("ascii", "replace") for _ in range(2)]


args = sys.argv[sys.argv.index("--") + 1:]
a, b = meshio.read(args[0]), meshio.read(args[1])
faces = faces_of(a)
moved = np.flatnonzero((a.points != b.points).any(axis=1))
lines = np.unique(np.concatenate([np.asarray(c.data).ravel() for c in a.cells
                                  if c.type.startswith("line")] + [np.zeros(0, np.int64)]))
out = {
    "meshio": meshio.__file__,
    "inverted": [meshcheck.stats(xyz(a.points), faces)["n_inverted"],
                 meshcheck.stats(xyz(b.points), faces)["n_inverted"]],
    "blocks": [[c.type, len(c.data)] for c in a.cells],
    "blocks_same": [c.type for c in a.cells] == [c.type for c in b.cells] and
    same_arrays([c.data for c in a.cells], [c.data for c in b.cells]),
    "cell_data_same": sorted(a.cell_data) == sorted(b.cell_data) and
    all(same_arrays(a.cell_data[k], b.cell_data[k]) for k in a.cell_data),
    "point_data_same": sorted(a.point_data) == sorted(b.point_data) and
    all(np.array_equal(a.point_data[k], b.point_data[k]) for k in a.point_data),
    "field_data_same": sorted(a.field_data) == sorted(b.field_data) and
    all(np.array_equal(a.field_data[k], b.field_data[k]) for k in a.field_data),
    "groups": sorted(a.field_data),
    "head": [head(args[0]), head(args[1])],
    "n_points": len(a.points),
    "moved": int(moved.size),
    "boundary_moved": int(np.isin(moved, lines).sum()),
}
if len(args) > 2:
    with open(args[2]) as fh:
        expected = np.array([int(x) for x in fh.read().split()], dtype=np.int64)
    out["moved_as_in_blender"] = bool(np.array_equal(np.sort(expected), moved))
    out["moved_in_blender"] = int(expected.size)
print("SOLVER-CHECK " + json.dumps(out), flush=True)
