# SPDX-License-Identifier: GPL-3.0-or-later
"""Bulk NumPy reads and writes of a mesh's UV maps (no per-loop Python loops).

UVs go through the UV map's corner attribute (``FLOAT2``) with float32 buffers, pins through
``uv_layer.pin``. UV selection is stored differently across versions: Blender 5.0 keeps one
UV selection per mesh (``.uv_select_vert`` / ``.uv_select_edge`` corner and
``.uv_select_face`` face attributes), Blender 4.2-4.5 one per UV map
(``uv_layer.vertex_selection`` / ``edge_selection``). Meshes must be in Object Mode (the
operators leave Edit Mode around their reads and writes, which flushes the edit data).
"""

from __future__ import annotations

import bpy
import numpy as np

from ..mesh import mesh_io

UV_SELECT_VERT, UV_SELECT_EDGE, UV_SELECT_FACE = ".uv_select_vert", ".uv_select_edge", \
    ".uv_select_face"


def uv_layer(me: bpy.types.Mesh, name: str | None = None) -> bpy.types.MeshUVLoopLayer:
    """The UV map ``name`` (default: the active one); ValueError with a one-line reason."""
    layers = me.uv_layers
    if len(layers) == 0:
        raise ValueError("mesh has no UV map (unwrap it first)")
    if not name:
        layer = layers.active
        if layer is None:
            raise ValueError("mesh has no active UV map")
        return layer
    layer = layers.get(name)
    if layer is None:
        have = ", ".join(uv.name for uv in layers)
        raise ValueError(f"no UV map named '{name}' (UV maps: {have})")
    return layer


def read_uv(me: bpy.types.Mesh, layer: bpy.types.MeshUVLoopLayer) -> np.ndarray:
    """(L, 2) float32 copy of the UV map's values."""
    out = np.empty(len(me.loops) * 2, dtype=np.float32)
    if out.size:
        me.attributes[layer.name].data.foreach_get("vector", out)
    return out.reshape(-1, 2)


def write_uv(me: bpy.types.Mesh, layer: bpy.types.MeshUVLoopLayer, uv: np.ndarray) -> None:
    """Set every value of the UV map from (L, 2) (converted to float32)."""
    buf = np.ascontiguousarray(uv, dtype=np.float32).ravel()
    me.attributes[layer.name].data.foreach_set("vector", buf)
    me.update()


def read_uv_pins(me: bpy.types.Mesh, layer: bpy.types.MeshUVLoopLayer) -> np.ndarray:
    """(L,) bool: UVs pinned in the UV editor (``P``); all False when none was ever pinned."""
    out = np.zeros(len(me.loops), dtype=bool)
    if out.size and len(layer.pin) == out.size:
        layer.pin.foreach_get("value", out)
    return out


def _corner_bool(me: bpy.types.Mesh, name: str, size: int) -> np.ndarray | None:
    """A boolean attribute's values, or None when the mesh has none of that name."""
    attr = me.attributes.get(name)
    if attr is None or attr.data_type != "BOOLEAN":
        return None
    out = np.zeros(size, dtype=bool)
    if size:
        attr.data.foreach_get("value", out)
    return out


def _layer_flags(layer: bpy.types.MeshUVLoopLayer, prop: str, size: int) -> np.ndarray | None:
    """Blender 4.x per-map UV selection flags (``vertex_selection``/``edge_selection``)."""
    coll = getattr(layer, prop, None)
    if coll is None:
        return None
    out = np.zeros(size, dtype=bool)
    if size and len(coll) == size:
        coll.foreach_get("value", out)
    return out


def read_uv_face_selection(me: bpy.types.Mesh, layer: bpy.types.MeshUVLoopLayer,
                           sync: bool, select_mode: str = "VERTEX") -> np.ndarray:
    """(F,) bool: the faces selected in the UV editor.

    With UV Sync Selection the UV editor shows the mesh selection: the selected, visible
    faces. Without it, it shows the faces selected in the mesh, and of those the ones whose
    UVs are selected count: Blender 5.0's UV face flags, or (4.x) every corner's vertex flag
    (edge flags in edge and face select mode).
    """
    shown = mesh_io.read_face_selection(me) & ~mesh_io.read_face_hidden(me)
    if sync:
        return shown
    nf, nl = len(me.polygons), len(me.loops)
    face = _corner_bool(me, UV_SELECT_FACE, nf)
    if face is not None and getattr(layer, "vertex_selection", None) is None:
        return shown & face
    prop = "vertex_selection" if select_mode == "VERTEX" else "edge_selection"
    corner = _layer_flags(layer, prop, nl)
    if corner is None:  # 5.0 without a face flag layer: the per-mesh corner flags
        corner = _corner_bool(me, UV_SELECT_VERT, nl)
    if corner is None:
        return np.zeros(nf, dtype=bool)
    topo = mesh_io.read_topology(me)
    per_face = np.bitwise_and.reduceat(corner[_face_order(topo)], _offsets(topo)) \
        if nl else np.zeros(nf, dtype=bool)
    return shown & per_face


def _face_order(topo: mesh_io.MeshArrays) -> np.ndarray:
    """Loops face by face (Blender's face offsets may come in any order)."""
    from ...core.uv import corner_loops
    return corner_loops(topo.loop_start, topo.loop_total)


def _offsets(topo: mesh_io.MeshArrays) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(topo.loop_total)[:-1]]).astype(np.int64)


def select_uv_faces(me: bpy.types.Mesh, layer: bpy.types.MeshUVLoopLayer, faces: np.ndarray,
                    loop_node: np.ndarray, sync: bool) -> None:
    """Select exactly ``faces`` (bool (F,)) in the UV editor.

    Sync: the mesh selection (faces, their vertices and edges). Otherwise the UV selection
    of the faces' corners: every corner of a selected face's UV vertices (so the UV vertex
    is selected wherever it is used, as Blender's sticky selection does), the corners' edges
    and the faces (Blender 5.0's per-mesh flags, or the UV map's flags in 4.x).
    """
    topo = mesh_io.read_topology(me)
    corner_face = mesh_io.corner_faces(topo)
    if sync:
        vsel = np.zeros(len(me.vertices), dtype=bool)
        vsel[topo.corner_verts[faces[corner_face]]] = True
        ev = np.empty(2 * len(me.edges), dtype=np.int32)
        me.edges.foreach_get("vertices", ev)
        esel = vsel[ev.reshape(-1, 2)].all(axis=1) if ev.size else np.zeros(0, bool)
        me.polygons.foreach_set("select", faces)
        me.vertices.foreach_set("select", vsel)
        me.edges.foreach_set("select", esel)
        me.update()
        return
    corner_in = faces[corner_face]
    node_on = np.zeros(int(loop_node.max()) + 1 if loop_node.size else 0, dtype=bool)
    node_on[loop_node[corner_in]] = True
    vert = node_on[loop_node]
    if getattr(layer, "vertex_selection", None) is not None:  # Blender 4.x
        layer.vertex_selection.foreach_set("value", vert)
        layer.edge_selection.foreach_set("value", corner_in)
    else:
        for name, values in ((UV_SELECT_VERT, vert), (UV_SELECT_EDGE, corner_in),
                             (UV_SELECT_FACE, faces)):
            attr = me.attributes.get(name)
            if attr is None:
                domain = "FACE" if name == UV_SELECT_FACE else "CORNER"
                attr = me.attributes.new(name, "BOOLEAN", domain)
            attr.data.foreach_set("value", values)
    me.update()
