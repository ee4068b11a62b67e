"""Target 'reference': each face pulled towards its own shape in a mesh of the same
topology (core.metrics.reference_shapes), so a graded or anisotropic mesh keeps its grading."""

import numpy as np
import pytest
from meshdata import load, load2d

from bench.meshgen import boundary_layer_annulus, moved_body
from core import EEGTParams, mesh_stats, quality, untangle_and_smooth, untangle_and_smooth_3d
from core.mesh.faces import as_faceset
from core.metrics.measures import face_values
from core.metrics.reference_shapes import reference_targets, reference_to_2d

REFERENCE = EEGTParams(target="reference")


def areas(p, faces) -> np.ndarray:
    fs = as_faceset(faces, len(p))
    out = np.empty(fs.n_faces)
    for g in fs.groups:
        x, y = p[g.nodes, 0], p[g.nodes, 1]
        out[g.ids] = 0.5 * np.sum(x * np.roll(y, -1, 0) - np.roll(x, -1, 0) * y, axis=0)
    return out


def against(p, r, faces) -> dict:
    """Median and 95th percentile of max(x / x_ref, x_ref / x) for the size (sqrt of the
    area) and the aspect ratio of every face, and the size grading (largest / smallest)."""
    s = np.sqrt(np.abs(areas(p, faces)) / np.abs(areas(r, faces)))
    s = np.maximum(s, 1 / s)
    a = face_values(p, faces, "aspect_ratio") / face_values(r, faces, "aspect_ratio")
    a = np.maximum(a, 1 / a)
    size = np.sqrt(np.abs(areas(p, faces)))
    return {"size_med": np.median(s), "size_p95": np.percentile(s, 95),
            "aspect_med": np.median(a), "aspect_p95": np.percentile(a, 95),
            "grading": size.max() / size.min()}


def test_boundary_layer_keeps_its_grading_and_anisotropy_only_with_reference_targets():
    """An O-grid with a boundary layer (cell sizes 1:257, aspect up to 105) whose body moved:
    43 folded cells. Both untangle it; the regular targets make it isotropic, the
    reference keeps it (bench.engineers: size ratio p95 1.06 vs 6.7, grading 266 vs 21)."""
    ref, faces = boundary_layer_annulus()
    pts = moved_body(ref)
    g_ref = against(ref, ref, faces)["grading"]
    assert g_ref > 200 and mesh_stats(pts, faces).n_inverted == 43
    regular = untangle_and_smooth(pts, faces)
    kept = untangle_and_smooth(pts, faces, params=REFERENCE, reference_points=ref)
    assert regular.after.n_inverted == kept.after.n_inverted == 0
    a, b = against(kept.points, ref, faces), against(regular.points, ref, faces)
    assert a["size_med"] < 1.05 and a["size_p95"] < 1.2 and a["aspect_p95"] < 1.3
    assert 0.8 < a["grading"] / g_ref < 1.25
    assert b["size_p95"] > 3 and b["aspect_p95"] > 10 and b["grading"] < 0.2 * g_ref
    assert kept.after.q_min > 0.9  # against the reference shapes
    assert mesh_stats(kept.points, faces, targets=reference_targets(ref, faces, len(ref))) \
        == kept.after


def test_naca_deform_with_its_undeformed_mesh_as_reference():
    p, f = load2d("naca_deform")
    r, _ = load2d("naca_undeformed")
    regular = untangle_and_smooth(p, f)
    res = untangle_and_smooth(p, f, params=REFERENCE, reference_points=r)
    assert res.status == regular.status == "untangled"
    assert res.after.n_inverted == 0 and res.n_target_fallback == 0
    a, b = against(res.points, r, f), against(regular.points, r, f)
    # measured (bench.engineers): size median 1.07 vs 1.08, aspect p95 3.3 vs 3.5; the
    # reference is nearly isotropic, so the two are close: each within a clear bound
    for m in (a, b):
        assert m["size_med"] < 1.15 and m["aspect_med"] < 1.4 and m["aspect_p95"] < 4.5
    assert res.after.q_min > 0.35  # against the reference (measured 0.49)


def test_a_reference_in_another_plane_gives_the_2d_result():
    """The reference's own plane, position, rotation and scale do not matter."""
    v, f = load("quad_hole")
    p = v[:, :2].copy()
    r2, _ = load2d("quad_hole")
    r2 = r2 + 0.05 * np.sin(3 * r2[:, ::-1])  # another valid shape of the same mesh
    flat = untangle_and_smooth(p, f, params=REFERENCE, reference_points=r2)
    rot = np.array([[0.6, 0.0, 0.8], [0.0, 1.0, 0.0], [-0.8, 0.0, 0.6]])
    r3 = 7.0 * np.column_stack([r2, np.zeros(len(r2))]) @ rot.T + [1.0, -2.0, 3.0]
    back = reference_to_2d(r3, f, len(r3))
    assert np.allclose(quality(back, f), quality(r2, f), atol=1e-12)
    tilted = untangle_and_smooth_3d(v, f, params=REFERENCE, reference_points=r3)
    assert tilted.status == flat.status == "untangled"
    # the same targets up to round-off: runs that differ in the last bits, same outcome
    assert tilted.after.q_avg == pytest.approx(flat.after.q_avg, abs=1e-3)


def test_inverted_reference_faces_fall_back_to_the_regular_polygon():
    p, f = load2d("quad_hole")
    res = untangle_and_smooth(p, f, params=REFERENCE, reference_points=p)  # tangled itself
    assert res.n_target_fallback == mesh_stats(p, f).n_inverted == 23
    assert "unusable target shape" in res.message and res.after.n_inverted == 0


@pytest.mark.parametrize("make, msg", [
    (lambda r: None, "needs a reference mesh"),
    (lambda r: r[:-1], "reference mesh has 167 vertices, the mesh has 168"),
    (lambda r: r[:, :1], r"must be an \(N, 2\) array"),
    (lambda r: np.where(np.arange(len(r))[:, None] == 5, np.nan, r), "1 vertices with NaN"),
    (lambda r: r * [1.0, -1.0], "reference mesh is clockwise"),
    (lambda r: r * [1.0, 0.0], "zero total area"),
    (lambda r: [["a", "b"]] * len(r), "array of numbers"),
])
def test_bad_reference_is_a_one_line_error(make, msg):
    p, f = load2d("quad_hole")
    with pytest.raises(ValueError, match=msg) as err:
        untangle_and_smooth(p, f, params=REFERENCE, reference_points=make(p.copy()))
    assert "\n" not in str(err.value)


def test_reference_needs_its_target_and_excludes_targets():
    p, f = load2d("quad_hole")
    with pytest.raises(ValueError, match="target is 'regular'"):
        untangle_and_smooth(p, f, reference_points=p)
    with pytest.raises(ValueError, match="not both"):
        untangle_and_smooth(p, f, params=REFERENCE, reference_points=p,
                            targets=np.zeros((f.n_corners, 2)))


def test_non_planar_3d_reference_is_refused():
    v, f = load("quad_hole")
    bent = v.copy()
    bent[:, 2] = 0.3 * bent[:, 0] ** 2
    with pytest.raises(ValueError, match="reference mesh is not planar"):
        untangle_and_smooth_3d(v, f, params=REFERENCE, reference_points=bent)


def test_reference_near_the_float_limit_is_accepted_with_the_same_targets():
    """Regression: a reference of about 5e307 was refused as 'zero total area' after an
    overflow warning (its mean overflowed). The orientation test now works at unit scale
    (powers of two), so 2^k multiples give the same run bit for bit and 5e307 (rounded
    coordinates) the same outcome up to round-off; in 3D as well."""
    import warnings

    v, f = load("quad_hole")
    p = v[:, :2].copy()
    r = p + 0.05 * np.sin(3 * p[:, ::-1])
    base = untangle_and_smooth(p, f, params=REFERENCE, reference_points=r)
    s = 5e307 / np.abs(r).max()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for k in (-1000, 1019):
            assert np.array_equal(reference_targets(r * 2.0**k, f, len(r)),
                                  reference_targets(r, f, len(r)) * 2.0**k)
        exact = untangle_and_smooth(p, f, params=REFERENCE, reference_points=r * 2.0**1019)
        near = untangle_and_smooth(p, f, params=REFERENCE, reference_points=r * s)
        r3 = np.column_stack([r, np.zeros(len(r))]) @ np.array(
            [[0.6, 0.0, 0.8], [0.0, 1.0, 0.0], [-0.8, 0.0, 0.6]]).T
        flat = reference_to_2d(r3 * s, f, len(r))
    assert np.abs(r * s).max() == pytest.approx(5e307)
    assert np.array_equal(exact.points, base.points) and exact.after == base.after
    assert near.status == base.status == "untangled" and near.after.n_inverted == 0
    assert near.after.q_avg == pytest.approx(base.after.q_avg, abs=1e-4)  # round-off only
    assert np.allclose(quality(flat, f), quality(r, f), rtol=0, atol=1e-12)
