"""Project to Plane, no-op runs, pin attributes of every type, and the quality attributes'
names, through the installed extension (headless bpy)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from .conftest import import_obj, positions, snapshot

pytestmark = pytest.mark.blender

N = 6  # grid cells per side


def grid_object(bpy, name: str, jitter: float = 0.0, lift: float = 0.0, rot=None, seed: int = 0):
    """An N x N quad grid of side 1.5 (float32-exact nodes at z = 0), interior nodes jittered
    in the plane (folds above ~0.5 cell) and lifted by a bump; optionally rotated + shifted.
    Returns (object, boundary mask)."""
    xs, ys = np.meshgrid(np.arange(N + 1) * 0.25, np.arange(N + 1) * 0.25)
    p = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    border = np.zeros((N + 1, N + 1), bool)
    border[[0, -1], :] = border[:, [0, -1]] = True
    border = border.ravel()
    rng = np.random.default_rng(seed)
    p[~border, :2] += rng.uniform(-jitter, jitter, ((~border).sum(), 2)) * 0.25
    p[~border, 2] = lift * np.sin(np.pi * p[~border, 0] / 1.5) * np.sin(np.pi * p[~border, 1] / 1.5)
    if rot is not None:
        p = p @ rot.T + [3.0, -2.0, 5.0]
    faces = [(j * (N + 1) + i, j * (N + 1) + i + 1, (j + 1) * (N + 1) + i + 1,
              (j + 1) * (N + 1) + i) for j in range(N) for i in range(N)]
    me = bpy.data.meshes.new(name)
    me.from_pydata(p.astype(np.float32).tolist(), [], faces)
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    for o in bpy.context.selected_objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return obj, border


def tilt() -> np.ndarray:
    a, b = 0.7, -1.1
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]) @ \
        np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])


def line(ext) -> str:
    return ext.operators.mesh.ops_untangle.LAST_RESULTS[0].line()


# -- Project to Plane ------------------------------------------------------------------------

def test_project_puts_every_vertex_on_the_plane_of_the_fixed_ones(bpy, ext):
    """Boundary exactly at z = 0, interior folded and lifted by up to 0.05: every vertex
    ends at z == 0 (the all-vertex centroid plane was at z ~ 0.01), boundary bit-identical."""
    obj, border = grid_object(bpy, "bump", jitter=0.7, lift=0.05)
    before = positions(obj)
    assert before[:, 2].astype(np.float64).mean() > 0.009
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"CANCELLED"}  # not planar: refused
    assert "not planar" in obj.eegt_last_run.message
    assert np.array_equal(positions(obj), before)
    assert bpy.ops.mesh.eegt_untangle_smooth(project=True) == {"FINISHED"}
    after = positions(obj)
    assert np.all(after[:, 2] == 0.0)
    assert after[border].tobytes() == before[border].tobytes()
    lr = obj.eegt_last_run
    assert (lr.inverted_after, lr.status) == (0, "untangled") and lr.inverted_before > 0
    assert "projected onto the plane of the fixed vertices (largest offset 0.0" in lr.message


@pytest.mark.parametrize("selected_only", [False, True])
def test_plane_fit_from_the_edge_table_equals_the_sorted_search_bit_for_bit(bpy, ext,
                                                                             selected_only):
    """The operator analyses the edges from Blender's edge table (no sort of every corner);
    a loose edge and a face selection change nothing: the same edges, counts and open
    edges as the sorted analysis of the chosen faces, the same frame."""
    runner, plane = ext.operators.mesh.runner, ext.core.mesh.plane
    obj = import_obj(bpy, "tri_two_holes")
    me = obj.data
    co = positions(obj).astype(np.float64) @ tilt().T + [1.0, 2.0, -3.0]
    me.attributes["position"].data.foreach_set("vector", co.astype(np.float32).ravel())
    n0 = len(me.vertices)
    me.vertices.add(2)
    me.edges.add(1)
    me.edges[-1].vertices = (n0, n0 + 1)  # a loose edge: its vertices are pinned, not faces
    if selected_only:
        sel = np.zeros(len(me.polygons), dtype=bool)
        sel[: len(sel) // 2] = True
        me.polygons.foreach_set("select", sel)
    me.update()
    job = runner.prepare(obj, selected_only=selected_only, project=True)
    assert job.error is None
    n = job.nodes.size
    topo = ext.operators.mesh.mesh_io.read_topology(me)
    faces = np.flatnonzero(np.asarray([p.select for p in me.polygons])) if selected_only \
        else np.arange(len(me.polygons))
    idx = np.concatenate([np.arange(topo.loop_start[f], topo.loop_start[f] + topo.loop_total[f])
                          for f in faces])
    lut = np.zeros(len(me.vertices), dtype=np.int64)
    lut[job.nodes] = np.arange(n)
    offsets = np.concatenate([[0], np.cumsum(topo.loop_total[faces])])
    got = runner._edge_info(idx, offsets, topo, ext.operators.mesh.mesh_io.read_edges(me), lut, n)
    assert got is not None and job.edges is not None
    sorted_info = ext.core.mesh.topology.EdgeInfo(job.faces, n)
    for info in (got, job.edges):
        assert np.array_equal(info.boundary_mask(), sorted_info.boundary_mask())
        assert sorted(zip(info.lo.tolist(), info.hi.tolist(), info.counts.tolist())) == \
            sorted(zip(sorted_info.lo.tolist(), sorted_info.hi.tolist(),
                       sorted_info.counts.tolist()))
        want = plane.open_edges(job.faces, n)
        assert want[0].size > 50
        for g, w in zip(info.open_edges(), want):
            assert g.tobytes() == w.tobytes()
    pts = job.co[job.nodes].astype(np.float64)
    ref = plane.PlaneFrame.fit(pts, job.faces, tol=runner.PLANE_TOL, project=True,
                               fixed=job.fixed)
    for attr in ("origin", "u", "v", "normal"):
        assert getattr(job.frame, attr).tobytes() == getattr(ref, attr).tobytes()


def test_an_edge_table_naming_an_interior_edge_twice_falls_back_to_the_sorted_analysis(bpy,
                                                                                         ext):
    """A corrupt mesh whose two faces walk one interior edge through two copies of it in
    the edge table: the table's counts would call it an open edge (its nodes fixed); the
    operator sees the table does not fit and analyses the faces themselves, so the result
    is the intact mesh's, bit for bit."""
    runner, topology = ext.operators.mesh.runner, ext.core.mesh.topology
    good, _ = grid_object(bpy, "intact", jitter=0.7)
    bad, _ = grid_object(bpy, "split", jitter=0.7)
    me = bad.data
    ev = np.empty(2 * len(me.edges), dtype=np.int32)
    me.edges.foreach_get("vertices", ev)
    ce = np.empty(len(me.loops), dtype=np.int32)
    me.loops.foreach_get("edge_index", ce)
    uses = np.bincount(ce, minlength=len(me.edges))
    inner = int(np.flatnonzero(uses == 2)[0])  # an interior edge: two corners walk it
    me.edges.add(1)
    me.edges[-1].vertices = tuple(int(v) for v in ev.reshape(-1, 2)[inner])
    ce[np.flatnonzero(ce == inner)[0]] = len(me.edges) - 1  # one walk on the copy
    me.loops.foreach_set("edge_index", ce)
    job = runner.prepare(bad)
    assert job.error is None and job.edges.in_key_order  # the sorted analysis, not the table's
    want = topology.EdgeInfo(job.faces, job.nodes.size)
    assert np.array_equal(job.edges.boundary_mask(), want.boundary_mask())
    assert job.edges.boundary_mask().sum() == 4 * N
    for obj in (good, bad):
        bpy.context.view_layer.objects.active = obj
        for o in bpy.context.selected_objects:
            o.select_set(False)
        obj.select_set(True)
        assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    assert positions(good).tobytes() == positions(bad)[: len(good.data.vertices)].tobytes()


def test_project_keeps_a_pinned_vertex_off_the_plane_and_says_so(bpy, ext):
    """A pinned vertex 0.05 off a tilted plane stays (bit for bit); the others land on the
    plane through the fixed vertices' centroid (1/25 of the lift away from the boundary's)."""
    rot = tilt()
    obj, border = grid_object(bpy, "tilted_bump", jitter=0.7, lift=0.05, rot=rot, seed=1)
    centre = 3 * (N + 1) + 3
    pins = obj.data.attributes.new("eegt_pinned", "BOOLEAN", "POINT")
    mask = np.zeros(len(border), bool)
    mask[centre] = True
    pins.data.foreach_set("value", mask)
    before = positions(obj)
    lift = float((before[centre] - [3.0, -2.0, 5.0]) @ rot[:, 2])
    assert lift > 0.04
    assert bpy.ops.mesh.eegt_untangle_smooth(project=True) == {"FINISHED"}
    after = positions(obj).astype(np.float64)
    fixed = border | mask
    assert after[fixed].tobytes() == before[fixed].astype(np.float64).tobytes()
    off = (after - [3.0, -2.0, 5.0]) @ rot[:, 2]
    eps = 4 * np.finfo(np.float32).eps * 6.0  # float32 storage of coordinates up to ~6
    assert np.abs(off[~fixed] - lift / 25).max() < eps
    assert (f"boundary/pinned vertices up to {lift * 24 / 25:.3g} off the plane were kept "
            "where they are") in obj.eegt_last_run.message


# -- a result no better than the input writes nothing ------------------------------------

@pytest.mark.parametrize("tilted", [False, True])
def test_optimal_mesh_is_not_rewritten(bpy, ext, tmp_path, tilted):
    """A grid of squares (q = 1 everywhere; tilted: float32 nodes off every axis) is left bit
    for bit by the operator, runner.run_object and the command line."""
    obj, _ = grid_object(bpy, "squares", rot=tilt() if tilted else None)
    before = snapshot(obj, skip=())
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"CANCELLED"}
    assert snapshot(obj, skip=()) == before
    res = ext.operators.mesh.ops_untangle.LAST_RESULTS[0]
    assert (res.status, res.written) == ("valid", False)
    assert (res.before["n_inverted"], res.after["n_inverted"]) == (0, 0)
    assert res.before["q_min"] == pytest.approx(1.0, abs=1e-6)
    assert "nothing written" in line(ext) and "mesh unchanged" in line(ext)
    runner = ext.operators.mesh.runner
    r = runner.run_object(obj, ext.core.EEGTParams())
    assert (r.status, r.written) == ("valid", False)
    assert snapshot(obj, skip=()) == before
    # the command line, .blend in and out
    src, out, rep = tmp_path / "in.blend", tmp_path / "out.blend", tmp_path / "r.json"
    bpy.ops.wm.save_as_mainfile(filepath=str(src))
    execute = ext.operators.command.entry.execute
    code = execute([str(src), "-o", str(out), "--report", str(rep), "--quiet"])
    assert code == 0
    (o,) = json.loads(rep.read_text())["objects"]
    assert (o["status"], o["written"]) == ("valid", False)
    bpy.ops.wm.open_mainfile(filepath=str(out))
    assert snapshot(bpy.data.objects["squares"], skip=()) == before


# -- pins of every attribute type ------------------------------------------------------------

def _boundary(ext, obj) -> np.ndarray:
    me = obj.data
    ls, lt = np.empty(len(me.polygons), np.int32), np.empty(len(me.polygons), np.int32)
    cv = np.empty(len(me.loops), np.int32)
    me.polygons.foreach_get("loop_start", ls)
    me.polygons.foreach_get("loop_total", lt)
    me.loops.foreach_get("vertex_index", cv)
    return np.asarray(ext.core.boundary_nodes(len(me.vertices),
                                              ext.core.faces_from_csr(ls, lt, cv)))


@pytest.mark.parametrize("data_type, on, dtype", [("BOOLEAN", True, bool),
                                                  ("FLOAT", 0.5, np.float32),
                                                  ("FLOAT", -2.0, np.float32),
                                                  ("INT", 7, np.int32),
                                                  ("INT8", -3, np.int8)])
def test_pin_attribute_of_any_number_type_pins_where_nonzero(bpy, ext, data_type, on, dtype):
    obj = import_obj(bpy, "quad_hole")
    before = positions(obj)
    interior = np.flatnonzero(~_boundary(ext, obj))
    pins = np.zeros(len(before), bool)
    pins[interior[::6]] = True
    attr = obj.data.attributes.new("eegt_pinned", data_type, "POINT")
    attr.data.foreach_set("value", np.where(pins, on, 0).astype(dtype))
    raw = np.zeros(len(before), dtype)
    attr.data.foreach_get("value", raw)
    assert np.array_equal(raw != 0, pins)
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    after = positions(obj)
    assert after[pins].tobytes() == before[pins].tobytes()
    free = np.zeros(len(before), bool)
    free[interior] = True
    free &= ~pins
    assert np.any(after[free] != before[free], axis=1).sum() > 0.9 * free.sum()
    assert obj.eegt_last_run.inverted_after == 0
    # the Pin operator edits the attribute in its own type: 1 for new pins, others kept
    extra = np.zeros(len(before), bool)
    extra[interior[1]] = True
    obj.data.vertices.foreach_set("select", extra)
    assert bpy.ops.mesh.eegt_pin() == {"FINISHED"}
    attr = obj.data.attributes["eegt_pinned"]
    assert attr.data_type == data_type
    attr.data.foreach_get("value", raw)
    assert np.array_equal(raw[pins], np.full(pins.sum(), on, dtype))
    assert raw[interior[1]] == 1 and np.count_nonzero(raw) == pins.sum() + 1


@pytest.mark.parametrize("data_type, domain", [("FLOAT", "FACE"), ("BOOLEAN", "EDGE"),
                                               ("FLOAT_VECTOR", "POINT"),
                                               ("FLOAT_COLOR", "POINT")])
def test_pin_attribute_of_unusable_domain_or_type_is_a_one_line_error(bpy, ext, data_type,
                                                                      domain):
    obj = import_obj(bpy, "quad_hole")
    obj.data.attributes.new("eegt_pinned", data_type, domain)
    obj.data.vertices.foreach_set("select", np.ones(len(obj.data.vertices), bool))
    before = snapshot(obj, skip=())
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"CANCELLED"}
    assert snapshot(obj, skip=()) == before
    lr = obj.eegt_last_run
    assert lr.status == "error" and "\n" not in lr.message
    assert lr.message == (
        f"quad_hole: not changed: attribute 'eegt_pinned' is {data_type} on {domain}: pins "
        "must be a point attribute (boolean, float, integer or 8-bit integer, nonzero = "
        "pinned); fix it or turn off Use Pinned")
    assert bpy.ops.mesh.eegt_pin() == {"CANCELLED"}  # the Pin operator refuses it too
    assert snapshot(obj, skip=()) == before
    assert bpy.ops.mesh.eegt_untangle_smooth(use_pinned=False) == {"FINISHED"}
    assert obj.eegt_last_run.inverted_after == 0


# -- Analyze Quality never deletes a user's attribute ---------------------------------------

@pytest.mark.parametrize("name, data_type, domain", [
    ("eegt_quality", "INT", "FACE"), ("eegt_quality", "FLOAT", "POINT"),
    ("eegt_quality_color", "BYTE_COLOR", "CORNER"), ("eegt_quality_color", "FLOAT_COLOR",
                                                     "POINT")])
def test_analyze_refuses_to_replace_a_user_attribute(bpy, ext, name, data_type, domain):
    obj = import_obj(bpy, "quad_hole")
    me = obj.data
    attr = me.attributes.new(name, data_type, domain)
    width = {"INT": 1, "FLOAT": 1, "BYTE_COLOR": 4, "FLOAT_COLOR": 4}[data_type]
    prop = "value" if width == 1 else "color"
    vals = (np.arange(len(attr.data) * width) % 5 / 4).astype(np.float32)
    attr.data.foreach_set(prop, vals.astype(np.int32) if data_type == "INT" else vals)
    before = snapshot(obj, skip=())
    with pytest.raises(RuntimeError, match=f"quad_hole: attribute '{name}' exists as "
                                           f"{data_type} on {domain}"):
        bpy.ops.mesh.eegt_analyze()
    assert snapshot(obj, skip=()) == before  # the user's attribute, and nothing new
    assert {a.name for a in me.attributes} & {"eegt_quality", "eegt_quality_color"} == {name}
    # measuring without storing still works, and so does storing once the name is free
    assert bpy.ops.mesh.eegt_analyze(store=False) == {"CANCELLED"}
    me.attributes.remove(me.attributes[name])
    assert bpy.ops.mesh.eegt_analyze() == {"FINISHED"}
    assert me.attributes["eegt_quality"].data_type == "FLOAT"
    assert bpy.ops.mesh.eegt_analyze() == {"FINISHED"}  # our own attributes are reused


def test_analyze_refuses_a_vertex_group_named_like_the_quality(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    obj.vertex_groups.new(name="eegt_quality_color")
    before = snapshot(obj, skip=())
    with pytest.raises(RuntimeError, match="a vertex group is named 'eegt_quality_color'"):
        bpy.ops.mesh.eegt_analyze()
    assert snapshot(obj, skip=()) == before
    assert "eegt_quality" not in obj.data.attributes
