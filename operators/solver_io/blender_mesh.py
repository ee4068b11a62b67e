# SPDX-License-Identifier: GPL-3.0-or-later
"""A solver mesh as a Blender mesh object, and the object written back into its file.

The object has one vertex per point of the file (same numbers) and one face per 2D cell
(block by block); point data become point attributes, the 2D cells' one-component cell data
face attributes, every group a vertex group, a pin mask the ``eegt_pinned`` attribute.
The mesh remembers its file (path, format, SHA-256) and the float64 origin its vertex
positions are relative to (the centre of the file's bounding box; the object is placed
there): writing it back reads that file again and changes only the coordinates of the
vertices whose position differs from the file's, to the origin plus their single-precision
position (so a mesh far from 0, e.g. at UTM coordinates, keeps steps of its own size), and
every other node, block, array and group is the file's own, bit for bit.
"""

from __future__ import annotations

import os

import bpy
import numpy as np

from ...fileio import checked_write, solver_mesh
from ...fileio.solver_mesh import SolverMesh, SolverMeshError
from ..mesh.mesh_io import PIN_NAME, read_positions

SOURCE, DIGEST, FORMAT = "eegt_solver_source", "eegt_solver_sha256", "eegt_solver_format"
ORIGIN = "eegt_solver_origin"  # float64 (x, y, z) the vertex positions are relative to
_FLOAT_TYPES = {1: "FLOAT", 2: "FLOAT2", 3: "FLOAT_VECTOR"}


def build_object(sm: SolverMesh, name: str, pinned: np.ndarray | None = None,
                 groups: bool = True) -> bpy.types.Object:
    """A new mesh object of `sm` linked to the scene's collection."""
    me = bpy.data.meshes.new(name)
    me.vertices.add(sm.n_points)
    origin = mesh_origin(sm)
    me.vertices.foreach_set("co", local_positions(sm, origin).ravel())
    me.loops.add(int(sm.corners.size))
    me.loops.foreach_set("vertex_index", sm.corners.astype(np.int32))
    me.polygons.add(sm.n_faces)
    me.polygons.foreach_set("loop_start", sm.offsets[:-1].astype(np.int32))
    me.update(calc_edges=True)
    _point_attributes(me, sm)
    _face_attributes(me, sm)
    if pinned is not None and pinned.any():
        set_pins(me, pinned)
    me[SOURCE] = os.path.abspath(sm.path)
    me[DIGEST] = solver_mesh.file_digest(sm.path)
    me[FORMAT] = sm.fmt
    me[ORIGIN] = [float(v) for v in origin]
    obj = bpy.data.objects.new(name, me)
    obj.location = origin.tolist()  # where the file puts it (display only)
    bpy.context.scene.collection.objects.link(obj)
    if groups:
        _vertex_groups(obj, sm)
    return obj


def mesh_origin(sm: SolverMesh) -> np.ndarray:
    """(3,) float64: the centre of the file's bounding box, which the Blender mesh's
    float32 vertex positions are taken relative to (a mesh at UTM-like coordinates keeps
    float32 steps of its own size, not of its offset)."""
    p = sm.points3d()
    lo, hi = p.min(axis=0), p.max(axis=0)
    return 0.5 * lo + 0.5 * hi


def local_positions(sm: SolverMesh, origin: np.ndarray) -> np.ndarray:
    """(N, 3) float32: the file's points relative to `origin`, as the Blender mesh holds
    them."""
    return (sm.points3d() - origin).astype(np.float32)


def set_pins(me: bpy.types.Mesh, pinned: np.ndarray) -> None:
    """The boolean ``eegt_pinned`` point attribute (what the Pin operator writes)."""
    attr = me.attributes.get(PIN_NAME)
    if attr is not None:
        me.attributes.remove(attr)
    attr = me.attributes.new(PIN_NAME, "BOOLEAN", "POINT")
    attr.data.foreach_set("value", np.asarray(pinned, dtype=bool))


def _new_attribute(me: bpy.types.Mesh, name: str, values: np.ndarray, domain: str) -> None:
    if name in me.attributes or len(name.encode()) > 63:
        return
    values = values.reshape(values.shape[0], -1)
    k = values.shape[1]
    if values.dtype.kind in "iub" and k == 1:
        attr = me.attributes.new(name, "INT", domain)
        attr.data.foreach_set("value", values.astype(np.int32).ravel())
    elif values.dtype.kind == "f" and k in _FLOAT_TYPES:
        attr = me.attributes.new(name, _FLOAT_TYPES[k], domain)
        attr.data.foreach_set("value" if k == 1 else "vector",
                              values.astype(np.float32).ravel())
    elif values.dtype.kind in "iubf":
        for i in range(k):  # one attribute per component
            _new_attribute(me, f"{name}[{i}]", values[:, i:i + 1], domain)


def _point_attributes(me: bpy.types.Mesh, sm: SolverMesh) -> None:
    for name, values in sm.mesh.point_data.items():
        _new_attribute(me, name, np.asarray(values), "POINT")


def _face_attributes(me: bpy.types.Mesh, sm: SolverMesh) -> None:
    for name, blocks in sm.mesh.cell_data.items():
        parts = [np.asarray(blocks[b]) for b in sm.face_blocks]
        if all(p.ndim == 1 or p.reshape(len(p), -1).shape[1] == 1 for p in parts):
            _new_attribute(me, name, np.concatenate([p.reshape(-1) for p in parts]), "FACE")


def _vertex_groups(obj: bpy.types.Object, sm: SolverMesh) -> None:
    """A vertex group of weight 1 for every named group (every tag when none is named)."""
    names = [n for n in sm.group_names() if not n.lstrip("-").isdigit()] or sm.group_names()
    for name in names:
        nodes = np.flatnonzero(sm.group_nodes(name))
        if nodes.size and name not in obj.vertex_groups:
            obj.vertex_groups.new(name=name).add(nodes.tolist(), 1.0, "REPLACE")


def source_of(me: bpy.types.Mesh) -> SolverMesh:
    """The solver mesh `me` was imported from, read again and checked: unchanged on disk,
    with the mesh's vertex and face counts. SolverMeshError (one line) otherwise."""
    path = me.get(SOURCE)
    if not path:
        raise SolverMeshError(f"mesh '{me.name}' was not imported from a solver mesh (File > "
                              "Import > Solver mesh): there is no file to write back into")
    if not os.path.isfile(path):
        raise SolverMeshError(f"the solver mesh '{path}' that mesh '{me.name}' came from is "
                              "gone: import it again")
    if solver_mesh.file_digest(path) != me.get(DIGEST):
        raise SolverMeshError(f"the solver mesh '{path}' changed since mesh '{me.name}' was "
                              "imported from it: import it again")
    sm = solver_mesh.read(path, me.get(FORMAT))
    if len(me.vertices) != sm.n_points or len(me.polygons) != sm.n_faces:
        raise SolverMeshError(
            f"mesh '{me.name}' has {len(me.vertices)} vertices and {len(me.polygons)} faces, "
            f"its file '{path}' {sm.n_points} points and {sm.n_faces} 2D cells: only moved "
            "vertices can be written back")
    return sm


def moved_positions(me: bpy.types.Mesh, sm: SolverMesh) -> tuple[np.ndarray, np.ndarray]:
    """(positions (N, 3) float64, moved (N,) bool): the vertices whose float32 position
    differs from the file's as imported (relative to the mesh's stored origin, rounded to
    float32), at the origin plus their float32 position (computed in float64). Every
    other vertex keeps the file's own float64 coordinates."""
    origin = np.asarray(me.get(ORIGIN, (0.0, 0.0, 0.0)), dtype=np.float64).reshape(3)
    co = read_positions(me)
    moved = (co != local_positions(sm, origin)).any(axis=1)
    return origin + co.astype(np.float64), moved


def write_object(obj: bpy.types.Object, path: str) -> int:
    """Write `obj`'s mesh into a solver mesh file at `path` (its source file's blocks and
    data, the moved vertices' positions); the number of moved nodes. The file is written
    beside `path`, read back whole and only then put in place (``fileio.checked_write``):
    a failed write (SolverMeshError, one line naming `path`) leaves `path` as it was."""
    sm = source_of(obj.data)
    positions, moved = moved_positions(obj.data, sm)
    checked_write.write(sm, path, positions, moved)
    return int(np.count_nonzero(moved))


def solver_objects() -> list[bpy.types.Object]:
    """Mesh objects imported from a solver mesh, in the scene."""
    return [o for o in bpy.data.objects if o.type == "MESH" and o.data.get(SOURCE)]
