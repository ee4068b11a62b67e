"""Nearest-boundary distances (exact, NumPy only) and the plane frame."""

import numpy as np
import pytest

from core import PlaneFrame
from core.eegt.distance import NearestBoundary


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


def _rotation(a: float, b: float) -> np.ndarray:
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    return np.array([[ca, 0, sa], [0, 1, 0], [-sa, 0, ca]]) @ np.array(
        [[1, 0, 0], [0, cb, -sb], [0, sb, cb]]
    )


def _grid(n: int = 6, jitter: float = 0.0, lift: float = 0.0, seed: int = 0):
    """(n+1)^2 nodes of an n x n quad grid on [0, 1]^2 (z = 0), quads counterclockwise;
    interior nodes jittered in the plane (by `jitter` cells: folds above ~0.5) and lifted
    out of it by a bump of height `lift`; the boundary mask."""
    xs, ys = np.meshgrid(np.arange(n + 1) / n, np.arange(n + 1) / n)
    p = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    k = np.arange(n + 1)
    border = np.zeros((n + 1, n + 1), bool)
    border[[0, -1], :] = border[:, [0, -1]] = True
    border = border.ravel()
    rng = np.random.default_rng(seed)
    inner = ~border
    p[inner, :2] += rng.uniform(-jitter, jitter, (inner.sum(), 2)) / n
    p[inner, 2] = lift * np.sin(np.pi * p[inner, 0]) * np.sin(np.pi * p[inner, 1])
    faces = [[j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1,
              (j + 1) * (n + 1) + i] for j in k[:-1] for i in k[:-1]]
    return p, faces, border


def test_plane_frame_maps_with_the_explicit_formula_bit_for_bit():
    """to_2d / to_3d are q.x*u.x + q.y*u.y + q.z*u.z and origin + x u + y v in that order:
    no BLAS kernel (chosen per CPU) decides their last bits."""
    p, faces, _ = _grid(9, jitter=0.3, lift=1e-7)
    p3 = p @ _rotation(0.7, -1.1).T + [3.0, -2.0, 5.0]
    frame = PlaneFrame.fit(p3, faces)
    q = p3 - frame.origin
    u, v = frame.u, frame.v
    want2 = np.column_stack([q[:, 0] * u[0] + q[:, 1] * u[1] + q[:, 2] * u[2],
                             q[:, 0] * v[0] + q[:, 1] * v[1] + q[:, 2] * v[2]])
    got2 = frame.to_2d(p3)
    assert got2.tobytes() == want2.tobytes()
    want3 = np.column_stack([frame.origin[k] + got2[:, 0] * u[k] + got2[:, 1] * v[k]
                             for k in range(3)])
    assert frame.to_3d(got2).tobytes() == want3.tobytes()
    n = frame.normal
    assert np.cross(u, v) == pytest.approx(n, abs=1e-15)
    assert n == pytest.approx(_rotation(0.7, -1.1)[:, 2], abs=1e-9)
    assert (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) == pytest.approx(1.0, abs=4e-16)


def test_plane_normal_depends_on_the_boundary_only_bit_for_bit():
    """The vector area is summed over open edges: interior nodes, tangled or not, cannot
    change a single bit of the normal (and, with project, of the whole frame)."""
    rot = _rotation(0.3, 0.9)
    frames = []
    for jitter, seed in ((0.0, 0), (0.8, 1), (0.8, 2)):
        p, faces, _ = _grid(7, jitter=jitter, seed=seed)
        frames.append(PlaneFrame.fit(p @ rot.T + [1.0, 2.0, -3.0], faces, project=True))
    for f in frames[1:]:
        for name in ("origin", "u", "v", "normal"):
            assert getattr(f, name).tobytes() == getattr(frames[0], name).tobytes(), name
    p, faces, _ = _grid(7, jitter=0.8, seed=1)
    plain = PlaneFrame.fit(p @ rot.T, faces)  # all-node centroid origin: round-off only
    assert plain.normal == pytest.approx(frames[0].normal, abs=1e-15)


@pytest.mark.parametrize("jitter", [0.0, 0.7])  # a perfect grid (no move) and a folded one
def test_project_puts_free_nodes_on_the_plane_of_the_fixed_nodes(jitter):
    """Boundary exactly at z = 0, interior lifted by a bump: with project every node ends
    at z == 0 exactly and the boundary is bit-identical (the all-node centroid plane put the
    interior at the all-node centroid's z, about 0.01 here)."""
    from core import untangle_and_smooth_3d

    p, faces, border = _grid(6, jitter=jitter, lift=0.04)
    assert p[:, 2].mean() > 0.009  # where the all-node centroid plane would have put it
    with pytest.raises(ValueError, match="not planar"):
        untangle_and_smooth_3d(p, faces)
    frame = PlaneFrame.fit(p, faces, project=True)
    assert frame.origin[2] == 0.0 and abs(frame.normal[2]) == 1.0
    assert frame.fixed_offset == 0.0 and frame.max_offset == pytest.approx(0.04, rel=0.05)
    res = untangle_and_smooth_3d(p, faces, project=True)
    assert np.all(res.points[:, 2] == 0.0)
    assert res.points[border].tobytes() == p[border].tobytes()
    if jitter:
        assert res.before.n_inverted > 0 and res.after.n_inverted == 0
    else:  # nothing to optimise: the interior is only projected, x and y bit-identical
        assert res.points[:, :2].tobytes() == p[:, :2].tobytes()


def test_project_on_a_tilted_plane_with_a_pinned_node_off_it():
    """Tilted and shifted, one pinned interior node off the plane: the plane goes through
    the fixed nodes' centroid (24 boundary nodes and the pin: 1/25 of its lift) with the
    boundary's normal; free nodes land on it to round-off, fixed nodes do not move and fit
    reports how far the farthest one is."""
    from core import untangle_and_smooth_3d

    p, faces, border = _grid(6, jitter=0.7, lift=0.03, seed=3)
    pinned = np.zeros(len(p), bool)
    pinned[3 * 7 + 3] = True  # the centre node, near the top of the bump
    lift = p[pinned, 2][0]
    assert lift > 0.02
    rot = _rotation(0.7, -1.1)
    p3 = p @ rot.T + [3.0, -2.0, 5.0]
    frame = PlaneFrame.fit(p3, faces, project=True, fixed=pinned)
    assert frame.normal == pytest.approx(rot[:, 2], abs=1e-12)
    assert frame.fixed_offset == pytest.approx(lift * 24 / 25, rel=1e-9)
    res = untangle_and_smooth_3d(p3, faces, fixed=pinned, project=True)
    fixed = border | pinned
    assert res.points[fixed].tobytes() == p3[fixed].tobytes()
    off = (res.points - [3.0, -2.0, 5.0]) @ rot[:, 2]  # from the boundary's plane
    assert np.abs(off[~fixed] - lift / 25).max() < 1e-12 * np.sqrt(2.0)
    assert off[pinned][0] == pytest.approx(lift, rel=1e-9)
    assert res.after.n_inverted == 0 < res.before.n_inverted
