"""Bulk mesh reads through Blender's internal attributes give what the items' properties
give (the properties are read item by item: 0.05-0.2 s per million), on the installed
extension (headless bpy)."""

from __future__ import annotations

import numpy as np
import pytest

from .conftest import import_obj

pytestmark = pytest.mark.blender


def _rna(collection, prop: str, dtype, width: int = 1) -> np.ndarray:
    out = np.empty(len(collection) * width, dtype=dtype)
    collection.foreach_get(prop, out)
    return out if width == 1 else out.reshape(-1, width)


def test_topology_and_edges_equal_the_item_properties_on_a_mixed_mesh(bpy, ext):
    mesh_io = ext.operators.mesh.mesh_io
    me = import_obj(bpy, "mixed_quad_tri").data
    topo = mesh_io.read_topology(me)
    assert np.unique(topo.loop_total).size >= 2  # triangles and quads
    assert np.array_equal(topo.loop_start, _rna(me.polygons, "loop_start", np.int32))
    assert np.array_equal(topo.loop_total, _rna(me.polygons, "loop_total", np.int32))
    assert np.array_equal(topo.corner_verts, _rna(me.loops, "vertex_index", np.int32))
    edges = mesh_io.read_edges(me)
    assert np.array_equal(edges.edge_verts, _rna(me.edges, "vertices", np.int32, 2))
    assert np.array_equal(edges.corner_edges, _rna(me.loops, "edge_index", np.int32))


def test_selection_and_hiding_equal_the_item_properties_set_or_not(bpy, ext):
    mesh_io = ext.operators.mesh.mesh_io
    me = import_obj(bpy, "tri_two_holes").data
    nf, nv = len(me.polygons), len(me.vertices)
    me.polygons.foreach_set("select", np.zeros(nf, dtype=bool))
    me.vertices.foreach_set("select", np.zeros(nv, dtype=bool))
    me.update()
    assert me.attributes.get(".hide_poly") is None  # absent: nothing hidden
    for got, (items, prop) in ((mesh_io.read_face_selection(me), (me.polygons, "select")),
                               (mesh_io.read_vertex_selection(me), (me.vertices, "select")),
                               (mesh_io.read_face_hidden(me), (me.polygons, "hide"))):
        assert not got.any() and np.array_equal(got, _rna(items, prop, bool))
    rng = np.random.default_rng(0)
    faces, verts, hidden = (rng.random(nf) < 0.3), (rng.random(nv) < 0.4), (rng.random(nf) < 0.2)
    me.polygons.foreach_set("select", faces)
    me.vertices.foreach_set("select", verts)
    me.polygons.foreach_set("hide", hidden)
    me.update()
    assert np.array_equal(mesh_io.read_face_selection(me), faces)
    assert np.array_equal(mesh_io.read_vertex_selection(me), verts)
    assert np.array_equal(mesh_io.read_face_hidden(me), hidden)
    for got, (items, prop) in ((mesh_io.read_face_selection(me), (me.polygons, "select")),
                               (mesh_io.read_vertex_selection(me), (me.vertices, "select")),
                               (mesh_io.read_face_hidden(me), (me.polygons, "hide"))):
        assert np.array_equal(got, _rna(items, prop, bool))
