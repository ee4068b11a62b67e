# SPDX-License-Identifier: GPL-3.0-or-later
"""Bulk NumPy reads and writes of Blender mesh data (no per-element Python loops).

Positions go through ``attributes["position"]`` with float32 buffers, topology through the
polygons' ``loop_start`` and the ``.corner_vert``, ``.corner_edge`` and ``.edge_verts``
attributes, selection and hiding through ``.select_vert``, ``.select_poly`` and
``.hide_poly`` (falling back to the items' properties where an internal name is missing or
of another type): the attributes are read as one block, the properties item by item
(0.05-0.2 s per million items).
"""

from __future__ import annotations

from dataclasses import dataclass

import bpy
import numpy as np

from ...core.mesh import ragged_arange

PIN_NAME = "eegt_pinned"
QUALITY_NAME = "eegt_quality"
QUALITY_COLOR_NAME = "eegt_quality_color"


@dataclass
class MeshArrays:
    """Topology of a mesh as flat arrays (Blender's own CSR layout)."""

    n_verts: int
    loop_start: np.ndarray  # (F,) int32
    loop_total: np.ndarray  # (F,) int32
    corner_verts: np.ndarray  # (L,) int32


def _read_corner_ints(me: bpy.types.Mesh, attr_name: str, loop_prop: str) -> np.ndarray:
    """A per-corner int array: the internal attribute (fast), else the loops' property."""
    nl = len(me.loops)
    out = np.empty(nl, dtype=np.int32)
    attr = me.attributes.get(attr_name)
    if attr is not None and attr.domain == "CORNER" and attr.data_type == "INT" and nl:
        attr.data.foreach_get("value", out)
    elif nl:
        me.loops.foreach_get(loop_prop, out)
    return out


def read_topology(me: bpy.types.Mesh) -> MeshArrays:
    """Face offsets and corner vertices of ``me``."""
    nf = len(me.polygons)
    corner_verts = _read_corner_ints(me, ".corner_vert", "vertex_index")
    if corner_verts.size == 3 * nf:  # faces have 3 corners or more: all triangles
        loop_start = np.arange(0, 3 * nf, 3, dtype=np.int32)
    else:
        loop_start = np.empty(nf, dtype=np.int32)
        me.polygons.foreach_get("loop_start", loop_start)
    # Blender stores faces as offsets (face i: corners start[i] to start[i + 1]), so the
    # starts of triangles and the sizes are known; read them only when not.
    loop_total = np.diff(loop_start, append=np.int32(corner_verts.size)).astype(np.int32)
    if nf and (loop_start[0] != 0 or loop_total.min() < 1):
        me.polygons.foreach_get("loop_total", loop_total)
    return MeshArrays(len(me.vertices), loop_start, loop_total, corner_verts)


def read_positions(me: bpy.types.Mesh) -> np.ndarray:
    """Vertex positions as a (N, 3) float32 array (a copy)."""
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    if co.size:
        me.attributes["position"].data.foreach_get("vector", co)
    return co.reshape(-1, 3)


def write_positions(me: bpy.types.Mesh, co: np.ndarray) -> None:
    """Set every vertex position from a (N, 3) array (converted to float32)."""
    buf = np.ascontiguousarray(co, dtype=np.float32).ravel()
    me.attributes["position"].data.foreach_set("vector", buf)
    me.update()


def read_key_positions(key_block: bpy.types.ShapeKey) -> np.ndarray:
    """Positions of one shape key as (N, 3) float32."""
    co = np.empty(len(key_block.data) * 3, dtype=np.float32)
    if co.size:
        key_block.data.foreach_get("co", co)
    return co.reshape(-1, 3)


def write_key_positions(key_block: bpy.types.ShapeKey, co: np.ndarray) -> None:
    """Set the positions of one shape key from (N, 3)."""
    key_block.data.foreach_set("co", np.ascontiguousarray(co, dtype=np.float32).ravel())


def _read_flags(me: bpy.types.Mesh, collection, prop: str, attr_name: str,
                domain: str) -> np.ndarray:
    """A boolean property of every item of a mesh collection, in one bulk read: from the
    internal attribute Blender keeps it in (an absent one means False everywhere), else
    from the items' property."""
    out = np.zeros(len(collection), dtype=bool)
    if out.size == 0:
        return out
    attr = me.attributes.get(attr_name)
    if attr is None:
        return out
    if attr.domain == domain and attr.data_type == "BOOLEAN":
        attr.data.foreach_get("value", out)
    else:
        collection.foreach_get(prop, out)
    return out


def read_vertex_selection(me: bpy.types.Mesh) -> np.ndarray:
    """Selected vertices (bool (N,))."""
    return _read_flags(me, me.vertices, "select", ".select_vert", "POINT")


def read_face_selection(me: bpy.types.Mesh) -> np.ndarray:
    """Selected faces (bool (F,))."""
    return _read_flags(me, me.polygons, "select", ".select_poly", "FACE")


def read_face_hidden(me: bpy.types.Mesh) -> np.ndarray:
    """Hidden faces (bool (F,))."""
    return _read_flags(me, me.polygons, "hide", ".hide_poly", "FACE")


def vertex_group_pins(obj: bpy.types.Object, n_verts: int) -> np.ndarray | None:
    """Vertices with a weight > 0 in the ``eegt_pinned`` vertex group, or None without one.

    Blender has no bulk read of vertex-group weights; this loop only runs when the group
    exists (the boolean attribute is the fast path, ~10^4 times quicker).
    """
    vg = obj.vertex_groups.get(PIN_NAME)
    if vg is None:
        return None
    idx = vg.index
    pinned = np.zeros(n_verts, dtype=bool)
    me = obj.data
    hits = [v.index for v in me.vertices for g in v.groups if g.group == idx and g.weight > 0.0]
    if hits:
        pinned[np.asarray(hits, dtype=np.int64)] = True
    return pinned


PIN_BUFFERS = {"BOOLEAN": bool, "FLOAT": np.float32, "INT": np.int32, "INT8": np.int8}


def pin_attribute_values(me: bpy.types.Mesh) -> np.ndarray | None:
    """Raw values of the ``eegt_pinned`` point attribute in its own buffer type (bool,
    float32, int32 or int8; a float 0.5 read as an int would be 0, unpinned), or None when
    there is no such attribute.

    Any other domain or type raises ValueError with a one-line message: ignoring it would
    silently move vertices the user meant to pin.
    """
    attr = me.attributes.get(PIN_NAME)
    if attr is None:
        return None
    dtype = PIN_BUFFERS.get(attr.data_type)
    if attr.domain != "POINT" or dtype is None:
        raise ValueError(
            f"attribute '{PIN_NAME}' is {attr.data_type} on {attr.domain}: pins must be a "
            f"point attribute (boolean, float, integer or 8-bit integer, nonzero = pinned); "
            f"fix it or turn off Use Pinned")
    buf = np.zeros(len(attr.data), dtype=dtype)
    if buf.size:
        attr.data.foreach_get("value", buf)
    return buf


def read_pin_attribute(me: bpy.types.Mesh) -> np.ndarray | None:
    """Pins from the ``eegt_pinned`` point attribute, nonzero = pinned (bool (N,)), or None
    without one; BOOLEAN (what the Pin operator writes), FLOAT, INT and INT8 are read."""
    values = pin_attribute_values(me)
    return None if values is None else values != 0


def read_pins(obj: bpy.types.Object) -> np.ndarray:
    """User-pinned vertices (bool (N,)): the ``eegt_pinned`` point attribute (nonzero) or
    vertex group (weight > 0); ValueError for an attribute of an unusable domain or type."""
    me = obj.data
    n = len(me.vertices)
    pinned = np.zeros(n, dtype=bool)
    attr = read_pin_attribute(me)
    if attr is not None:
        pinned |= attr
    vg = vertex_group_pins(obj, n)
    if vg is not None:
        pinned |= vg
    return pinned


def corner_faces(topo: MeshArrays) -> np.ndarray:
    """Face index of every corner (L,), whatever the order of the face offsets."""
    out = np.empty(topo.corner_verts.size, dtype=np.int64)
    nf = topo.loop_start.size
    if nf == 0:
        return out
    out[ragged_arange(topo.loop_start, topo.loop_total)] = np.repeat(np.arange(nf),
                                                                     topo.loop_total)
    return out


@dataclass
class EdgeArrays:
    """Blender's edge table and the edge of every corner (the edge to the next corner)."""

    corner_edges: np.ndarray  # (L,) int32
    edge_verts: np.ndarray  # (E, 2) int32


def read_edges(me: bpy.types.Mesh) -> EdgeArrays:
    """The edge table and the corners' edges of ``me``."""
    ne = len(me.edges)
    edge_verts = np.empty(2 * ne, dtype=np.int32)
    attr = me.attributes.get(".edge_verts")
    if ne and attr is not None and attr.domain == "EDGE" and attr.data_type == "INT32_2D":
        attr.data.foreach_get("value", edge_verts)
    elif ne:
        me.edges.foreach_get("vertices", edge_verts)
    return EdgeArrays(_read_corner_ints(me, ".corner_edge", "edge_index"),
                      edge_verts.reshape(-1, 2))


def loose_edge_vertices(n_verts: int, edges: EdgeArrays) -> np.ndarray | None:
    """Vertices of edges used by no face (bool (N,)), or None when there is no loose edge."""
    ne = edges.edge_verts.shape[0]
    if ne == 0:
        return None
    used = np.zeros(ne, dtype=bool)
    used[edges.corner_edges] = True
    if used.all():
        return None
    out = np.zeros(n_verts, dtype=bool)
    out[edges.edge_verts[~used].ravel()] = True
    return out
