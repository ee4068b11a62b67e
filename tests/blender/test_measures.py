"""Analyze Quality's measure choice and the batch command's ``--metrics`` on the installed
extension: stored attributes equal the core's values, report numbers, heat-map direction,
refusal of clashing names, and the CLI report's before/after summaries."""

from __future__ import annotations

import json

import meshdata
import numpy as np
import pytest

from .conftest import DATA, import_obj, positions, snapshot

pytestmark = pytest.mark.blender

NAMES = ("mean_ratio", "min_angle", "max_angle", "aspect_ratio", "scaled_jacobian",
         "skewness")


def attr_name(measure: str) -> str:
    return "eegt_quality" if measure == "mean_ratio" else f"eegt_{measure}"


def face_values(obj, name: str) -> np.ndarray:
    a = obj.data.attributes[name]
    assert (a.domain, a.data_type) == ("FACE", "FLOAT")
    v = np.empty(len(obj.data.polygons), np.float32)
    a.data.foreach_get("value", v)
    return v


def corner_colors(obj) -> np.ndarray:
    a = obj.data.attributes["eegt_quality_color"]
    assert (a.domain, a.data_type) == ("CORNER", "FLOAT_COLOR")
    c = np.empty(4 * len(obj.data.loops), np.float32)
    a.data.foreach_get("color", c)
    return c.reshape(-1, 4)


def mesh_arrays(ext, obj):
    """(2D points on the mesh's plane, core FaceSet, arity per face) as the core sees them."""
    me = obj.data
    nf = len(me.polygons)
    start, total = np.empty(nf, np.int32), np.empty(nf, np.int32)
    me.polygons.foreach_get("loop_start", start)
    me.polygons.foreach_get("loop_total", total)
    corners = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", corners)
    faces = ext.core.faces_from_csr(start, total, corners)
    pts = positions(obj).astype(np.float64)
    frame = ext.core.PlaneFrame.fit(pts, faces, tol=1e-5)
    return frame.to_2d(pts), faces, total


def corner_face(obj) -> np.ndarray:
    me = obj.data
    f = np.empty(len(me.loops), np.int64)
    for p in me.polygons:  # small test meshes only
        f[p.loop_start:p.loop_start + p.loop_total] = p.index
    return f


def test_measure_choice_is_an_enum_with_tooltips_on_the_operator_and_the_scene(bpy, ext):
    op = bpy.ops.mesh.eegt_analyze.get_rna_type().properties["measure"]
    scene = bpy.context.scene.eegt_settings.bl_rna.properties["quality_measure"]
    for prop in (op, scene):
        assert prop.default == "mean_ratio"
        assert tuple(i.identifier for i in prop.enum_items) == NAMES
        for item in prop.enum_items:
            assert item.name and len(item.description) > 30, item.identifier
        assert "heat map" in prop.description
    assert op.is_skip_save  # a script calling Analyze without a measure gets the mean ratio


@pytest.mark.parametrize("measure", NAMES)
def test_analyze_stores_the_cores_values_heat_map_and_report(bpy, ext, capfd, measure):
    obj = import_obj(bpy, "mixed_quad_tri")  # triangles and quads
    before = positions(obj)
    capfd.readouterr()
    assert bpy.ops.mesh.eegt_analyze(measure=measure) == {"FINISHED"}
    assert np.array_equal(positions(obj), before)
    pts, faces, arity = mesh_arrays(ext, obj)
    expected = ext.core.quality(pts, faces, measure=measure)
    stored = face_values(obj, attr_name(measure))
    assert np.array_equal(stored, expected.astype(np.float32))
    others = {attr_name(m) for m in NAMES} - {attr_name(measure)}
    assert not others & set(obj.data.attributes.keys())
    # report: min / mean / max and the count beyond the threshold, from the core's summary
    summary = ext.core.summarize(measure, expected, arity)
    out = capfd.readouterr().out
    if measure == "mean_ratio":
        assert (f"Info: mixed_quad_tri: 2941 faces, 294 inverted, q_min 0.000, q_avg "
                f"{expected.mean():.3f}, q_max {expected.max():.3f}, {summary.n_beyond} "
                f"below 0.5") in out
    else:
        assert f"Info: mixed_quad_tri: {summary.line()}" in out
    # the heat map: faces beyond the threshold are on the red half (red channel 1), the
    # others on the green half (green channel 1); the best face is greener than the worst
    m = ext.core.MEASURES[measure]
    beyond = m.beyond(expected, arity)
    assert 0 < beyond.sum() < len(expected)
    col = corner_colors(obj)
    cf = corner_face(obj)
    assert (col[beyond[cf], 0] == 1.0).all()
    assert (col[~beyond[cf], 1] == 1.0).all()
    best = np.argmax(expected if m.higher_is_better else -expected)
    worst = np.argmin(expected if m.higher_is_better else -expected)
    assert tuple(col[cf == worst][0]) == (1.0, 0.0, 0.0, 1.0)  # inverted or collapsed: red
    assert col[cf == best][0][0] < 0.2 and col[cf == best][0][1] == 1.0


def test_mean_ratio_heat_map_is_todays_formula_bit_for_bit(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    assert bpy.ops.mesh.eegt_analyze() == {"FINISHED"}
    q = face_values(obj, "eegt_quality").astype(np.float64)
    pts, faces, _ = mesh_arrays(ext, obj)
    q64 = ext.core.quality(pts, faces)
    qc = np.clip(q64, 0.0, 1.0)
    rgba = np.empty((qc.size, 4), np.float32)
    rgba[:, 0] = np.clip(2.0 * (1.0 - qc), 0.0, 1.0)
    rgba[:, 1] = np.clip(2.0 * qc, 0.0, 1.0)
    rgba[:, 2] = 0.1
    rgba[:, 3] = 1.0
    rgba[qc <= 0.0] = (1.0, 0.0, 0.0, 1.0)
    assert np.array_equal(corner_colors(obj), rgba[corner_face(obj)])
    assert np.array_equal(q, q64.astype(np.float32))


def test_measures_are_stored_side_by_side_and_the_heat_map_follows_the_last(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    assert bpy.ops.mesh.eegt_analyze() == {"FINISHED"}
    assert bpy.ops.mesh.eegt_analyze(measure="aspect_ratio") == {"FINISHED"}
    q = face_values(obj, "eegt_quality")
    ar = face_values(obj, "eegt_aspect_ratio")
    assert (ar >= 1.0 - 1e-6).all() and int((q <= 0).sum()) == 23
    cf = corner_face(obj)
    col = corner_colors(obj)
    elongated = ar > 5.0  # aspect ratio's threshold: the red half
    assert elongated.sum() == 4
    assert (col[elongated[cf], 0] == 1.0).all() and (col[~elongated[cf], 1] == 1.0).all()
    # the inverted but not elongated faces are on the green half of the aspect ratio map
    assert (col[((q <= 0) & ~elongated)[cf], 1] == 1.0).all()
    # a script calling Analyze with no measure gets the mean ratio again, not the last one
    assert bpy.ops.mesh.eegt_analyze() == {"FINISHED"}
    col2 = corner_colors(obj)
    assert np.allclose(col2[(q <= 0)[cf]], [1, 0, 0, 1])


@pytest.mark.parametrize("measure, name, data_type, domain", [
    ("min_angle", "eegt_min_angle", "INT", "FACE"),
    ("skewness", "eegt_skewness", "FLOAT", "POINT"),
    ("scaled_jacobian", "eegt_quality_color", "BYTE_COLOR", "CORNER")])
def test_analyze_refuses_to_replace_a_user_attribute_of_the_measures_name(
        bpy, ext, measure, name, data_type, domain):
    obj = import_obj(bpy, "quad_hole")
    me = obj.data
    attr = me.attributes.new(name, data_type, domain)
    width = 4 if data_type == "BYTE_COLOR" else 1
    vals = (np.arange(len(attr.data) * width) % 5 / 4).astype(np.float32)
    prop = "color" if width == 4 else "value"
    attr.data.foreach_set(prop, vals.astype(np.int32) if data_type == "INT" else vals)
    before = snapshot(obj, skip=())
    with pytest.raises(RuntimeError, match=f"quad_hole: attribute '{name}' exists as "
                                           f"{data_type} on {domain}"):
        bpy.ops.mesh.eegt_analyze(measure=measure)
    assert snapshot(obj, skip=()) == before  # nothing written, nothing new
    assert bpy.ops.mesh.eegt_analyze(measure=measure, store=False) == {"CANCELLED"}
    me.attributes.remove(me.attributes[name])
    assert bpy.ops.mesh.eegt_analyze(measure=measure) == {"FINISHED"}
    assert me.attributes[attr_name(measure)].data_type == "FLOAT"


def test_analyze_refuses_a_vertex_group_named_like_the_measure(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    obj.vertex_groups.new(name="eegt_scaled_jacobian")
    before = snapshot(obj, skip=())
    with pytest.raises(RuntimeError, match="a vertex group is named 'eegt_scaled_jacobian'"):
        bpy.ops.mesh.eegt_analyze(measure="scaled_jacobian")
    assert snapshot(obj, skip=()) == before
    assert "eegt_quality_color" not in obj.data.attributes
    # another measure's names are free: it is stored
    assert bpy.ops.mesh.eegt_analyze(measure="skewness") == {"FINISHED"}
    assert "eegt_skewness" in obj.data.attributes


def test_a_user_attribute_named_like_another_measure_is_left_alone(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    me = obj.data
    mine = me.attributes.new("eegt_quality", "INT", "POINT")  # the user's, not the measure's
    mine.data.foreach_set("value", np.arange(len(mine.data), dtype=np.int32))
    before = snapshot(obj, skip=("eegt_min_angle", "eegt_quality_color"))
    assert bpy.ops.mesh.eegt_analyze(measure="min_angle") == {"FINISHED"}
    assert snapshot(obj, skip=("eegt_min_angle", "eegt_quality_color")) == before


# -- the batch command ---------------------------------------------------------------------

def read_points_faces(ext, path):
    """The OBJ's 2D points (as float32 positions) and faces, as the installed extension's
    FaceSet (its core is a module apart from the checkout's)."""
    pts, read = meshdata.read(path)
    faces = ext.core.mesh.faces.FaceSet(read.offsets, read.indices)
    return pts[:, :2].astype(np.float32).astype(np.float64), faces


def test_cli_metrics_all_reports_before_and_after_of_every_measure(bpy, ext, tmp_path):
    out, rep = tmp_path / "out.obj", tmp_path / "r.json"
    execute = ext.operators.command.entry.execute
    code = execute([str(DATA / "quad_hole.obj"), "-o", str(out), "--report", str(rep),
                    "--metrics", "all", "--quiet"])
    assert code == 0
    (o,) = json.loads(rep.read_text())["objects"]
    assert tuple(o["metrics"]) == NAMES
    # "before": the input as read; "after": the written result (both OBJ files, z = 0)
    for key, path in (("before", DATA / "quad_hole.obj"), ("after", out)):
        pts, faces = read_points_faces(ext, path)
        for name in NAMES:
            s = o["metrics"][name][key]
            v = ext.core.quality(pts, faces, measure=name)
            assert s["n_faces"] == 140
            assert s["min"] == pytest.approx(v.min(), rel=1e-5, abs=1e-5)
            assert s["mean"] == pytest.approx(v.mean(), rel=1e-5, abs=1e-5)
            assert s["max"] == pytest.approx(v.max(), rel=1e-5, abs=1e-5)
            thr = ext.core.MEASURES[name].threshold(4)
            assert s["thresholds"] == {"4": thr}
            near = np.abs(v - thr) < 1e-4 * max(1.0, abs(thr))  # float32 round trip
            m = ext.core.MEASURES[name]
            lo = int(m.beyond(v, 4)[~near].sum())
            assert lo <= s["n_beyond"] <= lo + int(near.sum())
    mr = o["metrics"]["mean_ratio"]
    assert mr["before"]["min"] == o["before"]["q_min"] == 0.0
    assert mr["before"]["mean"] == pytest.approx(o["before"]["q_avg"], rel=1e-12)
    assert mr["after"]["min"] == pytest.approx(o["after"]["q_min"], rel=1e-12)
    # untangling: every inverted face gone, so no negative angle or scaled Jacobian is left
    assert o["metrics"]["min_angle"]["before"]["min"] < 0 < o["metrics"]["min_angle"][
        "after"]["min"]
    assert o["metrics"]["scaled_jacobian"]["after"]["n_beyond"] < o["metrics"][
        "scaled_jacobian"]["before"]["n_beyond"]
    assert o["metrics"]["max_angle"]["after"]["max"] < 180.0
    assert o["metrics"]["skewness"]["before"]["beyond"] == "above"


def test_cli_metrics_list_and_unwritten_result(bpy, ext, tmp_path):
    rep = tmp_path / "r.json"
    args = [str(DATA / "quad_hole.obj"), "--report", str(rep), "--quiet", "--untangle", "eegt",
            "--max-untangle-iterations", "1", "--no-write-on-fail"]
    assert ext.operators.command.entry.execute([*args, "--metrics", "skewness,min_angle"]) == 3
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["status"] == "failed" and o["written"] is False
    assert tuple(o["metrics"]) == ("skewness", "min_angle")
    for name in ("skewness", "min_angle"):  # nothing written: after is the input
        assert o["metrics"][name]["after"] == o["metrics"][name]["before"]


def test_cli_without_metrics_keeps_the_report_unchanged(bpy, ext, tmp_path):
    rep = tmp_path / "r.json"
    assert ext.operators.command.entry.execute([str(DATA / "quad_hole.obj"), "--report", str(rep),
                                      "--quiet"]) == 0
    (o,) = json.loads(rep.read_text())["objects"]
    assert "metrics" not in o
    assert set(o) == {"kind", "object", "mesh", "status", "message", "written", "before", "after",
                      "untangle_iterations", "smooth_iterations", "global_iterations",
                      "seconds", "backend", "n_nodes", "n_faces", "n_free", "notes"}


@pytest.mark.parametrize("value, needle", [
    ("bogus", "unknown measure 'bogus'"), ("min_angle,nope", "unknown measure 'nope'"),
    (",", "unknown measure ','")])
def test_cli_unknown_metric_is_a_usage_error(bpy, ext, tmp_path, capfd, value, needle):
    rep = tmp_path / "r.json"
    code = ext.operators.command.entry.execute([str(DATA / "quad_hole.obj"), "--metrics", value,
                                      "--report", str(rep)])
    assert code == 2
    err = capfd.readouterr().err.strip().splitlines()[-1]
    assert needle in err and "mean_ratio, min_angle" in err
    assert not rep.exists()  # an argument error stops before anything is read or written
