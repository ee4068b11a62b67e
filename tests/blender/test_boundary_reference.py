"""Boundary modes and reference targets in the installed extension: scene settings, the
operator (its redo-panel properties), the reference sources (shape key, object, OBJ file),
the command line, and bad input (one line, mesh unchanged)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from oracles import boundary_loops

from bench.meshgen import boundary_layer_annulus, moved_body
from core.mesh.obj_io import write_obj

from .conftest import DATA, import_obj, positions, snapshot

pytestmark = pytest.mark.blender


def loops_of(obj) -> list[np.ndarray]:
    """Boundary loops of a mesh object (faces counterclockwise: interior on the left), by the
    tests' oracle (tests/oracles.py)."""
    return boundary_loops([list(poly.vertices) for poly in obj.data.polygons])


def polyline_distance(q: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Distance of each point q to the closed polyline through the points a."""
    b = np.roll(a, -1, axis=0)
    d = b - a
    u = np.clip(((q[:, None] - a[None]) * d[None]).sum(2) / (d * d).sum(1)[None], 0.0, 1.0)
    return np.sqrt(((a[None] + u[..., None] * d[None] - q[:, None]) ** 2).sum(2)).min(1)


def check_slid(before: np.ndarray, after: np.ndarray, loops) -> int:
    """Every boundary vertex on its input loop (float32 storage: 1e-6 of the size), the four
    square corners unchanged; returns how many boundary vertices moved."""
    size = float(np.ptp(before, axis=0).max())
    moved = 0
    for loop in loops:
        dist = polyline_distance(after[loop].astype(np.float64), before[loop].astype(np.float64))
        assert dist.max() <= 1e-6 * size
        moved += int(np.any(after[loop] != before[loop], axis=1).sum())
    return moved


def square_corners(co: np.ndarray) -> np.ndarray:
    lo, hi = co[:, :2].min(axis=0), co[:, :2].max(axis=0)
    return np.flatnonzero(np.all((co[:, :2] == lo) | (co[:, :2] == hi), axis=1))


def new_object(bpy, name: str, points: np.ndarray, faces) -> object:
    """A mesh object from 2D points (z = 0) and faces, selected and active."""
    me = bpy.data.meshes.new(name)
    verts = np.column_stack([points, np.zeros(len(points))])
    me.from_pydata(verts.tolist(), [], [list(map(int, f)) for f in faces])
    me.update()
    obj = bpy.data.objects.new(name, me)
    bpy.context.collection.objects.link(obj)
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return obj


def annulus_with_keys(bpy):
    """The boundary-layer O-grid: Basis = the reference, key 'Moved' (active) = the body
    moved, 43 quads folded."""
    ref, faces = boundary_layer_annulus()
    obj = new_object(bpy, "annulus", ref, faces.to_lists())
    obj.shape_key_add(name="Basis")
    moved = obj.shape_key_add(name="Moved")
    co = np.column_stack([moved_body(ref), np.zeros(len(ref))]).astype(np.float32)
    moved.data.foreach_set("co", co.ravel())
    obj.active_shape_key_index = 1
    return obj, ref, faces


def key_positions(obj, name: str) -> np.ndarray:
    kb = obj.data.shape_keys.key_blocks[name]
    co = np.empty(len(kb.data) * 3, np.float32)
    kb.data.foreach_get("co", co)
    return co.reshape(-1, 3)


def size_ratios(points: np.ndarray, ref: np.ndarray, faces) -> tuple[float, float]:
    """Median and 95th percentile of max(s / s_ref, s_ref / s), s = sqrt(face area)."""
    def areas(p):
        out = []
        for f in faces.to_lists():
            x, y = p[f, 0], p[f, 1]
            out.append(0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)))
        return np.array(out)
    s = np.sqrt(areas(points) / areas(ref))
    s = np.maximum(s, 1 / s)
    return float(np.median(s)), float(np.percentile(s, 95))


# ---- settings, redo panel, command line ------------------------------------------------


def test_boundary_and_target_everywhere_with_tooltips(bpy, ext):
    settings = bpy.context.scene.eegt_settings
    assert (settings.boundary, settings.feature_angle, settings.target) == (
        "fixed", 30.0, "regular")
    op = bpy.ops.mesh.eegt_untangle_smooth.get_rna_type().properties
    for rna in (settings.bl_rna.properties, op):
        assert [i.identifier for i in rna["boundary"].enum_items] == ["fixed", "slide", "free"]
        assert [i.identifier for i in rna["target"].enum_items] == ["regular", "reference", "keep"]
        for name in ("boundary", "target"):
            assert all(len(i.description) > 30 for i in rna[name].enum_items)
        for name in ("boundary", "feature_angle", "target", "reference_key",
                     "reference_object"):
            assert len(rna[name].description) > 30, name
        assert (rna["feature_angle"].hard_min, rna["feature_angle"].hard_max) == (0.0, 180.0)
    assert settings.bl_rna.properties["reference_object"].fixed_type.identifier == "Object"
    parser = ext.operators.command.parser.build_parser()
    flags = {a.dest: a for a in parser._actions}
    assert flags["boundary"].choices == ["fixed", "slide", "free"]
    assert flags["target"].choices == ["regular", "reference", "keep"]
    assert "--reference" in flags["reference"].option_strings
    assert "--reference-key" in flags["reference_key"].option_strings
    assert hasattr(bpy.types.MESH_OT_eegt_untangle_smooth, "draw")


# ---- boundary modes ----------------------------------------------------------------------


def test_slide_from_the_redo_panel_keeps_the_boundary_curve(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    before = positions(obj)
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    fixed_q = obj.eegt_last_run.q_avg_after
    obj.data.attributes["position"].data.foreach_set("vector", before.ravel())
    assert bpy.ops.mesh.eegt_untangle_smooth(boundary="slide") == {"FINISHED"}
    after = positions(obj)
    lr = obj.eegt_last_run
    assert lr.inverted_after == 0 and lr.q_avg_after > fixed_q + 0.01
    assert check_slid(before, after, loops_of(obj)) > 20
    corners = square_corners(before)
    assert corners.size == 4 and np.array_equal(after[corners], before[corners])


def test_scene_setting_and_feature_angle_drive_the_operator(bpy, ext):
    obj = import_obj(bpy, "quad_hole")
    before = positions(obj)
    settings = bpy.context.scene.eegt_settings
    settings.boundary = "slide"
    settings.feature_angle = 10.0  # the hole's nodes turn by 12.9 deg: corners now
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    after = positions(obj)
    hole = max(loops_of(obj), key=lambda lp: -np.ptp(before[lp, 0]))  # the smaller loop
    assert np.array_equal(after[hole], before[hole])
    assert check_slid(before, after, loops_of(obj)) > 10  # the square's sides slid


def test_free_mode_with_pins_untangles_three_quads_around_a_triangle(bpy, ext):
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3.0) / 2]])
    pts, faces = [*tri], [[0, 1, 2]]
    for k in range(3):
        u, v = k, (k + 1) % 3
        d = tri[v] - tri[u]
        out = np.array([d[1], -d[0]])
        pts += [tri[u] + out, tri[v] + out]
        faces.append([u, 3 + 2 * k, 4 + 2 * k, v])
    p = np.array(pts)
    p[:3] = tri.mean(axis=0)  # the free corners all start at one point
    obj = new_object(bpy, "hybrid", p, faces)
    attr = obj.data.attributes.new("eegt_pinned", "BOOLEAN", "POINT")
    attr.data.foreach_set("value", [False] * 3 + [True] * 6)
    before = positions(obj)
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"CANCELLED"}  # fixed: nothing can move
    assert np.array_equal(positions(obj), before)
    assert bpy.ops.mesh.eegt_untangle_smooth(boundary="free") == {"FINISHED"}
    after = positions(obj)
    assert obj.eegt_last_run.inverted_after == 0 and obj.eegt_last_run.q_min_after > 0.9
    assert np.array_equal(after[3:], before[3:])


# ---- reference targets -------------------------------------------------------------------


def test_reference_from_the_basis_key_keeps_the_grading(bpy, ext):
    obj, ref, faces = annulus_with_keys(bpy)
    basis = key_positions(obj, "Basis")
    assert bpy.ops.mesh.eegt_untangle_smooth(target="reference") == {"FINISHED"}
    lr = obj.eegt_last_run
    assert lr.inverted_before == 43 and lr.inverted_after == 0
    assert "face shapes of shape key 'Basis'" in lr.message
    # beside the stats against the reference's shapes, the mean ratio against regular
    # polygons (the report line's last stats)
    assert "; against regular polygons: q_min 0.0000 -> " in lr.message
    moved = key_positions(obj, "Moved")
    med, p95 = size_ratios(moved[:, :2].astype(np.float64), ref, faces)
    assert med < 1.05 and p95 < 1.2  # measured 1.02 / 1.06 in the core
    assert np.array_equal(key_positions(obj, "Basis"), basis)  # the reference is untouched
    # regular targets on the same input lose the grading
    moved_in = np.column_stack([moved_body(ref), np.zeros(len(ref))]).astype(np.float32)
    obj.data.shape_keys.key_blocks["Moved"].data.foreach_set("co", moved_in.ravel())
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    reg = key_positions(obj, "Moved")
    assert size_ratios(reg[:, :2].astype(np.float64), ref, faces)[1] > 3


def test_reference_object_from_the_scene_settings(bpy, ext):
    ref, faces = boundary_layer_annulus()
    ref_obj = new_object(bpy, "reference", ref, faces.to_lists())
    obj = new_object(bpy, "moved", moved_body(ref), faces.to_lists())
    settings = bpy.context.scene.eegt_settings
    settings.target = "reference"
    settings.reference_object = ref_obj
    assert bpy.ops.mesh.eegt_untangle_smooth() == {"FINISHED"}
    lr = obj.eegt_last_run
    assert lr.inverted_after == 0 and "object 'reference'" in lr.message
    med, p95 = size_ratios(positions(obj)[:, :2].astype(np.float64), ref, faces)
    assert med < 1.05 and p95 < 1.2


@pytest.mark.parametrize("case, needle", [
    ("no_reference", "needs a reference: choose a shape key"),
    ("missing_key", "reference shape key 'Nope' not found"),
    ("missing_object", "reference object 'Nope' not found"),
    ("other_topology", "different topology"),
    ("not_planar", "reference mesh is not planar"),
    ("edited_key", "is the shape key being edited"),
])
def test_bad_reference_is_one_line_and_leaves_the_mesh(bpy, ext, case, needle):
    obj = import_obj(bpy, "quad_hole")
    kwargs = {"target": "reference"}
    if case in ("missing_key", "edited_key"):
        obj.shape_key_add(name="Basis")
        obj.shape_key_add(name="Edit")
        obj.active_shape_key_index = 1
        kwargs["reference_key"] = "Nope" if case == "missing_key" else "Edit"
    elif case == "missing_object":
        kwargs["reference_object"] = "Nope"
    elif case in ("other_topology", "not_planar"):
        other = import_obj(bpy, "mixed_quad_tri" if case == "other_topology" else "quad_hole")
        other.name = "Other"
        if case == "not_planar":
            co = positions(other)
            co[:, 2] = 0.5 * co[:, 0] ** 2
            other.data.attributes["position"].data.foreach_set("vector", co.ravel())
        bpy.context.view_layer.objects.active = obj
        other.select_set(False)
        obj.select_set(True)
        kwargs["reference_object"] = "Other"
    before = snapshot(obj, skip=())
    assert bpy.ops.mesh.eegt_untangle_smooth(**kwargs) == {"CANCELLED"}
    assert snapshot(obj, skip=()) == before
    msg = obj.eegt_last_run.message
    assert needle in msg and "\n" not in msg and msg.startswith("quad_hole: not changed: ")


# ---- command line ------------------------------------------------------------------------


def test_cli_slide_and_reference_file(bpy, ext, tmp_path):
    cli = ext.operators.command.entry
    out, rep = tmp_path / "out.obj", tmp_path / "r.json"
    assert cli.execute([str(DATA / "quad_hole.obj"), "-o", str(out), "--report", str(rep),
                        "--boundary", "slide", "--quiet"]) == 0
    report = json.loads(rep.read_text())
    assert report["params"]["boundary"] == "slide"
    (o,) = report["objects"]
    assert o["after"]["n_inverted"] == 0
    src = import_obj(bpy, "quad_hole")
    before = positions(src)
    dst = import_obj(bpy, "out", out)
    assert check_slid(before, positions(dst), loops_of(src)) > 20
    # the boundary-layer mesh with its reference as an OBJ file
    ref, faces = boundary_layer_annulus()
    moved, refp = tmp_path / "moved.obj", tmp_path / "ref.obj"
    write_obj(moved, moved_body(ref), faces)
    write_obj(refp, ref, faces)
    out2, rep2 = tmp_path / "out2.obj", tmp_path / "r2.json"
    assert cli.execute([str(moved), "-o", str(out2), "--report", str(rep2),
                        "--reference", str(refp), "--quiet"]) == 0
    report = json.loads(rep2.read_text())
    assert report["params"]["target"] == "reference"
    assert report["reference"] == f"file '{refp}'"
    (o,) = report["objects"]
    assert o["before"]["n_inverted"] == 43 and o["after"]["n_inverted"] == 0
    rows = [ln.split()[1:3] for ln in open(out2) if ln.startswith("v ")]
    med, p95 = size_ratios(np.array(rows, dtype=np.float64), ref, faces)
    assert med < 1.05 and p95 < 1.2


def nan_reference(tmp_path):
    """quad_hole.obj with its first vertex's x a NaN."""
    lines = (DATA / "quad_hole.obj").read_text().splitlines()
    first = next(i for i, ln in enumerate(lines) if ln.startswith("v "))
    lines[first] = "v nan " + " ".join(lines[first].split()[2:])
    path = tmp_path / "nan.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def uv_blend(bpy, tmp_path):
    """A .blend with a grid that has a UV map."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=4)
    path = tmp_path / "uv.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_homefile(use_empty=True)
    return path


@pytest.mark.parametrize("case", ["other topology", "NaN coordinate", "missing key",
                                  "no reference", "uv with a file", "uv with a key",
                                  "uv with target reference"])
def test_cli_bad_reference_is_exit_2_before_any_work_and_writes_nothing(bpy, ext, tmp_path,
                                                                         capfd, case):
    inp, other = DATA / "quad_hole.obj", DATA / "mixed_quad_tri.obj"
    uv_message = ("eegt: --uv takes each UV face's target shape from its 3D face: "
                  "--reference, --reference-key and --target reference are for vertex "
                  "positions")
    args, expected = {
        "other topology": (["--reference", other],
                           f"eegt: --reference '{other}' (2790 vertices, 2941 faces) does not "
                           "fit object 'quad_hole' (168 vertices, 140 faces): a reference has "
                           "the same vertices and faces, in the same order"),
        "NaN coordinate": (["--reference", nan_reference(tmp_path)],
                           f"eegt: reference '{tmp_path / 'nan.obj'}' has 1 vertex with a NaN "
                           "or infinite coordinate"),
        "missing key": (["--reference-key", "Nope"],
                        "eegt: --reference-key Nope: object 'quad_hole' has no shape key "
                        "'Nope' (its shape keys: none)"),
        "no reference": (["--target", "reference"],
                         "eegt: --target reference needs --reference FILE or --reference-key "
                         "NAME: object 'quad_hole' has no Basis shape key under an active "
                         "one to take by default"),
        "uv with a file": (["--uv", "--reference", inp], uv_message),
        "uv with a key": (["--uv", "--reference-key", "Basis"], uv_message),
        "uv with target reference": (["--uv", "--target", "reference"], uv_message),
    }[case]
    if case.startswith("uv"):
        inp = uv_blend(bpy, tmp_path)
    out, rep = tmp_path / f"out{inp.suffix}", tmp_path / "r.json"
    capfd.readouterr()
    code = ext.operators.command.entry.execute([str(inp), "-o", str(out), "--report", str(rep),
                                      *map(str, args)])
    captured = capfd.readouterr()
    assert code == 2
    assert [ln for ln in captured.err.splitlines() if ln.strip()] == [expected]
    assert "EEGT" not in captured.out  # no object was worked on
    assert not out.exists() and not [n for n in os.listdir(tmp_path) if n.startswith(".")]
    report = json.loads(rep.read_text())
    assert report["exit_code"] == 2 and report["error"] == expected
    assert report["objects"] == [] and report["written"] is False


def test_cli_bad_reference(bpy, ext, tmp_path, capsys):
    cli = ext.operators.command.entry
    inp = str(DATA / "quad_hole.obj")
    # contradictions and unreadable files: usage errors (exit 2), one line on stderr
    for args, needle in (
        (["--target", "regular", "--reference", inp], "need --target reference"),
        (["--reference", str(tmp_path / "none.obj")], "cannot read reference"),
        (["--reference", str(DATA / "quad_hole.png")], "must be an .obj file"),
        (["--reference", inp, "--reference-key", "Basis"], "not both"),
        (["--boundary", "sliding"], "invalid choice"),
    ):
        capsys.readouterr()
        assert cli.execute([inp, *args, "--quiet"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert needle in err[-1], (args, err)


def test_cli_reference_key_of_a_blend_checks_every_chosen_object(bpy, ext, tmp_path, capfd):
    """A .blend whose first object has Basis + an active key and whose second has no keys:
    --target reference is refused for the second (exit 2, nothing written) unless --object
    leaves it out; the first then runs against its Basis key."""
    keyed = import_obj(bpy, "quad_hole")
    keyed.shape_key_add(name="Basis")
    keyed.shape_key_add(name="Edit")
    keyed.active_shape_key_index = 1
    keyed_name, plain_name = keyed.name, import_obj(bpy, "tilted_plane").name
    src = tmp_path / "in.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(src))
    out, rep = tmp_path / "out.blend", tmp_path / "r.json"
    cli = ext.operators.command.entry
    capfd.readouterr()
    assert cli.execute([str(src), "-o", str(out), "--target", "reference", "--quiet"]) == 2
    assert capfd.readouterr().err.strip() == (
        "eegt: --target reference needs --reference FILE or --reference-key NAME: object "
        f"'{plain_name}' has no Basis shape key under an active one to take by default")
    assert not out.exists()
    assert cli.execute([str(src), "-o", str(out), "--target", "reference", "--object",
                        keyed_name, "--report", str(rep), "--quiet"]) == 0
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["object"] == keyed_name and o["after"]["n_inverted"] == 0
    assert "shape key 'Basis'" in " ".join(o["notes"])
    assert cli.execute([str(src), "-o", str(out), "--reference-key", "Edit", "--object",
                        keyed_name, "--quiet"]) == 2
    assert capfd.readouterr().err.strip() == (
        f"eegt: --reference-key Edit: it is the active shape key of object '{keyed_name}', "
        "the one the run changes: choose another")


def test_cli_reference_key_with_a_nan_is_exit_2_and_writes_nothing(bpy, ext, tmp_path, capfd):
    obj = import_obj(bpy, "quad_hole")
    obj.shape_key_add(name="Basis")
    obj.shape_key_add(name="Edit")
    obj.active_shape_key_index = 1
    obj.data.shape_keys.key_blocks["Basis"].data[0].co.x = float("nan")
    src = tmp_path / "in.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(src))
    out = tmp_path / "out.blend"
    capfd.readouterr()
    execute = ext.operators.command.entry.execute
    assert execute([str(src), "-o", str(out), "--reference-key", "Basis", "--quiet"]) == 2
    assert capfd.readouterr().err.strip() == (
        "eegt: object 'quad_hole': reference shape key 'Basis' has 1 vertex with a NaN or "
        "infinite coordinate")
    assert not out.exists()
