"""Per-face target shapes (core.metrics.targets): quality against targets, the generalised stretch,
fallbacks, bad input, and whole runs towards anisotropic targets."""

from __future__ import annotations

import math

import numpy as np
import pytest
from meshdata import load, load2d

from core import (
    EEGTParams,
    free_nodes,
    mesh_stats,
    quality,
    untangle_and_smooth,
    untangle_and_smooth_3d,
)
from core.eegt.transform import _stretch, _target_stretch, transform_polygon
from core.mesh.faces import as_faceset
from core.metrics.mean_ratio import group_quality
from core.metrics.targets import (
    FLAT_TOL,
    THIN_TOL,
    corner_factors,
    face_shapes_2d,
    prepare_targets,
    regular_polygon,
    stretch_gain,
)

EEGT_ONLY = EEGTParams(untangle="eegt", polish_iterations=0, lift_rounds=0)


def rot(a: float) -> np.ndarray:
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


def regular(n: int, phase: float = 0.0) -> np.ndarray:
    t = 2 * np.pi * np.arange(n) / n + phase
    return np.column_stack([np.cos(t), np.sin(t)])


def random_faces(n: int, count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """`count` separate jittered regular n-gons (some inverted by the jitter)."""
    rng = np.random.default_rng(seed)
    amp = rng.uniform(0.05, 1.2, count)
    pts = np.concatenate([regular(n) + a * rng.normal(size=(n, 2)) for a in amp])
    return pts, np.arange(count * n).reshape(count, n)


def regular_targets(faces: np.ndarray, seed: int) -> np.ndarray:
    """A regular polygon per face, each moved, turned and scaled at random."""
    rng = np.random.default_rng(seed)
    n = faces.shape[1]
    out = []
    for s in 10.0 ** rng.uniform(-2, 2, faces.shape[0]):  # offsets a few sizes away
        out.append(s * (regular(n, rng.uniform(0, 7)) + rng.uniform(-5, 5, 2)))
    return np.concatenate(out)


def single(n: int):
    return as_faceset([list(range(n))], n)


# ---- quality against targets ------------------------------------------------------------


@pytest.mark.parametrize("n", [3, 4, 5, 6])
def test_regular_targets_give_the_regular_quality_to_round_off(n):
    pts, faces = random_faces(n, 400, n)
    q0 = quality(pts, faces)
    q = quality(pts, faces, regular_targets(faces, 10 + n))
    assert (q0 == 0).sum() > 20 and (q0 > 0).sum() > 100  # inverted and valid faces
    assert np.array_equal(q == 0, q0 == 0)
    np.testing.assert_allclose(q, q0, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("n", [4, 5, 6, 8])
def test_fallback_faces_use_the_regular_constants_bit_for_bit(n):
    """A quad's or n-gon's fallback target (the regular polygon, with the constants of
    core.fpmath.regular_corner) gives the targets=None quality exactly."""
    pts, faces = random_faces(n, 300, 20 + n)
    nan = np.full((faces.size, 2), np.nan)
    assert np.array_equal(quality(pts, faces, nan), quality(pts, faces))


@pytest.mark.parametrize("n", [3, 4, 5, 6, 7])
def test_quality_invariant_under_target_similarity_and_first_corner(n):
    rng = np.random.default_rng(n)
    target = regular(n) * [1.0, 0.4] + 0.08 * rng.normal(size=(n, 2))
    pts, faces = random_faces(n, 200, 30 + n)
    T = np.tile(target, (len(faces), 1))
    q = quality(pts, faces, T)
    assert (q > 0.3).sum() > 20
    moved = np.tile(7.5 * target @ rot(2.1).T + [40.0, -3.0], (len(faces), 1))
    np.testing.assert_allclose(quality(pts, faces, moved), q, rtol=1e-12, atol=1e-15)
    for shift in range(1, n):  # corner `shift` first, for the face and its target alike
        order = np.roll(np.arange(n), -shift)
        qs = quality(pts, faces[:, order], np.tile(target[order], (len(faces), 1)))
        np.testing.assert_allclose(qs, q, rtol=1e-12, atol=1e-15)


def test_rectangle_target_one_for_similar_rectangles_less_for_a_square():
    rect = np.array([[0, 0], [1, 0], [1, 3], [0, 3]], float)
    face = [[0, 1, 2, 3]]
    for a, s, off in [(0.0, 1.0, (0, 0)), (0.7, 2.5, (3, -1)), (math.pi / 2, 1e-3, (1e3, 5))]:
        p = s * rect @ rot(a).T + off
        assert quality(p, face, rect)[0] == pytest.approx(1.0, abs=1e-14)
        # the same rectangle with another corner first
        assert quality(p[[2, 3, 0, 1]], face, rect)[0] == pytest.approx(1.0, abs=1e-14)
    wide = np.array([[0, 0], [3, 0], [3, 1], [0, 1]], float)  # 3 x 1: a quarter turn of it
    # corner by corner M = diag(3, 1/3): q = 2 / (9 + 1/9), unless the corners turn with it
    assert quality(wide, face, rect)[0] == pytest.approx(18 / 82, abs=1e-14)
    assert quality(wide[[1, 2, 3, 0]], face, rect)[0] == pytest.approx(1.0, abs=1e-14)
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    # M = diag(1, 1/3): q = 2 (1/3) / (1 + 1/9) = 0.6
    assert quality(square, face, rect)[0] == pytest.approx(0.6, abs=1e-14)
    assert quality(square, face)[0] == 1.0


def test_inverted_rule_does_not_depend_on_targets():
    pts, faces = random_faces(5, 300, 3)
    T = np.tile(regular(5) * [2.0, 0.5], (len(faces), 1))
    assert np.array_equal(quality(pts, faces, T) == 0, quality(pts, faces) == 0)


# ---- fallback and bad input ----------------------------------------------------------------


def square_grid() -> tuple[np.ndarray, np.ndarray]:
    """3 x 3 unit squares (4 interior nodes), counterclockwise."""
    ys, xs = np.mgrid[0:4, 0:4]
    pts = np.column_stack([xs.ravel(), ys.ravel()]).astype(float)
    a = (np.arange(3)[:, None] * 4 + np.arange(3)[None, :]).ravel()
    return pts, np.column_stack([a, a + 1, a + 5, a + 4])


def test_unusable_targets_fall_back_and_are_counted():
    pts, faces = square_grid()
    good = [[0, 0], [2, 0], [2, 1], [0, 1]]
    T = [
        good,
        [[0, 0], [2, 0], [0.5, 0.5], [0, 2]],  # concave
        [[0, 0], [1, 0], [2, 0], [0, 1]],  # straight corner
        [[1, 1]] * 4,  # all one point
        [[0, 0], [1, 0], [1, np.nan], [0, 1]],
        [[0, 0], [np.inf, 0], [1, 1], [0, 1]],
        [[0, 0], [0, 1], [1, 1], [1, 0]],  # clockwise
        [[0, 0], [1, 0], [2, 1e-9], [0, 1]],  # sin(angle) ~ 1e-9: flat within FLAT_TOL
        [[0, 0], [1e300, 0], [1e300, 1e300], [0, 1e300]],  # huge but fine
    ]
    flat = np.array(T, dtype=float).reshape(-1, 2)
    tg = prepare_targets(flat, as_faceset(faces, len(pts)))
    assert tg.fallback.tolist() == [False] + [True] * 7 + [False]
    assert tg.n_fallback == 7 and FLAT_TOL > 1e-9
    q = quality(pts, faces, flat)
    assert q[0] == pytest.approx(0.8, abs=1e-14)  # square vs 2 x 1
    assert q[1:8].tolist() == [1.0] * 7  # the regular polygon: a square is perfect
    assert q[8] == pytest.approx(1.0, abs=1e-14)
    pts[5] += 0.3  # something to do
    res = untangle_and_smooth(pts, faces, params=EEGT_ONLY, targets=flat)
    assert res.n_target_fallback == 7 and res.as_dict()["target_fallback_faces"] == 7
    assert "7 faces have an unusable target shape" in res.message
    plain = untangle_and_smooth(pts, faces, params=EEGT_ONLY, targets=np.tile(good, (9, 1)))
    assert plain.n_target_fallback == 0 and "target" not in plain.message


@pytest.mark.filterwarnings("error")
def test_thin_targets_are_honoured_down_to_thin_tol_then_fall_back():
    """A turned 1 x 1e-7 rectangle is a usable target (K stays accurate: the target is
    turned onto its long axis first); one thinner than THIN_TOL falls back; no warnings."""
    rect = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    face = [[0, 1, 2, 3]]
    start = np.array([[0, 0], [1, 0], [1.2, 1], [0, 1.3]])
    for thin, fallback in ((1e-3, False), (1e-7, False), (1e-9, True), (1e-200, True)):
        T = (rect * [1.0, thin]) @ rot(0.7).T + [3.0, 4.0]
        assert prepare_targets(T, single(4)).n_fallback == int(fallback)
        p = start
        for _ in range(200):
            p = transform_polygon(p, 0.3, target=T)
        assert quality(p, face, T)[0] > 1 - 1e-9, thin
        if not fallback:
            assert similar(p, T) < 1e-6
    assert THIN_TOL == 1e-8


@pytest.mark.parametrize(
    "bad, needle",
    [
        (np.zeros((35, 2)), "got shape (35, 2)"),
        (np.zeros((36, 3)), "got shape (36, 3)"),
        (np.zeros(72), "got shape (72,)"),
        ([["a", "b"]] * 36, "array of numbers"),
        ([[0, 0]] * 35 + [[0]], "array of numbers"),
    ],
)
def test_wrong_targets_are_one_line_value_errors(bad, needle):
    pts, faces = square_grid()
    for call in (
        lambda: quality(pts, faces, bad),
        lambda: mesh_stats(pts, faces, bad),
        lambda: untangle_and_smooth(pts, faces, targets=bad),
    ):
        with pytest.raises(ValueError, match=r"targets must be an \(36, 2\) array") as err:
            call()
        assert needle in str(err.value) and "\n" not in str(err.value)


def test_prepared_targets_of_other_faces_are_refused():
    pts, faces = square_grid()
    T = np.tile(regular(4) * [1.0, 2.0], (9, 1))
    tg = prepare_targets(T, as_faceset(faces, len(pts)))
    assert np.array_equal(quality(pts, faces, tg), quality(pts, faces, T))
    with pytest.raises(ValueError, match="prepared targets belong to other faces"):
        quality(pts, faces[:3], tg)


# ---- the generalised stretch -------------------------------------------------------------


@pytest.mark.parametrize("n", [3, 4, 6])
def test_generalised_stretch_equals_the_papers_for_regular_targets(n):
    """n = 3, 4, 6: the paper's stretch moves no non-affine mode of these (eq. 10 gives
    mu_j = 1 for them), so both stretches are the same vectors."""
    pts, faces = random_faces(n, 300, 40 + n)
    X, Y = pts[faces.T, 0], pts[faces.T, 1]
    tg = prepare_targets(regular_targets(faces, n), as_faceset(faces, len(pts))).groups[0]
    NX, NY = _stretch(X, Y)
    GX, GY = _target_stretch(X, Y, tg)
    size = np.maximum(np.ptp(X, axis=0), np.ptp(Y, axis=0))
    err = np.maximum(np.abs(GX - NX).max(axis=0), np.abs(GY - NY).max(axis=0)) / size
    assert np.median(err) < 2e-15 and err.max() < 1e-14


@pytest.mark.parametrize("n", [5, 7, 8])
def test_generalised_stretch_is_the_papers_stretch_of_the_affine_part(n):
    """For other n the generalised stretch is the paper's applied to the least-squares
    affine image of the target (modes 1 and n - 1): the other modes are not stretched."""
    pts, faces = random_faces(n, 50, 50 + n)
    X, Y = pts[faces.T, 0], pts[faces.T, 1]
    t = regular(n)
    tg = prepare_targets(np.tile(t, (len(faces), 1)), as_faceset(faces, len(pts))).groups[0]
    z = (X - X.mean(axis=0)) + 1j * (Y - Y.mean(axis=0))
    w = t[:, 0] + 1j * t[:, 1]
    # projection onto w (mode 1) and conj(w) (mode n - 1): the affine part of each face
    a = (np.conj(w)[:, None] * z).sum(axis=0) / (np.abs(w) ** 2).sum()
    b = (w[:, None] * z).sum(axis=0) / (np.abs(w) ** 2).sum()
    affine = a * w[:, None] + b * np.conj(w)[:, None]
    NX, NY = _stretch(affine.real, affine.imag)
    GX, GY = _target_stretch(X, Y, tg)
    np.testing.assert_allclose(GX, NX, atol=1e-13 * np.abs(NX).max())
    np.testing.assert_allclose(GY, NY, atol=1e-13 * np.abs(NY).max())
    PX, _ = _stretch(X, Y)
    assert np.abs(PX - GX).max() > 0.05 * np.abs(PX).max()  # the paper's moves more modes


def test_stretch_gain_is_the_papers_eigenvalue():
    for n in range(3, 20):
        R = math.ceil((n - 1) / 4)
        assert stretch_gain(n) == pytest.approx(
            sum(2 * math.sin(2 * math.pi * r / n) for r in range(1, R + 1)), rel=1e-15
        )


def similar(p: np.ndarray, t: np.ndarray) -> float:
    """Residual of the best similarity t -> p (complex least squares), relative to p's size."""
    z = p[:, 0] + 1j * p[:, 1]
    w = t[:, 0] + 1j * t[:, 1]
    z, w = z - z.mean(), w - w.mean()
    a = (np.conj(w) * z).sum() / (np.abs(w) ** 2).sum()
    return float(np.abs(z - a * w).max() / np.abs(z).max())


@pytest.mark.parametrize(
    "target",
    [
        [[0, 0], [4, 0], [1, 1]],
        [[0, 0], [3, 0], [3, 1], [0, 1]],
        [[0, 0], [2, 0], [3, 0.3], [2, 0.6], [0, 0.6], [-1, 0.3]],
        [[0, 0], [2, 0], [3, 1], [1, 3], [-1, 1]],
    ],
    ids=["triangle", "quad", "hexagon", "pentagon"],
)
def test_repeated_transform_converges_to_a_similar_copy_of_the_target(target):
    T = np.array(target, dtype=float)
    n = len(T)
    rng = np.random.default_rng(n)
    starts = [rng.normal(size=(n, 2)), rng.normal(size=(n, 2))[::-1], regular(n)]
    for p in starts:
        c = p.mean(axis=0)
        for _ in range(300):
            p = transform_polygon(p, 0.3, target=T)
        assert quality(p, [list(range(n))], T)[0] > 1 - 1e-12
        assert similar(p, T) < 1e-9
        np.testing.assert_allclose(p.mean(axis=0), c, atol=1e-12)  # centroid kept (Theorem 1)


# ---- factors for the global stage ----------------------------------------------------------


@pytest.mark.parametrize("n", [3, 4, 5, 6, 9])
def test_corner_factors_regular_and_none_give_the_regular_corner(n):
    pts, faces = random_faces(n, 20, n)
    fs = as_faceset(faces, len(pts))
    cos_a, sin_a = math.cos((n - 2) * math.pi / n), math.sin((n - 2) * math.pi / n)
    for targets in (None, np.full((fs.n_corners, 2), np.nan)):  # exact constants
        u00, u01, u11 = corner_factors(targets, fs)[n]
        assert u00.shape == (20, n)
        assert (u00 == 1.0).all() and (u01 == u01[0, 0]).all() and (u11 == u11[0, 0]).all()
        assert abs(u01[0, 0] - cos_a) < 1e-15 and abs(u11[0, 0] - sin_a) < 1e-15
    u00, u01, u11 = corner_factors(regular_targets(faces, 3), fs)[n]  # to round-off
    np.testing.assert_allclose(u00, 1.0, rtol=1e-13)
    np.testing.assert_allclose(u01, cos_a, atol=1e-13)
    np.testing.assert_allclose(u11, sin_a, rtol=1e-13)


def test_corner_factors_of_a_rectangle_and_their_meaning():
    """1 x 3 rectangle, scaled to area 1 (the unit square's): corner 0 has edges 1 and 3
    scaled by 1 / sqrt(3); J U^-1 has the det and Frobenius norm of J W^-1."""
    rect = np.array([[0, 0], [1, 0], [1, 3], [0, 3]], float)
    fs = single(4)
    u00, u01, u11 = (a[0] for a in corner_factors(rect, fs)[4])
    s = 1 / math.sqrt(3)
    np.testing.assert_allclose(u00, [s, 3 * s, s, 3 * s], rtol=1e-14)
    np.testing.assert_allclose(u11, [3 * s, s, 3 * s, s], rtol=1e-14)
    np.testing.assert_allclose(u01, 0.0, atol=1e-15)
    rng = np.random.default_rng(0)
    T = regular(6) * [1.0, 0.3] @ rot(0.4).T + 0.05 * rng.normal(size=(6, 2))
    P = rng.normal(size=(6, 2))
    u00, u01, u11 = (a[0] for a in corner_factors(T, single(6))[6])
    area = 0.5 * np.sum(T[:, 0] * np.roll(T[:, 1], -1) - np.roll(T[:, 0], -1) * T[:, 1])
    sigma = math.sqrt(6 / (4 * math.tan(math.pi / 6)) / area)
    for k in range(6):
        J = np.column_stack([P[(k + 1) % 6] - P[k], P[k - 1] - P[k]])
        W = sigma * np.column_stack([T[(k + 1) % 6] - T[k], T[k - 1] - T[k]])
        U = np.array([[u00[k], u01[k]], [0.0, u11[k]]])
        M1, M2 = J @ np.linalg.inv(W), J @ np.linalg.inv(U)
        assert np.linalg.det(M2) == pytest.approx(np.linalg.det(M1), rel=1e-12)
        assert np.linalg.norm(M2) == pytest.approx(np.linalg.norm(M1), rel=1e-12)
        assert u00[k] > 0 and u11[k] > 0


# ---- targets from 3D -----------------------------------------------------------------------


def test_face_shapes_2d_of_a_turned_copy_measure_quality_one():
    p, f = load2d("polygon_voronoi")
    rng = np.random.default_rng(2)
    q3, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    p3 = np.column_stack([p, np.zeros(len(p))]) @ q3.T * 3.0 + [1.0, 2.0, 3.0]
    shapes = face_shapes_2d(p3, f)
    q = quality(p, f, shapes)
    valid = quality(p, f) > 0
    assert valid.sum() > 50
    np.testing.assert_allclose(q[valid], 1.0, atol=1e-12)
    mirrored = face_shapes_2d(p3 * [1.0, 1.0, -1.0], f)  # a mirror image: same shapes
    np.testing.assert_allclose(quality(p, f, mirrored)[valid], 1.0, atol=1e-12)


# ---- whole runs ------------------------------------------------------------------------------


def tangled_grid(m: int, n: int, w: float, h: float, jitter: float, seed: int):
    """An m x n grid of w x h cells, interior nodes jittered (which tangles it)."""
    ys, xs = np.mgrid[0 : m + 1, 0 : n + 1]
    pts = np.column_stack([xs.ravel() * w, ys.ravel() * h]).astype(float)
    inner = ((xs > 0) & (xs < n) & (ys > 0) & (ys < m)).ravel()
    rng = np.random.default_rng(seed)
    pts[inner] += rng.uniform(-jitter, jitter, (int(inner.sum()), 2)) * [w, h]
    a = (np.arange(m)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    return pts, np.column_stack([a, a + 1, a + n + 2, a + n + 1])


def test_anisotropic_targets_untangle_towards_their_shape():
    """Cells 1 x 4: pulled towards 1 x 4 rectangles the run ends near target quality 1;
    pulled towards squares (the paper) it stays far from it."""
    pts, faces = tangled_grid(8, 16, 1.0, 4.0, 0.6, 0)
    T = np.tile([[0, 0], [1, 0], [1, 4], [0, 4]], (len(faces), 1)).astype(float)
    before = mesh_stats(pts, faces, T)
    assert before.n_inverted > 20
    prm = EEGT_ONLY.with_(tol=1e-4)
    res = untangle_and_smooth(pts, faces, params=prm, targets=T)
    reg = untangle_and_smooth(pts, faces, params=prm)
    assert res.status == reg.status == "untangled"
    assert res.after == mesh_stats(res.points, faces, T)  # reported against the targets
    on_target = res.after
    off_target = mesh_stats(reg.points, faces, T)
    assert on_target.n_inverted == 0 and on_target.q_min > 0.9 and on_target.q_avg > 0.97
    assert off_target.q_min < 0.7 and off_target.q_avg < 0.9
    assert mesh_stats(res.points, faces).q_avg < 0.5  # far from squares, as asked


def test_default_params_with_targets_run_and_never_return_worse_than_input():
    pts, faces = tangled_grid(6, 10, 1.0, 3.0, 0.5, 1)
    T = np.tile([[0, 0], [1, 0], [1, 3], [0, 3]], (len(faces), 1)).astype(float)
    res = untangle_and_smooth(pts, faces, targets=T)
    before = mesh_stats(pts, faces, T)
    assert res.before == before
    assert res.after == mesh_stats(res.points, faces, T)
    assert res.status == "untangled" and res.after.better_than(before)
    # an already perfect mesh with its own targets stays exactly as it is
    grid, _ = tangled_grid(6, 10, 1.0, 3.0, 0.0, 1)
    ok = untangle_and_smooth(grid, faces, targets=T)
    assert ok.status == "valid" and np.array_equal(ok.points, grid)
    assert ok.after.q_min == pytest.approx(1.0, abs=1e-12)


def test_targets_pass_through_the_3d_entry_point():
    v, f = load("tilted_plane")
    flat, _ = load2d("quad_hole")
    T = np.tile([[0, 0], [2, 0], [2, 1], [0, 1]], (f.n_faces, 1)).astype(float)
    r3 = untangle_and_smooth_3d(v, f, params=EEGT_ONLY, targets=T)
    r2 = untangle_and_smooth(flat, f, params=EEGT_ONLY, targets=T)
    assert r3.status == r2.status == "untangled"
    assert r3.after.q_avg == pytest.approx(r2.after.q_avg, abs=1e-6)
    assert r3.after.q_avg != pytest.approx(untangle_and_smooth_3d(v, f, params=EEGT_ONLY)
                                           .after.q_avg, abs=1e-3)


def test_group_quality_with_targets_in_mixed_meshes_matches_quality():
    p, f = load2d("mixed_quad_tri")
    T = face_shapes_2d(np.column_stack([p * [1.0, 2.0], np.zeros(len(p))]), f)
    tg = prepare_targets(T, f)
    q = quality(p, f, T)
    for g, t in zip(f.groups, tg.groups):
        assert np.array_equal(group_quality(p[g.nodes, 0], p[g.nodes, 1], t.corners), q[g.ids])
    x, y = regular_polygon(4)
    np.testing.assert_allclose(np.column_stack([x, y]), regular(4), atol=1e-15)


def test_global_stage_with_regular_factors_is_bit_identical_to_none():
    """The energies with every face's regular factors given explicitly: the same bits as
    without factors (untangling, polish and the lift)."""
    from core.optimize import GlobalOptions, lift_min_quality, untangle_global

    p, f = load2d("mixed_quad_tri")
    free = free_nodes(len(p), f)
    groups, factors = f.by_arity(), corner_factors(None, f)
    opt = GlobalOptions(polish_iter=60, lift_rounds=3)
    a, ia = untangle_global(p, groups, free, opt)
    b, ib = untangle_global(p, groups, free, opt, factors=factors)
    assert np.array_equal(a, b) and ia["iterations"] == ib["iterations"] > 0
    la, _ = lift_min_quality(a, groups, free, opt)
    lb, _ = lift_min_quality(a, groups, free, opt, factors=factors)
    assert np.array_equal(la, lb) and not np.array_equal(la, a)


def test_default_pipeline_polishes_towards_the_targets():
    """With default parameters the global stage (untangling, polish, lift) measures corners
    against the targets: a tangled graded grid (rows 1.25x taller each) with its own cells as
    targets comes back graded, while pulled towards squares it does not."""
    ys = np.concatenate([[0.0], np.cumsum(0.2 * 1.25 ** np.arange(10))])
    X, Y = np.meshgrid(np.linspace(0.0, ys[-1], 11), ys)
    ref = np.column_stack([X.ravel(), Y.ravel()])
    a = (np.arange(10)[:, None] * 11 + np.arange(10)[None, :]).ravel()
    faces = np.column_stack([a, a + 1, a + 12, a + 11])
    inner = ((X > 0) & (X < ys[-1]) & (Y > 0) & (Y < ys[-1])).ravel()
    pts = ref.copy()
    rng = np.random.default_rng(4)
    cell = np.column_stack([np.full(len(ref), ys[-1] / 10), np.gradient(ys)[np.repeat(
        np.arange(11), 11)]])
    pts[inner] += rng.uniform(-0.45, 0.45, (int(inner.sum()), 2)) * cell[inner]
    T = ref[faces.ravel()]
    before = mesh_stats(pts, faces, T)
    res = untangle_and_smooth(pts, faces, targets=T)
    reg = untangle_and_smooth(pts, faces)
    assert before.n_inverted > 0 and res.status == "untangled" and res.global_iterations > 0
    assert res.after.q_min > 0.99 and res.after.q_avg > 0.999
    off = mesh_stats(reg.points, faces, T)
    assert off.q_min < 0.8 and off.q_avg < 0.95


def test_local_stage_subsets_target_factors_with_its_faces():
    """eegt+local on a grid with targets: the sub-mesh carries its own faces' factors."""
    from core.optimize import active_submesh

    pts, faces = tangled_grid(8, 12, 1.0, 3.0, 0.0, 2)
    fs = as_faceset(faces, len(pts))
    T = np.tile([[0, 0], [1, 0], [1, 3], [0, 3]], (len(faces), 1)).astype(float)
    factors = corner_factors(T, fs)
    seed = np.zeros(fs.n_faces, dtype=bool)
    seed[40] = True
    factors[4][1][:] = np.arange(fs.n_faces)[:, None]  # u01 names its face: traceable rows
    sub, nodes, _free, sub_f = active_submesh(fs.by_arity(), free_nodes(len(pts), fs), seed, 1,
                                              factors)
    row_of = {tuple(r): i for i, r in enumerate(fs.by_arity()[4].tolist())}
    rows = [row_of[tuple(r)] for r in nodes[sub[4]].tolist()]
    assert sub_f[4][0].shape == sub[4].shape and 1 < len(rows) < fs.n_faces
    assert np.array_equal(sub_f[4][1][:, 0], rows)
