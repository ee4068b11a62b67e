"""Target "Keep Shapes" of Untangle & Smooth UVs (issue 37 item 3): with Around Tangles it
repairs a fold of a laid-out UV map: the tangled faces and a margin move, every other loop
keeps its bits, and the faces that move keep the layout's proportions."""

from __future__ import annotations

import numpy as np
import pytest

from bench import uv_assets

from .uvtools import uv_values

pytestmark = pytest.mark.blender

N = 10  # vertices per side
GROWTH = 1.08  # each column of cells this much wider than the one before
H = 0.02  # cell height; column i is 4 * H * GROWTH**i wide


def ops_uv(ext):
    return ext.operators.uv.ops_uv


def graded_uv_grid(bpy, n: int = N, fold: bool = True, pins: tuple[tuple[int, int], ...] = (),
                   name: str = "Graded"):
    """(n-1) x (n-1) unit quads in 3D; UVs anisotropic and graded (cells 0.02 tall, column i
    4 * 0.02 * GROWTH**i wide); with ``fold`` the UV of vertex (4, 4) dragged across its
    right neighbour (faces fold); the UV vertices (i, j) of ``pins`` pinned. (the object,
    active and selected; its UVs per vertex)."""
    me = bpy.data.meshes.new(name)
    verts = [(float(i), float(j), 0.0) for j in range(n) for i in range(n)]
    faces = [(j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i)
             for j in range(n - 1) for i in range(n - 1)]
    me.from_pydata(verts, [], faces)
    layer = me.uv_layers.new(name="UVMap")
    h = H
    width = 4.0 * h * GROWTH ** np.arange(n - 1)
    u = np.concatenate([[0.0], np.cumsum(width)])
    uv = np.stack([u[np.tile(np.arange(n), n)], h * np.repeat(np.arange(n), n)], axis=1)
    if fold:
        uv[4 * n + 4] = (u[5] + 0.5 * width[5], 4.3 * h)
    cv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", cv)
    me.attributes[layer.name].data.foreach_set("vector", uv[cv].astype(np.float32).ravel())
    if pins:
        if hasattr(layer, "pin_ensure"):
            layer.pin_ensure()
        layer.pin.foreach_set("value", np.isin(cv, [j * n + i for i, j in pins]))
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    return obj, uv


def graded_grid(bpy):
    """``graded_uv_grid`` with its fold: the object."""
    return graded_uv_grid(bpy)[0]


def counts(ext, obj) -> dict:
    a = ops_uv(ext).analyze_uv(obj, True)
    return {k: int(v.sum()) for k, v in a.masks.items()}


def margin_loops(ext, obj, uv: np.ndarray) -> np.ndarray:
    """(L,) bool: loops of UV vertices of the tangled faces grown by two rings of faces (the
    repair's first margin); every other loop must keep its bits."""
    core = ext.core
    lay = core.uv.weld_uv(*uv_assets.mesh_csr(obj), uv)
    every = np.ones(lay.faces.n_faces, bool)
    tangled = core.uv.tangled_faces(lay, lay.points, every)
    assert tangled.sum() == 6
    region = core.run.repair.grow_region(lay.faces, lay.n_nodes, tangled, 2)
    outside = np.zeros(lay.n_nodes, bool)
    outside[lay.faces.indices[np.repeat(~region, lay.faces.counts)]] = True
    return ~outside[lay.loop_node]


def edit_all(bpy) -> None:
    bpy.context.scene.tool_settings.use_uv_select_sync = True
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")


def test_keep_shapes_repairs_the_fold_and_keeps_every_other_loop(bpy, ext):
    obj = graded_grid(bpy)
    uv0 = uv_values(obj)
    c0 = counts(ext, obj)
    assert c0["INVERTED"] == 2 and c0["OVERLAPPING"] == 6
    inside = margin_loops(ext, obj, uv0)
    edit_all(bpy)
    assert bpy.ops.uv.eegt_untangle_smooth(target_shape="KEEP") == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    uv1 = uv_values(obj)
    assert counts(ext, obj) == {"FLIPPED": 0, "INVERTED": 0, "OVERLAPPING": 0}
    assert np.array_equal(uv1[~inside], uv0[~inside])  # bit for bit outside the margin
    assert np.any(uv1[inside] != uv0[inside])
    (res,) = ops_uv(ext).LAST_RESULTS
    assert res.targets == "KEEP" and res.status == "untangled" and res.written
    assert (res.before["inverted"], res.after["inverted"]) == (2, 0)
    text = res.line()
    assert "(1 = as laid out)" in text
    assert "6 tangled faces took the shape of: 6 a neighbour's" in text
    assert res.as_dict()["targets"] == "KEEP"
    # the moved faces end close to their laid-out shapes (measured: mean 0.961 -> 1.000, worst
    # 0 -> 0.9993)
    assert res.after["distortion_worst"] > 0.99 and res.after["distortion_mean"] > 0.9999


def test_keep_shapes_from_the_sidebar_setting_and_from_python(bpy, ext):
    obj = graded_grid(bpy)
    uv0 = uv_values(obj)
    bpy.context.scene.eegt_uv_settings.target_shape = "KEEP"  # the sidebar's Target
    edit_all(bpy)
    assert bpy.ops.uv.eegt_untangle_smooth() == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    (res,) = ops_uv(ext).LAST_RESULTS
    assert res.targets == "KEEP"
    by_operator = uv_values(obj)
    # the Python entry (Object Mode, no UI) gives the same bits
    obj.data.attributes["UVMap"].data.foreach_set("vector", uv0.ravel())
    out = ext.operators.uv.uv_runner.run_object(obj, ext.core.EEGTParams(), targets="KEEP")
    assert out.targets == "KEEP" and out.status == "untangled"
    assert np.array_equal(uv_values(obj), by_operator)


def test_keep_shapes_is_an_item_of_the_target_choices(bpy, ext):
    ch = ext.core.choices
    assert "KEEP" in ch.ids(ch.UV_TARGET) and ch.UV_TARGET[0].id == "3D"
    op = bpy.ops.uv.eegt_untangle_smooth.get_rna_type().properties["target_shape"]
    assert [i.identifier for i in op.enum_items] == list(ch.ids(ch.UV_TARGET))
    assert op.enum_items["KEEP"].name == "Keep Shapes"
    assert "KEEP" in ext.operators.uv.uv_runner.TARGETS
