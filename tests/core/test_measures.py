"""Quality measures (core.metrics.measures): hand-computed single elements, degenerate input, a
per-element reference on real meshes, mesh summaries and threshold counts."""

import math

import numpy as np
import pytest
from meshdata import load2d

from core import MEASURE_NAMES, quality, summaries, summarize
from core.metrics.mean_ratio import group_quality
from core.metrics.measures import (
    ASPECT_MAX,
    MEASURES,
    face_values,
    get_measure,
    goodness,
    regular_width,
)

S3 = math.sqrt(3.0)
ATAN34 = math.degrees(math.atan2(3.0, 4.0))  # 36.87 deg, twice atan(1/3)

# element -> (points, {measure: hand-computed value}); angles in degrees
ELEMENTS = {
    "equilateral": ([[0, 0], [1, 0], [0.5, S3 / 2]], dict(
        mean_ratio=1.0, min_angle=60.0, max_angle=60.0, aspect_ratio=1.0,
        scaled_jacobian=1.0, skewness=0.0)),
    # legs 1: 4 sqrt3 (1/2) / (1 + 1 + 2); AR = (sqrt3 / 2) l_max^2 / (2 A); sin45 / sin60
    "right_isosceles": ([[0, 0], [1, 0], [0, 1]], dict(
        mean_ratio=S3 / 2, min_angle=45.0, max_angle=90.0, aspect_ratio=S3,
        scaled_jacobian=math.sqrt(2.0 / 3.0), skewness=0.25)),
    # sides 1, sqrt3, 2, area sqrt3/2: q = 4 sqrt3 (sqrt3/2) / 8; AR = (sqrt3/2) 4 / sqrt3;
    # skew = max((90 - 60) / 120, (60 - 30) / 60)
    "triangle_30_60_90": ([[0, 0], [S3, 0], [0, 1]], dict(
        mean_ratio=0.75, min_angle=30.0, max_angle=90.0, aspect_ratio=2.0,
        scaled_jacobian=1.0 / S3, skewness=0.5)),
    "square": ([[0, 0], [1, 0], [1, 1], [0, 1]], dict(
        mean_ratio=1.0, min_angle=90.0, max_angle=90.0, aspect_ratio=1.0,
        scaled_jacobian=1.0, skewness=0.0)),
    # q = 2 r / (1 + r^2); longest edge 3 over width 1
    "rectangle_1x3": ([[0, 0], [3, 0], [3, 1], [0, 1]], dict(
        mean_ratio=0.6, min_angle=90.0, max_angle=90.0, aspect_ratio=3.0,
        scaled_jacobian=1.0, skewness=0.0)),
    # unit edges, height sin60: every corner q_k = 2 sin60 / 2; skew = (120 - 90) / 90
    "rhombus_60": ([[0, 0], [1, 0], [1.5, S3 / 2], [0.5, S3 / 2]], dict(
        mean_ratio=S3 / 2, min_angle=60.0, max_angle=120.0, aspect_ratio=2.0 / S3,
        scaled_jacobian=S3 / 2, skewness=1.0 / 3.0)),
    # reflex corner of 270 - atan(3/4) deg at node 2 (sine -0.8); the others 90, 18.43, 18.43;
    # widths 2, 2, 3/sqrt(2.5), 3/sqrt(2.5): AR = 2 sqrt(2.5) / 3
    "concave_quad": ([[0, 0], [2, 0], [0.5, 0.5], [0, 2]], dict(
        mean_ratio=0.0, min_angle=-(90.0 + ATAN34), max_angle=270.0 - ATAN34,
        aspect_ratio=2.0 * math.sqrt(2.5) / 3.0, scaled_jacobian=-0.8,
        skewness=(90.0 + 90.0 + ATAN34) / 90.0)),
    # the equilateral triangle clockwise: corners of -60 (or 300) deg
    "inverted_triangle": ([[0, 0], [0.5, S3 / 2], [1, 0]], dict(
        mean_ratio=0.0, min_angle=-60.0, max_angle=300.0, aspect_ratio=1.0,
        scaled_jacobian=-1.0, skewness=2.0)),
    # three nodes on a line: angles 0, 180, 0; zero width
    "collinear_triangle": ([[0, 0], [1, 0], [2, 0]], dict(
        mean_ratio=0.0, min_angle=0.0, max_angle=180.0, aspect_ratio=ASPECT_MAX,
        scaled_jacobian=0.0, skewness=1.0)),
    # two coincident nodes: the corners beside the zero-length edge count as collapsed
    "zero_edge_triangle": ([[0, 0], [0, 0], [1, 0.5]], dict(
        mean_ratio=0.0, min_angle=0.0, max_angle=180.0, aspect_ratio=ASPECT_MAX,
        scaled_jacobian=0.0, skewness=1.0)),
    "point_quad": ([[2, 3]] * 4, dict(
        mean_ratio=0.0, min_angle=0.0, max_angle=180.0, aspect_ratio=ASPECT_MAX,
        scaled_jacobian=0.0, skewness=1.0)),
}


def regular(n: int, scale: float = 1.0) -> np.ndarray:
    t = 2 * np.pi * np.arange(n) / n
    return scale * np.column_stack([np.cos(t), np.sin(t)])


@pytest.mark.parametrize("measure", MEASURE_NAMES)
@pytest.mark.parametrize("element", ELEMENTS)
def test_single_element_equals_hand_computed_value(element, measure):
    pts, expected = ELEMENTS[element]
    p = np.asarray(pts, dtype=float)
    got = quality(p, [list(range(len(p)))], measure=measure)
    assert got.shape == (1,) and np.isfinite(got).all()
    assert got[0] == pytest.approx(expected[measure], rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("n, angle", [(5, 108.0), (6, 120.0), (8, 135.0)])
def test_regular_pentagon_hexagon_octagon_are_ideal(n, angle):
    p = regular(n, 7.0) + np.array([3.0, -2.0])
    face = [list(range(n))]
    assert quality(p, face, measure="min_angle")[0] == pytest.approx(angle, abs=1e-12)
    assert quality(p, face, measure="max_angle")[0] == pytest.approx(angle, abs=1e-12)
    for name in ("mean_ratio", "aspect_ratio", "scaled_jacobian"):
        assert quality(p, face, measure=name)[0] == pytest.approx(1.0, abs=1e-12)
    assert quality(p, face, measure="skewness")[0] == pytest.approx(0.0, abs=1e-12)
    # clockwise = inverted: every corner turns the wrong way
    rev = [face[0][::-1]]
    assert quality(p, rev, measure="min_angle")[0] == pytest.approx(-angle, abs=1e-12)
    assert quality(p, rev, measure="max_angle")[0] == pytest.approx(360.0 - angle, abs=1e-12)
    assert quality(p, rev, measure="scaled_jacobian")[0] == pytest.approx(-1.0, abs=1e-12)
    assert quality(p, rev, measure="skewness")[0] == pytest.approx(2.0, abs=1e-12)


def test_hexagon_squashed_to_half_height_has_aspect_ratio_two():
    # unit-edge regular hexagon (width sqrt3 across its edges) squashed to half height: the
    # longest edges are the horizontal ones (1), the narrowest width sqrt3 / 2 across them
    squashed = regular(6) * [1.0, 0.5]
    got = quality(squashed, [list(range(6))], measure="aspect_ratio")[0]
    assert got == pytest.approx((1.0 / (S3 / 2)) / (1.0 / S3), rel=1e-12)
    assert got == pytest.approx(2.0, rel=1e-12)


def test_regular_widths_are_apothem_plus_apothem_or_circumradius():
    for n in range(3, 12):
        apothem, radius = 0.5 / math.tan(math.pi / n), 0.5 / math.sin(math.pi / n)
        expected = 2 * apothem if n % 2 == 0 else apothem + radius
        assert regular_width(n) == pytest.approx(expected, rel=1e-14)
    assert regular_width(3) == pytest.approx(S3 / 2, rel=1e-15)  # the altitude
    assert regular_width(4) == 1.0


@pytest.mark.parametrize("measure", MEASURE_NAMES)
def test_measures_are_invariant_to_rotation_translation_scale_and_start_corner(measure):
    rng = np.random.default_rng(7)
    for n in (3, 4, 5, 7):
        base = regular(n) + rng.normal(scale=0.25, size=(n, 2))
        face = [list(range(n))]
        v0 = quality(base, face, measure=measure)[0]
        c, s = math.cos(0.7), math.sin(0.7)
        rot = np.array([[c, -s], [s, c]])
        for scale in (1e-150, 3.0, 1e150):
            moved = scale * base @ rot.T + [5.0 * scale, -2.0 * scale]
            assert quality(moved, face, measure=measure)[0] == pytest.approx(v0, rel=1e-9,
                                                                               abs=1e-9)
        shifted = [face[0][2:] + face[0][:2]]
        assert quality(base, shifted, measure=measure)[0] == pytest.approx(v0, rel=1e-12,
                                                                            abs=1e-12)


def test_default_measure_is_the_mean_ratio_bit_for_bit():
    p, f = load2d("mixed_quad_tri")
    q = quality(p, f)
    assert np.array_equal(q, quality(p, f, measure="mean_ratio"))
    assert np.array_equal(q, face_values(p, f, "mean_ratio"))
    ref = np.empty(f.n_faces)
    for g in f.groups:
        ref[g.ids] = group_quality(p[g.nodes, 0], p[g.nodes, 1])
    assert np.array_equal(q, ref)


@pytest.mark.parametrize("bad", ["minimum_angle", "", "MEAN_RATIO", None, 3])
def test_unknown_measure_is_refused_with_the_valid_names(bad):
    p = np.array(ELEMENTS["square"][0], float)
    with pytest.raises(ValueError, match="unknown measure") as info:
        quality(p, [[0, 1, 2, 3]], measure=bad)
    for name in MEASURE_NAMES:
        assert name in str(info.value)
    with pytest.raises(ValueError, match="unknown measure"):
        summaries(p, [[0, 1, 2, 3]], [bad])


def test_bad_points_and_faces_are_refused_for_every_measure():
    with pytest.raises(ValueError, match="NaN or infinite"):
        quality([[0, 0], [1, np.nan], [0, 1]], [[0, 1, 2]], measure="min_angle")
    with pytest.raises(ValueError, match="references node 5"):
        quality([[0, 0], [1, 0], [0, 1]], [[0, 1, 5]], measure="skewness")


# -- an independent per-element reference (Python loops, math module) --------------------

def reference(p: np.ndarray, measure: str) -> float:
    """One polygon's measure from the definitions in docs/measures.md, corner by corner."""
    n = len(p)
    te = 180.0 * (n - 2) / n
    angles, sines = [], []
    for k in range(n):
        e1, e2 = p[(k + 1) % n] - p[k], p[k - 1] - p[k]
        l1, l2 = math.hypot(*e1), math.hypot(*e2)
        if l1 == 0 or l2 == 0:
            angles.append(None)
            sines.append(0.0)
            continue
        cr = (e1[0] * e2[1] - e1[1] * e2[0]) / (l1 * l2)
        dt = (e1[0] * e2[0] + e1[1] * e2[1]) / (l1 * l2)
        angles.append(math.degrees(math.atan2(cr, dt)))
        sines.append(cr)
    mins = [0.0 if a is None else a for a in angles]
    maxs = [180.0 if a is None else (a + 360.0 if a < 0 else a) for a in angles]
    if measure == "min_angle":
        return min(mins)
    if measure == "max_angle":
        return max(maxs)
    if measure == "scaled_jacobian":
        return min(sines) / math.sin(math.radians(te))
    if measure == "skewness":
        return max((max(maxs) - te) / (180.0 - te), (te - min(mins)) / te, 0.0)
    assert measure == "aspect_ratio"
    lengths = [math.hypot(*(p[(k + 1) % n] - p[k])) for k in range(n)]
    widths = []
    for k in range(n):
        if lengths[k] == 0:
            continue
        ux, uy = (p[(k + 1) % n] - p[k]) / lengths[k]
        d = [ux * (q[1] - p[k][1]) - uy * (q[0] - p[k][0]) for q in p]
        widths.append(max(d) - min(d))
    unit = regular(n)
    unit = unit / math.hypot(*(unit[1] - unit[0]))
    w_reg = max(float(np.dot(q - unit[0], [-(unit[1] - unit[0])[1], (unit[1] - unit[0])[0]]))
                for q in unit)
    if not widths or min(widths) <= 0:
        return ASPECT_MAX
    return min(max(lengths) / min(widths) * w_reg, ASPECT_MAX)


@pytest.mark.parametrize("mesh", ["polygon_voronoi", "mixed_quad_tri", "quad_hole"])
@pytest.mark.parametrize("measure", ["min_angle", "max_angle", "aspect_ratio",
                                     "scaled_jacobian", "skewness"])
def test_vectorized_measures_equal_a_per_element_reference(mesh, measure):
    p, f = load2d(mesh)
    got = quality(p, f, measure=measure)
    faces = f.to_lists()
    step = max(1, len(faces) // 300)  # a few hundred faces of every arity present
    for i in range(0, len(faces), step):
        assert got[i] == pytest.approx(reference(p[faces[i]], measure), rel=1e-9, abs=1e-9)
    assert np.isfinite(got).all()


def test_random_tangled_polygons_give_finite_values():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(60, 2))
    pts[10:20] = pts[0]  # coincident nodes: zero-length edges and collapsed faces
    faces = [list(rng.choice(60, n, replace=False)) for n in (3, 4, 5, 6) for _ in range(200)]
    for name in MEASURE_NAMES:
        v = quality(pts, faces, measure=name)
        assert np.isfinite(v).all(), name
    s = summaries(pts, faces)
    assert all(np.isfinite([x.min, x.mean, x.max]).all() for x in s.values())


# -- mesh summaries and threshold counts ---------------------------------------------------

def loose_mesh():
    """Six separate elements: the right isosceles and 30-60-90 triangles, the inverted
    equilateral triangle, the square, the 1x3 rectangle and a 40-degree rhombus."""
    c, s = math.cos(math.radians(40)), math.sin(math.radians(40))
    shapes = [ELEMENTS["right_isosceles"][0], ELEMENTS["triangle_30_60_90"][0],
              ELEMENTS["inverted_triangle"][0], ELEMENTS["square"][0],
              ELEMENTS["rectangle_1x3"][0], [[0, 0], [1, 0], [1 + c, s], [c, s]]]
    pts, faces = [], []
    for i, shape in enumerate(shapes):
        faces.append(list(range(len(pts), len(pts) + len(shape))))
        pts.extend((np.asarray(shape, float) + np.array([10.0 * i, 0.0])).tolist())
    return np.array(pts), faces


SIN40 = math.sin(math.radians(40))
# measure -> (per-face values, number beyond the threshold); thresholds: triangles 20/120
# deg, quads 45/135 deg, aspect 5, scaled Jacobian 0.2, skewness 0.85, mean ratio 0.5
LOOSE_EXPECTED = {
    "min_angle": ([45, 30, -60, 90, 90, 40], 2),  # -60 (tri < 20), 40 (quad < 45)
    "max_angle": ([90, 90, 300, 90, 90, 140], 2),  # 300 (tri > 120), 140 (quad > 135)
    "aspect_ratio": ([S3, 2, 1, 1, 3, 1 / SIN40], 0),  # rhombus: edge 1 over height sin40
    "scaled_jacobian": ([math.sqrt(2 / 3), 1 / S3, -1, 1, 1, SIN40], 1),
    "skewness": ([0.25, 0.5, 2, 0, 0, 50 / 90], 1),  # rhombus: (140 - 90) / 90
    "mean_ratio": ([S3 / 2, 0.75, 0, 1, 0.6, SIN40], 1),  # rhombus: 2 sin40 / 2 per corner
}


@pytest.mark.parametrize("measure", MEASURE_NAMES)
def test_mesh_summary_min_mean_max_and_count_beyond_threshold(measure):
    p, faces = loose_mesh()
    values, n_beyond = LOOSE_EXPECTED[measure]
    got = quality(p, faces, measure=measure)
    np.testing.assert_allclose(got, values, rtol=1e-12, atol=1e-12)
    s = summaries(p, faces)[measure]
    assert s.n_faces == 6
    assert (s.min, s.mean, s.max) == pytest.approx((min(values), np.mean(values), max(values)),
                                                   rel=1e-12, abs=1e-12)
    assert s.n_beyond == n_beyond
    m = get_measure(measure)
    assert s.thresholds == {3: m.threshold(3), 4: m.threshold(4)}
    d = s.as_dict()
    assert d["n_beyond"] == n_beyond and d["beyond"] == ("below" if m.higher_is_better
                                                         else "above")
    assert set(d["thresholds"]) == {"3", "4"}


def test_thresholds_per_arity():
    assert [MEASURES["min_angle"].threshold(n) for n in (3, 4, 5, 6)] == [20, 45, 54, 60]
    assert [MEASURES["max_angle"].threshold(n) for n in (3, 4, 5, 6)] == [120, 135, 144, 150]
    for name, thr in (("aspect_ratio", 5.0), ("scaled_jacobian", 0.2), ("skewness", 0.85),
                      ("mean_ratio", 0.5)):
        assert {MEASURES[name].threshold(n) for n in (3, 4, 7)} == {thr}


def test_summary_line_names_the_thresholds_per_arity():
    p, faces = loose_mesh()
    line = summaries(p, faces, ["min_angle"])["min_angle"].line()
    assert line == ("Minimum Angle (deg): min -60, mean 39.17, max 90; 2 of 6 faces below "
                    "20 (triangles), 45 (quads)")


def test_summarize_checks_its_arrays():
    with pytest.raises(ValueError, match="same length"):
        summarize("min_angle", np.zeros(3), np.full(2, 3))
    with pytest.raises(ValueError, match="no faces"):
        summarize("min_angle", np.zeros(0), np.zeros(0, int))


def test_goodness_maps_ideal_threshold_worst_to_1_half_0():
    n = np.array([3, 3, 3, 4, 4, 4])
    ang = np.array([60.0, 20.0, 0.0, 90.0, 45.0, -10.0])
    np.testing.assert_array_equal(goodness("min_angle", ang, n), [1, 0.5, 0, 1, 0.5, 0])
    mx = np.array([60.0, 120.0, 180.0, 90.0, 135.0, 270.0])
    np.testing.assert_array_equal(goodness("max_angle", mx, n), [1, 0.5, 0, 1, 0.5, 0])
    np.testing.assert_array_equal(goodness("aspect_ratio", [1.0, 3.0, 5.0, 15.0, 25.0, 1e9],
                                           4), [1, 0.75, 0.5, 0.25, 0, 0])
    np.testing.assert_array_equal(goodness("skewness", [0.0, 0.85, 1.0, 2.0], 3),
                                  [1, 0.5, 0, 0])
    np.testing.assert_array_equal(goodness("scaled_jacobian", [1.0, 0.2, 0.1, -1.0], 4),
                                  [1, 0.5, 0.25, 0])


def test_goodness_of_the_mean_ratio_is_the_quality_itself_bit_for_bit():
    p, f = load2d("quad_hole")
    q = quality(p, f)
    assert np.array_equal(goodness("mean_ratio", q, f.counts), q)


# -- portable arithmetic -------------------------------------------------------------------

def test_fpmath_atan2_matches_numpy_within_a_few_ulp_in_every_quadrant():
    from core import fpmath

    rng = np.random.default_rng(11)
    y = rng.normal(size=40000) * np.exp(rng.uniform(-300, 300, 40000))
    x = rng.normal(size=40000) * np.exp(rng.uniform(-300, 300, 40000))
    y[:8], x[:8] = [0, 1, 0, -1, 1, -1, 1, -1], [1, 0, -1, 0, 1, 1, -1, -1]
    ref = np.arctan2(y, x)
    got = fpmath.atan2(y, x)
    assert (np.abs(got - ref) <= 4 * np.spacing(np.abs(ref) + 1e-300)).all()
    assert fpmath.atan2(-0.0, -1.0) == np.pi and fpmath.atan2(0.0, 0.0) == 0.0
    assert fpmath.atan2(-1.0, 0.0) == -np.pi / 2


def test_measures_are_the_same_bits_without_avx512_and_on_baseline_simd():
    """The measures use only correctly rounded operations: a run with NumPy's SIMD dispatch
    restricted gives the same bits (as the untangler's own reproducibility test)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    try:
        from numpy._core import _multiarray_umath as mu  # NumPy 2
    except ImportError:
        from numpy.core import _multiarray_umath as mu  # NumPy 1.26
    have = [f for f in mu.__cpu_dispatch__ if mu.__cpu_features__.get(f)]
    if not have:
        pytest.skip("this NumPy dispatches no SIMD extension on this CPU: nothing to restrict")
    root = Path(__file__).resolve().parents[2]
    child = (
        "import hashlib, sys\nsys.path.insert(0, sys.argv[1])\n"
        "from core import MEASURE_NAMES, quality\nfrom core.mesh.obj_io import read_obj\n"
        "h = hashlib.sha256()\n"
        "for name in ('polygon_voronoi', 'mixed_quad_tri', 'tri_two_holes'):\n"
        "    p, f = read_obj(f'{sys.argv[1]}/tests/data/{name}.obj')\n"
        "    for m in MEASURE_NAMES:\n"
        "        h.update(quality(p[:, :2], f, measure=m).tobytes())\n"
        "print(h.hexdigest())\n")

    def digest(disable: str | None) -> str:
        env = {k: v for k, v in os.environ.items() if k != "NPY_DISABLE_CPU_FEATURES"}
        if disable:
            env["NPY_DISABLE_CPU_FEATURES"] = disable
        done = subprocess.run([sys.executable, "-c", child, str(root)], env=env,
                              capture_output=True, text=True, timeout=300, check=False)
        assert done.returncode == 0, done.stderr[-2000:]
        return done.stdout.split()[-1]

    reference = digest(None)
    assert len(reference) == 64
    assert digest(" ".join(have)) == reference
