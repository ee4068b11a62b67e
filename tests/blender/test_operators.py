"""The installed extension driven through bpy.ops on real OBJ meshes (headless bpy)."""

from __future__ import annotations

import numpy as np
import pytest

from .conftest import MODULE, import_obj, mesh_quality, positions, snapshot

pytestmark = pytest.mark.blender


def boundary_mask(ext, obj) -> np.ndarray:
    """Topological boundary + non-manifold vertices, from the packaged core."""
    me = obj.data
    ls = np.empty(len(me.polygons), np.int32)
    lt = np.empty(len(me.polygons), np.int32)
    cv = np.empty(len(me.loops), np.int32)
    me.polygons.foreach_get("loop_start", ls)
    me.polygons.foreach_get("loop_total", lt)
    me.loops.foreach_get("vertex_index", cv)
    faces = ext.core.faces_from_csr(ls, lt, cv)
    return np.asarray(ext.core.boundary_nodes(len(me.vertices), faces))


def last(obj):
    return obj.eegt_last_run


def test_register_unregister_twice(bpy, ext):
    import addon_utils
    for _ in range(2):
        addon_utils.disable(MODULE, default_set=True)
        assert not hasattr(bpy.types, "MESH_OT_eegt_untangle_smooth")
        assert not hasattr(bpy.types.Scene, "eegt_settings")
        addon_utils.enable(MODULE, default_set=True)
        assert hasattr(bpy.types, "MESH_OT_eegt_untangle_smooth")
        assert hasattr(bpy.types.Scene, "eegt_settings")
    for name in ("MESH_OT_eegt_analyze", "MESH_OT_eegt_select_inverted", "MESH_OT_eegt_pin",
                 "MESH_OT_eegt_unpin", "VIEW3D_PT_eegt"):
        assert hasattr(bpy.types, name), name
    for name in ("VIEW3D_PT_eegt", "VIEW3D_PT_eegt_params", "VIEW3D_PT_eegt_last_run"):
        panel = getattr(bpy.types, name)  # all in the 3D View sidebar's EEGT tab
        assert (panel.bl_space_type, panel.bl_region_type, panel.bl_category) == (
            "VIEW_3D", "UI", "EEGT"), name
    # the redo panel carries every core parameter
    op_props = bpy.ops.mesh.eegt_untangle_smooth.get_rna_type().properties.keys()
    for f in ext.core.EEGTParams.field_names():
        assert f in op_props
        assert f in bpy.context.scene.eegt_settings.bl_rna.properties.keys()
    obj = import_obj(bpy, "quad_hole")
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    assert last(obj).inverted_after == 0


def test_object_mode_untangles_and_keeps_boundary(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    before = positions(obj)
    q0 = mesh_quality(ext, obj)
    assert int((q0 <= 0).sum()) == 23
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    after = positions(obj)
    q1 = mesh_quality(ext, obj)
    assert int((q1 <= 0).sum()) == 0
    assert q1.min() > 0.5 and q1.mean() > q0.mean() + 0.2
    bnd = boundary_mask(ext, obj)
    assert bnd.sum() == 56
    assert np.array_equal(after[bnd], before[bnd])  # bit-identical
    assert not np.array_equal(after[~bnd], before[~bnd])
    assert np.all(after[:, 2] == 0.0)
    lr = last(obj)
    assert (lr.status, lr.inverted_before, lr.inverted_after) == ("untangled", 23, 0)
    assert lr.q_min_after == pytest.approx(q1.min(), abs=1e-6)
    assert lr.q_avg_after == pytest.approx(q1.mean(), abs=1e-6)
    assert lr.message.startswith("quad_hole: inverted 23 -> 0, q_min 0.000 -> ")


def test_nothing_changed_is_cancelled(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    before = snapshot(obj, skip=())
    res = bpy.ops.mesh.eegt_untangle_smooth(untangle="eegt", max_untangle_iterations=0,
                                            max_smooth_iterations=0)
    assert res == {"CANCELLED"}
    assert snapshot(obj, skip=()) == before
    assert last(obj).status == "failed"


def test_scene_settings_feed_operator_and_args_override(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    settings = bpy.context.scene.eegt_settings
    settings.untangle = "eegt"  # EEGT only: one iteration cannot untangle quad_hole
    settings.max_untangle_iterations = 1
    settings.max_smooth_iterations = 0
    bpy.ops.mesh.eegt_untangle_smooth()
    assert last(obj).untangle_iterations == 1
    assert last(obj).status == "failed"
    assert last(obj).inverted_after < 23  # best iterate written
    bpy.ops.mesh.eegt_untangle_smooth(max_untangle_iterations=500, max_smooth_iterations=5)
    assert last(obj).status == "untangled"
    assert last(obj).smooth_iterations <= 5


def test_invoke_in_background_runs_to_the_end(bpy, ext, capfd):
    obj = import_obj(bpy, "quad_hole")
    assert bpy.ops.mesh.eegt_untangle_smooth("INVOKE_DEFAULT") == {"FINISHED"}
    assert last(obj).inverted_after == 0
    out = capfd.readouterr().out
    assert "EEGT quad_hole: untangle iteration 0: inverted 23" in out
    assert "smooth iteration" in out


def test_edit_mode_partial_selection(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    me = obj.data
    before = positions(obj)
    q0 = mesh_quality(ext, obj)
    cen = np.array([p.center[:] for p in me.polygons])
    sel = cen[:, 1] > 0.0
    assert (q0[sel] <= 0).sum() > 0 and (q0[~sel] <= 0).sum() > 0
    me.polygons.foreach_set("select", sel)
    vsel = np.zeros(len(me.vertices), bool)
    for p in np.flatnonzero(sel):
        vsel[list(me.polygons[p].vertices)] = True
    me.vertices.foreach_set("select", vsel)
    bpy.ops.object.mode_set(mode="EDIT")
    # the y = 0 border cuts through the tangle: cap the (partly hopeless) untangling
    assert bpy.ops.mesh.eegt_untangle_smooth(max_untangle_iterations=200) == {"FINISHED"}
    assert bpy.context.mode == "EDIT_MESH"
    bpy.ops.object.mode_set(mode="OBJECT")
    after = positions(obj)
    q1 = mesh_quality(ext, obj)
    # vertices of unselected faces (border + outside) are bit-identical
    outside = np.zeros(len(me.vertices), bool)
    for p in np.flatnonzero(~sel):
        outside[list(me.polygons[p].vertices)] = True
    assert np.array_equal(after[outside], before[outside])
    moved = np.any(after != before, axis=1)
    assert moved.any() and not (moved & outside).any()
    assert np.allclose(q1[~sel], q0[~sel], atol=1e-6)
    assert (q1[~sel] <= 0).sum() == (q0[~sel] <= 0).sum() > 0
    assert (q1[sel] <= 0).sum() < (q0[sel] <= 0).sum()
    # one selected face folds only at a concave corner of three fixed vertices (the
    # selection's border) in a simple counterclockwise quad: kept as given, not inverted
    assert last(obj).inverted_before == int((q0[sel] <= 0).sum()) - 1


def _select_vertices(obj, mask):
    obj.data.vertices.foreach_set("select", mask)
    obj.data.edges.foreach_set("select", np.zeros(len(obj.data.edges), bool))
    obj.data.polygons.foreach_set("select", np.zeros(len(obj.data.polygons), bool))


def test_pin_attribute_keeps_vertices(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    before = positions(obj)
    interior = ~boundary_mask(ext, obj)
    pins = np.zeros(len(before), bool)
    pins[np.flatnonzero(interior)[::7]] = True
    _select_vertices(obj, pins)
    bpy.ops.object.mode_set(mode="EDIT")
    assert bpy.ops.mesh.eegt_pin() == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    attr = obj.data.attributes["eegt_pinned"]
    assert (attr.domain, attr.data_type) == ("POINT", "BOOLEAN")
    got = np.zeros(len(before), bool)
    attr.data.foreach_get("value", got)
    assert np.array_equal(got, pins)
    bpy.ops.mesh.eegt_untangle_smooth()
    after = positions(obj)
    assert np.array_equal(after[pins], before[pins])
    assert np.any(after[interior & ~pins] != before[interior & ~pins])
    # use_pinned=False ignores the pins
    bpy.ops.mesh.eegt_untangle_smooth(use_pinned=False)
    assert np.any(positions(obj)[pins] != after[pins])
    # unpin all clears the attribute
    assert bpy.ops.mesh.eegt_unpin(all=True) == {"FINISHED"}
    attr = obj.data.attributes["eegt_pinned"]
    attr.data.foreach_get("value", got)
    assert not got.any()


def test_pin_vertex_group_and_name_clash(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    before = positions(obj)
    interior = np.flatnonzero(~boundary_mask(ext, obj))
    vg = obj.vertex_groups.new(name="eegt_pinned")
    vg.add(interior[::5].tolist(), 1.0, "REPLACE")
    zero = obj.vertex_groups.new(name="other")
    zero.add(interior[1::5].tolist(), 0.5, "REPLACE")
    # Blender refuses an attribute named like the group: the pin goes into the group
    extra = np.zeros(len(before), bool)
    extra[interior[2::5]] = True
    _select_vertices(obj, extra)
    assert bpy.ops.mesh.eegt_pin() == {"FINISHED"}
    assert "eegt_pinned" not in obj.data.attributes
    pinned = np.zeros(len(before), bool)
    pinned[interior[::5]] = True
    pinned |= extra
    bpy.ops.mesh.eegt_untangle_smooth()
    after = positions(obj)
    assert np.array_equal(after[pinned], before[pinned])
    free = np.zeros(len(before), bool)
    free[interior] = True
    free &= ~pinned
    assert np.any(after[free] != before[free])


def test_tilted_plane_stays_in_plane(bpy, ext):
    obj = import_obj(bpy, "tilted_plane")
    before = positions(obj).astype(np.float64)
    c = before.mean(axis=0)
    normal = np.linalg.svd(before - c)[2][2]
    size = np.linalg.norm(np.ptp(before, axis=0))
    assert abs(normal[2]) < 0.99  # really tilted
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    after = positions(obj).astype(np.float64)
    off = np.abs((after - c) @ normal)
    assert off.max() < 4 * np.finfo(np.float32).eps * (size + np.abs(c).max())
    assert last(obj).inverted_after == 0
    assert (mesh_quality(ext, obj) > 0).all()


@pytest.mark.parametrize("name, n_inverted", [("mixed_quad_tri", 294),
                                              ("polygon_voronoi", 100)])
def test_mixed_and_ngon_meshes(bpy, ext, name, n_inverted):
    obj = import_obj(bpy, name)
    sizes = {len(p.vertices) for p in obj.data.polygons}
    assert len(sizes) >= 2 and (max(sizes) > 4 or 3 in sizes)
    q0 = mesh_quality(ext, obj)
    assert int((q0 <= 0).sum()) == n_inverted
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    q1 = mesh_quality(ext, obj)
    assert int((q1 <= 0).sum()) == 0
    assert q1.min() > 0.3 and q1.mean() > q0.mean()
    assert last(obj).inverted_after == 0


def _bad_objects(bpy):
    """A non-planar, a NaN, a face-less and a repeated-vertex mesh object."""
    objs = {}
    good = import_obj(bpy, "quad_hole")
    for name in ("nonplanar", "nan", "all_pinned"):
        o = good.copy()
        o.data = good.data.copy()
        o.name = name
        bpy.context.scene.collection.objects.link(o)
        objs[name] = o
    co = positions(objs["nonplanar"])
    co[0, 2] = 0.5
    objs["nonplanar"].data.attributes["position"].data.foreach_set("vector", co.ravel())
    co = positions(objs["nan"])
    co[3, 0] = np.nan
    objs["nan"].data.attributes["position"].data.foreach_set("vector", co.ravel())
    ap = objs["all_pinned"].data.attributes.new("eegt_pinned", "BOOLEAN", "POINT")
    ap.data.foreach_set("value", np.ones(len(ap.data), bool))
    me = bpy.data.meshes.new("nofaces")
    me.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1), (1, 2)], [])
    objs["nofaces"] = bpy.data.objects.new("nofaces", me)
    me = bpy.data.meshes.new("repeat")
    me.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0.5, 0.5, 0)], [],
                   [(0, 1, 4, 1, 2), (0, 4, 2, 3)])
    objs["repeat"] = bpy.data.objects.new("repeat", me)
    for name in ("nofaces", "repeat"):
        bpy.context.scene.collection.objects.link(objs[name])
    return good, objs


def test_bad_inputs_one_line_each_and_untouched(bpy, ext):
    good, bad = _bad_objects(bpy)
    snaps = {n: snapshot(o, skip=()) for n, o in bad.items()}
    for o in [good, *bad.values()]:
        o.select_set(True)
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    assert last(good).inverted_after == 0
    expect = {"nonplanar": "not planar", "nan": "NaN", "all_pinned": "fixed",
              "nofaces": "no faces", "repeat": "repeats node"}
    for name, o in bad.items():
        assert snapshot(o, skip=()) == snaps[name], name
        lr = last(o)
        assert lr.status == "error", name
        assert lr.message.startswith(f"{name}: not changed: "), lr.message
        assert expect[name] in lr.message, lr.message
        assert "\n" not in lr.message
    # only bad objects: nothing changed -> CANCELLED
    good.select_set(False)
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"CANCELLED"}
    # project=True accepts the slightly non-planar one
    for o in bad.values():
        o.select_set(False)
    bad["nonplanar"].select_set(True)
    bpy.context.view_layer.objects.active = bad["nonplanar"]
    assert bpy.ops.mesh.eegt_untangle_smooth(project=True) == {"FINISHED"}
    assert last(bad["nonplanar"]).inverted_after == 0


def test_everything_but_positions_is_preserved(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    me = obj.data
    rng = np.random.default_rng(1)
    uv = me.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", rng.random(2 * len(me.loops)).astype(np.float32))
    for name, dtype, domain, n, prop in [
            ("fpt", "FLOAT", "POINT", len(me.vertices), "value"),
            ("iedge", "INT", "EDGE", len(me.edges), "value"),
            ("vface", "FLOAT_VECTOR", "FACE", 3 * len(me.polygons), "vector"),
            ("col", "FLOAT_COLOR", "CORNER", 4 * len(me.loops), "color")]:
        a = me.attributes.new(name, dtype, domain)
        vals = rng.random(n) * 100
        a.data.foreach_set(prop, vals.astype(np.int32 if dtype == "INT" else np.float32))
    vg = obj.vertex_groups.new(name="weights")
    vg.add(list(range(0, len(me.vertices), 3)), 0.25, "REPLACE")
    for mname in ("A", "B"):
        me.materials.append(bpy.data.materials.new(mname))
    me.polygons.foreach_set("material_index", (np.arange(len(me.polygons)) % 2).astype(np.int32))
    before = snapshot(obj)
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    assert snapshot(obj) == before
    assert bpy.ops.mesh.eegt_analyze() == {"FINISHED"}
    assert snapshot(obj, skip=("position", "eegt_quality", "eegt_quality_color")) == before


def test_analyze_and_select_inverted(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    me = obj.data
    before = positions(obj)
    assert bpy.ops.mesh.eegt_analyze() == {"FINISHED"}
    assert np.array_equal(positions(obj), before)
    qa = me.attributes["eegt_quality"]
    assert (qa.domain, qa.data_type) == ("FACE", "FLOAT")
    q = np.empty(len(me.polygons), np.float32)
    qa.data.foreach_get("value", q)
    assert int((q <= 0).sum()) == 23
    assert np.allclose(q, mesh_quality(ext, obj), atol=1e-6)
    ca = me.attributes["eegt_quality_color"]
    assert ca.domain == "CORNER"
    col = np.empty(4 * len(me.loops), np.float32)
    ca.data.foreach_get("color", col)
    col = col.reshape(-1, 4)
    inverted_corner = np.zeros(len(me.loops), bool)
    for p in np.flatnonzero(q <= 0):
        inverted_corner[me.polygons[p].loop_start:me.polygons[p].loop_start
                        + me.polygons[p].loop_total] = True
    assert np.allclose(col[inverted_corner], [1, 0, 0, 1])
    assert (col[~inverted_corner, 1] > 0).all()
    assert me.color_attributes.active_color_name == "eegt_quality_color"
    # select inverted (threshold 0) in edit mode, then "poor" faces with a threshold
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.context.tool_settings.mesh_select_mode = (True, False, False)
    assert bpy.ops.mesh.eegt_select_inverted() == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    sel = np.zeros(len(me.polygons), bool)
    me.polygons.foreach_get("select", sel)
    assert np.array_equal(sel, q <= 0)
    assert tuple(bpy.context.tool_settings.mesh_select_mode) == (False, False, True)
    assert bpy.ops.mesh.eegt_select_inverted(threshold=0.6) == {"FINISHED"}
    me.polygons.foreach_get("select", sel)
    assert np.array_equal(sel, q <= 0.6) and sel.sum() > 23
    # analyze without storing: a report only, no undo step
    assert bpy.ops.mesh.eegt_analyze(store=False) == {"CANCELLED"}


def test_shape_key_active_key_only(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    basis = obj.shape_key_add(name="Basis")
    key = obj.shape_key_add(name="Tangle", from_mix=False)
    obj.active_shape_key_index = 1
    basis_before = np.empty(3 * len(basis.data), np.float32)
    basis.data.foreach_get("co", basis_before)
    mesh_before = positions(obj)
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    lr = last(obj)
    assert lr.inverted_after == 0
    assert "shape key 'Tangle'" in lr.message
    basis_after = np.empty_like(basis_before)
    basis.data.foreach_get("co", basis_after)
    assert np.array_equal(basis_after, basis_before)
    assert np.array_equal(positions(obj), mesh_before)
    key_after = np.empty_like(basis_before)
    key.data.foreach_get("co", key_after)
    assert not np.array_equal(key_after, basis_before)


def test_shared_mesh_runs_once_and_modifiers_noted(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    twin = bpy.data.objects.new("twin", obj.data)
    bpy.context.scene.collection.objects.link(twin)
    twin.select_set(True)
    obj.modifiers.new("Sub", "SUBSURF")
    bpy.ops.mesh.eegt_untangle_smooth()
    ops = ext.operators.mesh.ops_untangle
    assert len(ops.LAST_RESULTS) == 1
    assert "base mesh (modifiers not applied)" in ops.LAST_RESULTS[0].line()
    assert ops.LAST_RESULTS[0].after["n_inverted"] == 0


def test_linked_library_mesh_is_refused(bpy, ext, tmp_path):
    src = import_obj(bpy, "quad_hole")
    lib = tmp_path / "lib.blend"
    bpy.data.libraries.write(str(lib), {src})
    bpy.ops.wm.read_homefile(use_empty=True)
    with bpy.data.libraries.load(str(lib), link=True) as (_src, dst):
        dst.objects = ["quad_hole"]
    obj = dst.objects[0]
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    before = positions(obj)
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"CANCELLED"}
    assert np.array_equal(positions(obj), before)
    assert "linked from a library" in ext.operators.mesh.ops_untangle.LAST_RESULTS[0].line()


def test_backend_choice_does_not_list_devices_while_the_device_was_never_chosen(bpy, ext,
                                                                               monkeypatch):
    """Listing OpenCL devices imports pyopencl and asks every driver: a fresh `blender -b`
    command does not pay for it before its work when the device preference is Automatic
    by default; a chosen device is read as before."""
    prefs_mod = ext.operators.prefs
    prefs = bpy.context.preferences.addons[MODULE].preferences
    if prefs.is_property_set("opencl_device"):
        prefs.property_unset("opencl_device")

    def no_listing():
        raise AssertionError("devices listed")

    monkeypatch.setattr(prefs_mod, "_list_devices", no_listing)
    assert prefs_mod.resolve_backend("AUTO") == ("auto", "AUTO")
    assert prefs_mod.resolve_backend("OPENCL") == ("opencl", "AUTO")
    monkeypatch.setattr(prefs_mod, "_list_devices", lambda: [("0:0", "Some device")])
    prefs.opencl_device = "0:0"
    try:
        assert prefs_mod.resolve_backend("AUTO") == ("auto", "0:0")
    finally:
        prefs.property_unset("opencl_device")


def test_preferences_and_backend_choice(bpy, ext):
    prefs = bpy.context.preferences.addons[MODULE].preferences
    assert prefs.default_backend == "NUMPY"
    items = ext.operators.ui.prefs.device_items(prefs, bpy.context)
    assert items[0][0] == "AUTO" and prefs.opencl_device == "AUTO"
    resolve = ext.operators.ui.prefs.resolve_backend
    assert resolve("PREFS")[0] == "numpy"
    assert resolve("AUTO") == ("auto", "AUTO") and resolve("NUMPY") == ("numpy", None)
    assert resolve("AUTO")[0] == "auto" and resolve("OPENCL")[0] == "opencl"
    prefs.default_backend = "AUTO"
    try:
        assert resolve("PREFS")[0] == "auto"
    finally:
        prefs.default_backend = "NUMPY"
    # the scene backend "Default" follows the preference; an explicit NumPy run says numpy
    obj = import_obj(bpy, "quad_hole")
    bpy.ops.mesh.eegt_untangle_smooth(backend="NUMPY")
    assert last(obj).backend == "numpy"


@pytest.mark.parametrize("written", [True, False])
def test_result_with_an_inverted_face_left_is_failed_whatever_the_core_said(ext, written):
    """The status of an object never claims more than its written (or kept) positions: a
    face still inverted there makes 'untangled' and 'valid' 'failed', with the count."""
    from importlib import import_module

    runner = import_module(f"{MODULE}.operators.mesh.runner")
    for status in ("untangled", "valid"):
        out = runner.ObjectResult(object="Plate", status=status, written=written,
                                  after={"n_inverted": 2, "q_min": 0.0, "q_avg": 0.7})
        out.claim_no_more_than_result()
        where = "written" if written else "kept"
        assert (out.status, out.ok) == ("failed", False)
        assert out.message == f"2 faces stay inverted in the {where} positions"
    clean = runner.ObjectResult(object="Plate", status="untangled", written=written,
                                after={"n_inverted": 0, "q_min": 0.4, "q_avg": 0.9})
    clean.claim_no_more_than_result()
    assert (clean.status, clean.message) == ("untangled", "")
