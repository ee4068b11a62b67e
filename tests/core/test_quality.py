"""Mean ratio (SPEC section 3): closed forms, inverted/degenerate faces, invariances."""

import math

import numpy as np
import pytest

from core import mesh_stats, quality


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
