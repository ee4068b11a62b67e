# SPDX-License-Identifier: GPL-3.0-or-later
"""Where the reference shapes of target "reference" come from: a shape key of the mesh, an
object of the same topology, or (command line) an OBJ file of the same topology.

``reference_positions`` returns the reference's (N, 3) float32 vertex positions for one
object, or raises ValueError with a one-line reason (the object is then left unchanged).
With no explicit choice the reference is the mesh's reference shape key (*Basis*) when
another key is being edited: the undeformed mesh under a deforming key. The topology
check compares every face's vertex list, in order; a reference vertex of a face with a NaN
or infinite coordinate is refused too.
"""

from __future__ import annotations

from dataclasses import dataclass

import bpy
import numpy as np

from ...core.mesh import FaceSet, faces_from_csr, read_obj
from . import mesh_io


@dataclass(frozen=True)
class ReferenceSource:
    """One reference choice: a shape key name, an object name, or a file's mesh."""

    key: str = ""
    object: str = ""
    file: str = ""
    file_points: np.ndarray | None = None  # (N, 3) of `file`, read once
    file_faces: FaceSet | None = None

    def describe(self) -> str:
        if self.file:
            return f"file '{self.file}'"
        if self.object:
            return f"object '{self.object}'"
        return f"shape key '{self.key}'" if self.key else "the reference shape key"


def from_file(path: str) -> ReferenceSource:
    """The mesh of an OBJ file as a reference (ValueError: one line)."""
    if not path.lower().endswith(".obj"):
        raise ValueError(f"reference '{path}' must be an .obj file")
    try:
        points, faces = read_obj(path)
    except OSError as exc:
        raise ValueError(f"cannot read reference '{path}': "
                         f"{(exc.strerror or str(exc)).lower()}") from None
    except (ValueError, IndexError) as exc:
        raise ValueError(f"cannot read reference '{path}': {exc}") from None
    if faces.n_faces == 0 or points.shape[0] == 0:
        raise ValueError(f"reference '{path}' has no faces")
    _check_finite(points, f"reference '{path}'", faces.indices)
    return ReferenceSource(file=path, file_points=points, file_faces=faces)


def _check_finite(points: np.ndarray, what: str, used: np.ndarray) -> None:
    """ValueError when a vertex of the reference that a face uses (`used`: vertex indices)
    has a NaN or infinite coordinate."""
    used = np.unique(used)
    bad = int((~np.isfinite(points[used]).all(axis=1)).sum())
    if bad:
        raise ValueError(f"{what} has {bad} vert{'ex' if bad == 1 else 'ices'} with a NaN or "
                         "infinite coordinate")


def edited_key(obj: bpy.types.Object) -> str | None:
    """The shape key a run on `obj` edits (its active one), None for the mesh itself."""
    key = obj.active_shape_key if obj.data.shape_keys is not None else None
    return key.name if key is not None else None


def default_key(me: bpy.types.Mesh, edited: str | None) -> str | None:
    """The reference with no explicit choice: the mesh's reference shape key (Basis) while
    another key is edited, else None (there is none)."""
    keys = me.shape_keys
    if keys is None or edited is None or edited == keys.reference_key.name:
        return None
    return keys.reference_key.name


def _faces_of(me: bpy.types.Mesh) -> FaceSet | None:
    topo = mesh_io.read_topology(me)
    if topo.loop_start.size == 0:
        return None
    return faces_from_csr(topo.loop_start, topo.loop_total, topo.corner_verts)


def _same_topology(a: FaceSet | None, b: FaceSet | None) -> bool:
    return (a is not None and b is not None and np.array_equal(a.offsets, b.offsets)
            and np.array_equal(a.indices, b.indices))


def same_topology(me: bpy.types.Mesh, n_vertices: int, faces: FaceSet | None) -> bool:
    """Whether a reference of `n_vertices` vertices and these faces fits the mesh `me`: the
    same vertex count and every face's vertex list the same, in order."""
    return n_vertices == len(me.vertices) and _same_topology(_faces_of(me), faces)


def _topology_error(what: str, n_ref: int, f_ref: int, me: bpy.types.Mesh) -> ValueError:
    return ValueError(f"reference {what} has a different topology ({n_ref} vertices, {f_ref} "
                      f"faces; the mesh has {len(me.vertices)} vertices, {len(me.polygons)} "
                      "faces, or the faces differ)")


def reference_positions(obj: bpy.types.Object, source: ReferenceSource | None,
                        edited_key: str | None) -> tuple[np.ndarray, str]:
    """(N, 3) float32 reference positions of ``obj``'s vertices (``edited_key``: the shape
    key the run writes, None for the mesh itself) and what they are, for the report."""
    points, what = _positions(obj, source or ReferenceSource(), edited_key)
    _check_finite(points, f"reference {what}", mesh_io.read_topology(obj.data).corner_verts)
    return points, what


def _positions(obj: bpy.types.Object, source: ReferenceSource,
               edited_key: str | None) -> tuple[np.ndarray, str]:
    me = obj.data
    if source.file:
        if not same_topology(me, source.file_points.shape[0], source.file_faces):
            raise _topology_error(source.describe(), source.file_points.shape[0],
                                  source.file_faces.n_faces, me)
        return source.file_points.astype(np.float32), source.describe()
    if source.object:
        ref = bpy.data.objects.get(source.object)
        if ref is None:
            raise ValueError(f"reference object '{source.object}' not found")
        if ref.type != "MESH":
            raise ValueError(f"reference object '{source.object}' is not a mesh")
        if ref.data != me and not same_topology(me, len(ref.data.vertices),
                                                _faces_of(ref.data)):
            raise _topology_error(source.describe(), len(ref.data.vertices),
                                  len(ref.data.polygons), me)
        return mesh_io.read_positions(ref.data), source.describe()
    keys = me.shape_keys
    name = source.key or default_key(me, edited_key)
    if not name:
        raise ValueError("target 'reference' needs a reference: choose a shape key, or an "
                         "object of the same topology")
    block = keys.key_blocks.get(name) if keys is not None else None
    if block is None:
        raise ValueError(f"reference shape key '{name}' not found")
    if name == edited_key:
        raise ValueError(f"reference shape key '{name}' is the shape key being edited: "
                         "choose another one")
    return mesh_io.read_key_positions(block), f"shape key '{name}'"
