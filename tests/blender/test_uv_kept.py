"""Knife-cut UV maps in the UV editor (issue 40 item 1): a face with a vertex in the middle
of its straight island-border edge is valid for Untangle & Smooth UVs and Select Flipped
(corners kept as given, core.metrics.kept), as it is in the mesh operator and the command."""

from __future__ import annotations

import numpy as np
import pytest

from .uvtools import uv_values

pytestmark = pytest.mark.blender

N = 4  # quads per side
KEPT = ("1 face kept as given (1 straight corner of fixed vertices only: valid, measured "
        "without those vertices)")


def ops_uv(ext):
    return ext.operators.uv.ops_uv


def knife_grid(bpy, unwrap: bool = False):
    """A 4 x 4 grid of unit quads (bmesh) whose bottom boundary edge of the first face is
    split in the middle (a knife cut): that face is a pentagon. UVs = the vertex xy / 4, set
    per loop (or Blender's own unwrap with ``unwrap``). The object, active and selected."""
    import bmesh
    me = bpy.data.meshes.new("Knife")
    obj = bpy.data.objects.new("Knife", me)
    bpy.context.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    bm = bmesh.new()
    vs = [[bm.verts.new((float(i), float(j), 0.0)) for i in range(N + 1)]
          for j in range(N + 1)]
    for j in range(N):
        for i in range(N):
            bm.faces.new((vs[j][i], vs[j][i + 1], vs[j + 1][i + 1], vs[j + 1][i]))
    bm.edges.ensure_lookup_table()
    edge = next(e for e in vs[0][0].link_edges if vs[0][1] in e.verts)
    bmesh.utils.edge_split(edge, vs[0][0], 0.5)  # the knife's vertex at (0.5, 0)
    layer = bm.loops.layers.uv.new("UVMap")
    for f in bm.faces:
        for loop in f.loops:
            loop[layer].uv = (loop.vert.co.x / N, loop.vert.co.y / N)
    bm.to_mesh(me)
    bm.free()
    assert sorted(len(p.vertices) for p in me.polygons) == [4] * (N * N - 1) + [5]
    if unwrap:
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        bpy.ops.uv.unwrap(margin=0.0)
        bpy.ops.object.mode_set(mode="OBJECT")
    return obj


def pentagon(obj) -> int:
    return next(p.index for p in obj.data.polygons if len(p.vertices) == 5)


def knife_corner(obj, uv: np.ndarray) -> str:
    """The pentagon's corner at the knife's vertex in the UV map ``uv``: straight, concave
    or convex."""
    p = obj.data.polygons[pentagon(obj)]
    loops = list(p.loop_indices)
    k = next(i for i, li in enumerate(loops) if obj.data.loops[li].vertex_index == (N + 1) ** 2)
    a, b, c = (uv[loops[(k + d) % 5]].astype(np.float64) for d in (-1, 0, 1))
    det = (c[0] - b[0]) * (a[1] - b[1]) - (c[1] - b[1]) * (a[0] - b[0])
    return "straight" if det == 0 else "concave" if det < 0 else "convex"


def edit_all(bpy) -> None:
    bpy.context.scene.tool_settings.use_uv_select_sync = True
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")


def selected_faces(bpy, obj, kind: str) -> list[int]:
    """Select Flipped UVs of ``kind`` (sync selection): the faces it selects."""
    edit_all(bpy)
    assert bpy.ops.uv.eegt_select_flipped(kind=kind) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    sel = np.zeros(len(obj.data.polygons), bool)
    obj.data.polygons.foreach_get("select", sel)
    return np.flatnonzero(sel).tolist()


def drag_centre(obj) -> None:
    """Every loop of the grid's centre vertex (2, 2) to the UV of (3.6, 3.4) / 4: across
    its neighbours."""
    me = obj.data
    centre = next(v.index for v in me.vertices if tuple(v.co) == (2.0, 2.0, 0.0))
    uv = uv_values(obj)
    cv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", cv)
    uv[cv == centre] = (3.6 / N, 3.4 / N)
    me.attributes[me.uv_layers.active.name].data.foreach_set("vector", uv.ravel())
    me.update()


@pytest.mark.parametrize("unwrap", [False, True], ids=["set", "unwrapped"])
def test_knife_cut_map_is_valid_and_not_selected_as_flipped(bpy, ext, unwrap):
    obj = knife_grid(bpy, unwrap)
    uv0 = uv_values(obj)
    a = ops_uv(ext).analyze_uv(obj, True)
    assert {k: int(v.sum()) for k, v in a.masks.items()} == {
        "FLIPPED": 0, "INVERTED": 0, "OVERLAPPING": 0}
    edit_all(bpy)
    bpy.ops.uv.eegt_untangle_smooth(target_shape="REGULAR")
    bpy.ops.object.mode_set(mode="OBJECT")
    (res,) = ops_uv(ext).LAST_RESULTS
    assert res.status == "valid" and res.ok and res.message == ""
    # Blender's unwrap may leave the knife's vertex a float32 hair off straight (concave:
    # kept as well; convex: an ordinary valid face, nothing kept)
    kind = knife_corner(obj, uv0)
    assert kind == "straight" or unwrap
    if kind == "convex":
        assert res.before["kept"] == 0 and "kept as given" not in res.line()
    else:
        note = KEPT.replace("straight", kind)
        assert note in res.notes and note in res.line() and res.before["kept"] == 1
    assert "FAILED" not in res.line()
    assert res.before["inverted"] == res.after["inverted"] == 0
    assert res.before["flipped"] == res.after["flipped"] == 0
    if not unwrap:  # the map is already the grid: nothing better to write
        assert not res.written and np.array_equal(uv_values(obj), uv0)
        assert res.before["distortion_worst"] == 1.0
    for kind in ("FLIPPED", "INVERTED", "OVERLAPPING"):
        assert selected_faces(bpy, obj, kind) == [], kind
    assert obj.eegt_last_uv_run.status == "valid"


def test_paper_mode_counts_the_straight_corner(bpy, ext):
    obj = knife_grid(bpy)
    bpy.context.scene.eegt_settings.untangle = "eegt"
    assert selected_faces(bpy, obj, "INVERTED") == [pentagon(obj)]
    assert selected_faces(bpy, obj, "FLIPPED") == []  # its area is positive
    bpy.context.scene.eegt_settings.untangle = "auto"
    assert selected_faces(bpy, obj, "INVERTED") == []


def test_dragged_uv_vertex_untangles_around_the_knife_cut(bpy, ext):
    obj = knife_grid(bpy)
    drag_centre(obj)
    assert selected_faces(bpy, obj, "INVERTED") != []
    assert pentagon(obj) not in selected_faces(bpy, obj, "INVERTED")
    uv0 = uv_values(obj)
    edit_all(bpy)
    assert bpy.ops.uv.eegt_untangle_smooth(target_shape="REGULAR") == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    (res,) = ops_uv(ext).LAST_RESULTS
    assert res.status == "untangled" and res.ok and res.written
    assert res.before["inverted"] == 3 and res.after["inverted"] == 0
    assert res.after["flipped"] == res.after["overlapping"] == 0
    assert KEPT in res.line()
    uv1 = uv_values(obj)
    cv = np.empty(len(obj.data.loops), np.int64)
    obj.data.loops.foreach_get("vertex_index", cv)
    border = np.array([not (0 < v.co.x < N and 0 < v.co.y < N) for v in obj.data.vertices])
    assert np.array_equal(uv1[border[cv]], uv0[border[cv]])  # island border: bits kept
    assert np.any(uv1 != uv0)
    for kind in ("FLIPPED", "INVERTED", "OVERLAPPING"):
        assert selected_faces(bpy, obj, kind) == [], kind
