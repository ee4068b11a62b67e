"""The paper's Section 2 theory, checked on our transform."""

import math

import numpy as np
import pytest

from core.eegt.transform import _stretch, stretch_radius, transform_polygon
from core.metrics.mean_ratio import group_quality


def polygon_quality(p: np.ndarray) -> float:
    return float(group_quality(p[:, 0:1], p[:, 1:2])[0])


def stretch_matrix(n: int, lam: float) -> np.ndarray:
    """A of eq. (5)-(6): a_0 = 1, a_m = lam i, a_{n-m} = -lam i for m = 1..R."""
    a = np.zeros(n, dtype=complex)
    a[0] = 1
    for m in range(1, stretch_radius(n) + 1):
        a[m] += 1j * lam
        a[n - m] += -1j * lam
    return np.array([[a[(k - j) % n] for j in range(n)] for k in range(n)])


@pytest.mark.parametrize("n", range(3, 9))
def test_centroid_is_preserved_theorem1(n):
    rng = np.random.default_rng(n)
    p = rng.normal(size=(n, 2))
    for lam in (0.05, 0.3, 1.0):
        out = transform_polygon(p, lam)
        np.testing.assert_allclose(out.mean(axis=0), p.mean(axis=0), atol=1e-14)


@pytest.mark.parametrize("n", range(3, 9))
def test_stretch_equals_circulant_matrix_eq5(n):
    rng = np.random.default_rng(10 + n)
    p = rng.normal(size=(n, 2))
    lam = 0.37
    NX, NY = _stretch(p[:, 0:1], p[:, 1:2])
    ours = (p[:, 0] + lam * NX[:, 0]) + 1j * (p[:, 1] + lam * NY[:, 0])
    np.testing.assert_allclose(stretch_matrix(n, lam) @ (p[:, 0] + 1j * p[:, 1]), ours, atol=1e-13)


@pytest.mark.parametrize("n", range(3, 9))
def test_eigenvalues_match_eq10(n):
    lam = 0.23
    A = stretch_matrix(n, lam)
    R = stretch_radius(n)
    for j in range(n):
        v = np.exp(2j * np.pi * j * np.arange(n) / n)
        mu = 1 + 2 * lam * sum(math.sin(2 * math.pi * j * m / n) for m in range(1, R + 1))
        np.testing.assert_allclose(A @ v, mu * v, atol=1e-13)
    assert np.allclose(
        np.sort(np.linalg.eigvalsh(A)),
        np.sort(
            [
                1 + 2 * lam * sum(math.sin(2 * math.pi * j * m / n) for m in range(1, R + 1))
                for j in range(n)
            ]
        ),
    )


def _shapes(n: int, rng) -> dict[str, np.ndarray]:
    t = 2 * np.pi * np.arange(n) / n
    regular = np.column_stack([np.cos(t), np.sin(t)])
    return {
        "random": rng.normal(size=(n, 2)),
        "inverted": regular[::-1] + 0.05 * rng.normal(size=(n, 2)),  # clockwise
        "self_intersecting": regular[rng.permutation(n)] + 0.05 * rng.normal(size=(n, 2)),
    }


@pytest.mark.parametrize("n", range(3, 9))
def test_iterated_transform_makes_any_polygon_regular_ccw_theorem3(n):
    rng = np.random.default_rng(100 + n)
    for kind, p in _shapes(n, rng).items():
        q0 = polygon_quality(p)
        for _ in range(400):
            p = transform_polygon(p, 0.3)
        q = polygon_quality(p)
        assert q > 1 - 1e-9, (kind, q0, q)  # mean ratio 1 <=> regular and counterclockwise
        edges = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
        assert np.ptp(edges) < 1e-6 * edges.mean(), kind


def test_lambda_sqrt3_over_3_makes_any_triangle_regular_in_one_step():
    rng = np.random.default_rng(7)
    for _ in range(50):
        p = rng.normal(size=(3, 2))
        out = transform_polygon(p, math.sqrt(3) / 3)
        assert polygon_quality(out) == pytest.approx(1.0, abs=1e-12)


def test_quad_convergence_rate_is_one_third_at_lambda_one():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(4, 2))
    z0 = np.fft.fft(p[:, 0] + 1j * p[:, 1])  # z0[j] / 4 = eigenpolygon e_j coefficient
    z1 = np.fft.fft(*[(lambda o: o[:, 0] + 1j * o[:, 1])(transform_polygon(p, 1.0))])
    for j in (2, 3):  # every non-regular component shrinks by |mu_j / mu_1| = 1/3
        ratio = (abs(z1[j]) / abs(z1[1])) / (abs(z0[j]) / abs(z0[1]))
        assert ratio == pytest.approx(1 / 3, rel=1e-12)
    assert z1[0] == pytest.approx(z0[0], abs=1e-12)  # centroid
