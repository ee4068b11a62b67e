"""Mean ratio (docs/method.md 3): closed forms, inverted/degenerate faces, invariances."""

import math
import warnings

import numpy as np
import pytest

from core import mesh_stats, quality, summaries
from core.mesh.faces import as_faceset
from core.metrics.face_quality import folded_area
from core.metrics.mean_ratio import group_quality


def tri_closed_form(p: np.ndarray) -> float:
    a = 0.5 * (
        (p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[2, 0] - p[0, 0]) * (p[1, 1] - p[0, 1])
    )
    l2 = sum(np.sum((p[(k + 1) % 3] - p[k]) ** 2) for k in range(3))
    return max(0.0, 4 * math.sqrt(3) * a / l2)


def quad_corner_formula(p: np.ndarray) -> float:
    qs = []
    for k in range(4):
        e1, e2 = p[(k + 1) % 4] - p[k], p[(k - 1) % 4] - p[k]
        det = e1[0] * e2[1] - e1[1] * e2[0]
        if det <= 0:
            return 0.0
        qs.append(2 * det / (e1 @ e1 + e2 @ e2))
    return float(np.mean(qs))


def test_triangle_quality_equals_4sqrt3_area_over_sum_of_squared_edges():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(300, 2))
    faces = rng.integers(0, 300, size=(400, 3))
    faces = faces[
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    ]
    q = quality(pts, faces)
    expected = [tri_closed_form(pts[f]) for f in faces]
    np.testing.assert_allclose(q, expected, rtol=1e-12, atol=1e-15)
    assert 0.3 < (q == 0).mean() < 0.7  # about half of random triangles are clockwise


def test_quad_quality_equals_corner_formula():
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(400, 2))
    faces = np.array([rng.choice(400, 4, replace=False) for _ in range(500)])
    q = quality(pts, faces)
    np.testing.assert_allclose(q, [quad_corner_formula(pts[f]) for f in faces], rtol=1e-12)
    assert (q > 0).sum() > 10


@pytest.mark.parametrize("n", range(3, 9))
def test_regular_polygon_has_quality_one(n):
    t = 2 * np.pi * np.arange(n) / n
    p = np.column_stack([np.cos(t), np.sin(t)])
    assert quality(p, [list(range(n))])[0] == pytest.approx(1.0, abs=1e-14)
    assert quality(p, [list(range(n))[::-1]])[0] == 0.0  # clockwise = inverted


def test_square_and_unit_quad_values():
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    assert quality(sq, [[0, 1, 2, 3]])[0] == 1.0
    rect = sq * [2.0, 1.0]
    assert quality(rect, [[0, 1, 2, 3]])[0] == pytest.approx(2 * 2 / 5)  # 2 det / (4 + 1)


def test_reflex_corner_degenerate_and_collapsed_faces_are_zero():
    dart = np.array([[0, 0], [2, 0], [0.5, 0.5], [0, 2]], float)  # reflex corner at node 2
    assert quality(dart, [[0, 1, 2, 3]])[0] == 0.0
    line = np.array([[0, 0], [1, 0], [2, 0]], float)
    assert quality(line, [[0, 1, 2]])[0] == 0.0
    point = np.zeros((4, 2))
    assert quality(point, [[0, 1, 2, 3]])[0] == 0.0
    bowtie = np.array([[0, 0], [1, 1], [1, 0], [0, 1]], float)
    assert quality(bowtie, [[0, 1, 2, 3]])[0] == 0.0


@pytest.mark.parametrize("n", [3, 4, 5, 6, 7])
def test_quality_is_scale_rotation_translation_invariant(n):
    rng = np.random.default_rng(n)
    t = 2 * np.pi * np.arange(n) / n
    base = np.column_stack([np.cos(t), np.sin(t)]) + 0.15 * rng.normal(size=(n, 2))
    q0 = quality(base, [list(range(n))])[0]
    assert q0 > 0.5
    a = 1.234
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    moved = 37.5 * base @ rot.T + [1e3, -2e3]
    assert quality(moved, [list(range(n))])[0] == pytest.approx(q0, rel=1e-12)


def test_mixed_mesh_stats_count_inverted_as_zero():
    pts = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [2, 0], [2, 1]], float)
    faces = [[0, 1, 2, 3], [1, 4, 5, 2][::-1], [1, 4, 5]]
    s = mesh_stats(pts, faces)
    assert s.n_inverted == 1
    assert s.q_min == 0.0
    q = quality(pts, faces)
    assert s.q_avg == pytest.approx(q.sum() / 3)
    assert q[0] == 1.0 and q[1] == 0.0 and q[2] > 0.5


EQUILATERAL = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, math.sqrt(3.0) / 2.0]])
SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
HEXAGON = np.column_stack([np.cos(np.arange(6) * np.pi / 3), np.sin(np.arange(6) * np.pi / 3)])
REGULAR = {"equilateral triangle": EQUILATERAL, "square": SQUARE, "hexagon": HEXAGON}


@pytest.mark.parametrize("shape", REGULAR)
def test_mean_ratio_is_the_same_at_every_power_of_two_scale_without_warnings(shape):
    """Regression: the squared edges overflowed from about 1e154 (NaN and a RuntimeWarning)
    and underflowed below about 1e-162 (0.0, read as inverted). Scaled by 2^k the corner
    coordinates are exact, so every k gives the unit-scale value bit for bit."""
    p = REGULAR[shape]
    face = [list(range(len(p)))]
    unit = quality(p, face)[0]
    assert unit == pytest.approx(1.0, abs=2e-16)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = {k: quality(p * 2.0**k, face)[0] for k in range(-1000, 1001)}
        stats = mesh_stats(p * 2.0**1000, face), mesh_stats(p * 2.0**-1000, face)
        summary = [summaries(p * 2.0**k, face, ["mean_ratio"])["mean_ratio"].min
                   for k in (-1000, 1000)]
    assert {k for k, q in got.items() if q != unit} == set()
    assert stats[0] == stats[1] == mesh_stats(p, face)
    assert summary == [unit, unit]



@pytest.mark.parametrize("k", [1023, -1022, -1060, -1074])
def test_unit_square_at_the_ends_of_the_float_range_reads_one(k):
    """Corners 0 and 2^k are exact from the largest double's exponent down to the smallest
    subnormal (2^-1074): the square reads 1, no warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert quality(SQUARE * 2.0**k, [[0, 1, 2, 3]])[0] == 1.0

@pytest.mark.parametrize("scale", [1e300, 1e154, 1e-162, 1e-300])
@pytest.mark.parametrize("shape", REGULAR)
def test_mean_ratio_at_decimal_extreme_scales_is_the_unit_value(shape, scale):
    """At a decimal scale the coordinates round, so the value may move by an ulp; it is
    exactly the value of the same rounded face brought back to unit size by a power of two,
    and no longer NaN (1e154, 1e300) or 0 (1e-162, 1e-300)."""
    p = REGULAR[shape] * scale
    face = [list(range(len(p)))]
    back = np.ldexp(p, -np.frexp(np.abs(p).max())[1])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        q = quality(p, face)[0]
    assert q == quality(back, face)[0]
    assert q == pytest.approx(1.0, abs=1e-15)


def test_scale_safe_mean_ratio_keeps_the_bits_of_ordinary_meshes_and_inverted_faces():
    """Faces of ordinary size are computed as before (group_quality's bits); tiny, huge,
    inverted and collapsed faces in the same call each read their own value."""
    rng = np.random.default_rng(7)
    pts = rng.normal(size=(600, 2))
    faces = np.array([rng.choice(600, 4, replace=False) for _ in range(300)])
    fs = as_faceset(faces, len(pts))
    g = fs.groups[0]
    plain = group_quality(pts[g.nodes, 0], pts[g.nodes, 1])
    assert np.array_equal(quality(pts, faces), plain) and (plain == 0).sum() > 50
    # two valid faces copied at 2^-700 and 2^700 (where their squares under- and overflow)
    # and a collapsed face
    a, b = np.flatnonzero(plain > 0.0)[:2]
    p = np.vstack([pts, pts[faces[a]] * 2.0**-700, pts[faces[b]] * 2.0**700, np.zeros((4, 2))])
    extra = np.arange(600, 612).reshape(3, 4)
    q = quality(p, np.vstack([faces, extra]))
    assert np.array_equal(q[:300], plain)
    assert q[300] == plain[a] > 0.1 and q[301] == plain[b] > 0.1 and q[302] == 0.0


def test_mean_ratio_against_targets_is_scale_safe():
    """The target path (per-corner constants) is redone at unit scale the same way."""
    t = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 1.0], [0.0, 1.0]])  # a 4 x 1 target
    face = [[0, 1, 2, 3]]
    unit = quality(t, face, targets=t)[0]
    assert unit == pytest.approx(1.0, abs=1e-15)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert [quality(t * 2.0**k, face, targets=t)[0] for k in (-1000, -520, 520, 1000)] \
            == [unit] * 4


@pytest.mark.parametrize("n", [3, 4, 5, 9])
def test_mean_ratio_in_pieces_is_the_whole_group_bit_for_bit(monkeypatch, n):
    import core.metrics.mean_ratio as mr

    rng = np.random.default_rng(n)
    X, Y = rng.random((n, 1001)), rng.random((n, 1001))  # some faces inverted, some not
    targets = (rng.random((n, 1001)) - 0.5, 1.0 + rng.random((n, 1001)))
    whole = [mr._mean_ratio(X, Y, c, True) for c in (None, targets)]
    monkeypatch.setattr(mr, "FACE_PIECE", 64)  # 16 pieces of 62-63 faces
    pieces = [mr._mean_ratio(X, Y, c, True) for c in (None, targets)]
    for (qa, sa), (qb, sb) in zip(whole, pieces, strict=True):
        assert np.array_equal(qa, qb) and np.array_equal(sa, sb)
    assert 0.0 < whole[0][0].max() <= 1.0 and (whole[0][0] == 0.0).any()


def test_folded_area_is_three_areas_of_an_inverted_triangle_and_zero_for_valid_faces():
    """A clockwise triangle of area 2 has folded area 6 (each corner's det is -4); a
    counterclockwise one and a convex quad have none; a bowtie quad (signed area 0) is
    folded at its two inverted corners; a dart (one reflex corner, det -1) by half of it."""
    pts = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0], [2.0, 2.0],  # 0-3
                    [0.5, 0.5]])  # 4: inside the square
    faces = [[0, 2, 1], [0, 1, 2], [0, 1, 3, 2], [0, 1, 2, 3], [0, 1, 3, 4]]
    got = folded_area(pts, faces)
    # bowtie 0-1-2-3: corners 1 and 2 turn clockwise, det -4 each; reflex corner 4 of
    # 0-1-3-4: edges on to 0 (-0.5, -0.5) and back to 3 (1.5, 1.5): det 0, not folded
    assert got.tolist() == [6.0, 0.0, 0.0, 4.0, 0.0]
    dart = np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.5], [0.0, 2.0]])
    # reflex corner 2: edges on to 3 (-1, 1.5) and back to 1 (1, -0.5): det 0.5 - 1.5 = -1
    assert folded_area(dart, [[0, 1, 2, 3]]).tolist() == [0.5]
