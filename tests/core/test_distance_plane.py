"""Nearest-boundary distances (exact, NumPy only) and the plane frame."""

import numpy as np
import pytest

from core import PlaneFrame
from core.distance import NearestBoundary


def brute(qx, qy, bx, by):
    return np.sqrt(((qx[:, None] - bx[None]) ** 2 + (qy[:, None] - by[None]) ** 2).min(axis=1))


@pytest.mark.parametrize("seed", range(4))
def test_nearest_boundary_distance_is_exact_inside_and_outside_the_domain(seed):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 2 * np.pi, 300))
    r = rng.uniform(0.3, 1.0, t.size)
    bx, by = r * np.cos(t), r * np.sin(t)
    hx, hy = rng.uniform(-1, 1, (2, 2000))
    nb = NearestBoundary(bx, by, hx, hy, min_cell=1e-3)
    qx, qy = rng.uniform(-4, 4, (2, 3000))  # many queries outside the tree's square too
    np.testing.assert_array_equal(nb.query(qx, qy), brute(qx, qy, bx, by))
    assert nb.n_candidate_pairs < 300 * 2000  # pruned, not brute force


def test_nearest_boundary_handles_dense_boundary_far_from_coarse_queries():
    # a tiny, densely sampled "airfoil" inside a large square: the naca_deform situation
    t = np.linspace(0, 2 * np.pi, 341, endpoint=False)
    ax, ay = 0.5 * np.cos(t), 0.06 * np.sin(t)
    s = np.linspace(-10, 10, 21)[:-1]
    sq = np.concatenate(
        [
            np.column_stack([s, -10 + 0 * s]),
            np.column_stack([10 + 0 * s, s]),
            np.column_stack([-s, 10 + 0 * s]),
            np.column_stack([-10 + 0 * s, -s]),
        ]
    )
    bx, by = np.concatenate([ax, sq[:, 0]]), np.concatenate([ay, sq[:, 1]])
    rng = np.random.default_rng(0)
    qx, qy = rng.uniform(-10, 10, (2, 5000))
    nb = NearestBoundary(bx, by, qx, qy, min_cell=0.002)
    np.testing.assert_array_equal(nb.query(qx, qy), brute(qx, qy, bx, by))
    assert nb.n_candidate_pairs < 3_000_000


def test_plane_frame_round_trip_and_orientation():
    rng = np.random.default_rng(1)
    p2 = rng.uniform(0, 1, (4, 2))
    p2 = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    a, b = 0.7, -1.1
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]) @ np.array(
        [[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]]
    )
    p3 = np.column_stack([p2, np.zeros(4)]) @ rot.T + [3, -2, 5]
    for faces in ([[0, 1, 2, 3]], [[3, 2, 1, 0]]):  # either winding is made counterclockwise
        frame = PlaneFrame.fit(p3, faces)
        q = frame.to_2d(p3)
        f = faces[0]
        area = 0.5 * sum(
            q[f[k], 0] * q[f[(k + 1) % 4], 1] - q[f[(k + 1) % 4], 0] * q[f[k], 1] for k in range(4)
        )
        assert area == pytest.approx(1.0)
        np.testing.assert_allclose(frame.to_3d(q), p3, atol=1e-14)
