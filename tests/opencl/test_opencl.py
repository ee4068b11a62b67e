"""OpenCL backend: parity with the NumPy reference, determinism, fallbacks, device choice.

Tests that need a real float64 OpenCL device (pocl's CPU device is enough) skip, saying why,
when none exists; the fallback and device-choice tests use stub modules and always run.
"""

from __future__ import annotations

import sys
import types
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from meshdata import load, load2d, spiked_strip

from bench.fuzz import merge_faces
from core.eegt import backends
from core.eegt.engine_numpy import NumpyEngine
from core.mesh.faces import FaceSet, as_faceset
from core.metrics.targets import prepare_targets
from core.params import EEGTParams
from core.run.pipeline import Cancelled, free_nodes, untangle_and_smooth
from core.run.pipeline_3d import untangle_and_smooth_3d

eo = pytest.importorskip("core.eegt.engine_opencl")
ort = pytest.importorskip("core.opencl.runtime")
ocb = pytest.importorskip("core.opencl.build")

PLANAR = ["quad_hole", "tri_two_holes", "naca_deform", "mixed_quad_tri", "polygon_voronoi"]
PLANAR += ["two_holes_twist"]
REL = 1e-12


@pytest.fixture(scope="module")
def device() -> str:
    """Skip unless a float64 OpenCL device is usable; returns its description."""
    cls, why = eo.available()
    if cls is None:
        pytest.skip(f"no usable OpenCL device: {why}")
    return ort.runtime().name


@pytest.fixture(scope="module")
def cpu_device(device) -> str:
    """A CPU device, where the OpenCL engine promises NumPy's bits (a GPU: round-off)."""
    if not ort.runtime().is_cpu:
        pytest.skip(f"bit-identity is promised on CPU devices; {device} is not one")
    return device


@pytest.fixture(autouse=True)
def _fresh_warnings(monkeypatch):
    """Each test sees the 'said once' fallback messages afresh (and probes devices anew)."""
    monkeypatch.setattr(backends, "_warned", set())
    monkeypatch.setattr(ort, "_build_faults", {})
    monkeypatch.setattr(ort, "runtimes", dict(ort.runtimes))  # fakes' runtimes stay here


def assert_close(a: np.ndarray, b: np.ndarray, scale: float, what: str) -> None:
    err = float(np.abs(a - b).max()) / scale
    assert err <= REL, f"{what}: max difference {err:.3e} of the mesh size (limit {REL})"


def step_both(p, f, free, params, n_untangle: int, n_smooth: int) -> None:
    """Step NumPy and OpenCL engines side by side; positions and stats agree every step."""
    ref = NumpyEngine(p, f, free, params)
    eng, name = backends.make_engine("opencl", p, f, free, params)
    assert name == "opencl", name
    scale = float(np.ptp(p, axis=0).max())
    assert eng.stats().n_inverted == ref.stats().n_inverted
    for it in range(n_untangle + n_smooth):
        phase = "untangle" if it < n_untangle else "smooth"
        sa, sb = ref.step(phase), eng.step(phase)
        assert_close(ref.points(), eng.points(), scale, f"iteration {it + 1} ({phase})")
        assert sa.n_inverted == sb.n_inverted, (it, sa, sb)
        assert sb.q_min == pytest.approx(sa.q_min, rel=REL, abs=REL)
        assert sb.q_avg == pytest.approx(sa.q_avg, rel=REL, abs=REL)
        if it % 7 == 0:  # the best-iterate copy lives on the device too
            ref.save_best()
            eng.save_best()
    assert_close(ref.best_points(), eng.best_points(), scale, "best iterate")


def step_exact(p, f, free, params, n_untangle: int, n_smooth: int, targets=None) -> None:
    """Step NumPy and OpenCL engines side by side: positions bit-identical every step.
    `targets`: per-corner target shapes (raw), or None."""
    tg = prepare_targets(targets, as_faceset(f, len(p)))
    ref = NumpyEngine(p, f, free, params, tg)
    eng, name = backends.make_engine("opencl", p, f, free, params, tg)
    assert name == "opencl", name
    for it in range(n_untangle + n_smooth):
        phase = "untangle" if it < n_untangle else "smooth"
        sa, sb = ref.step(phase), eng.step(phase)
        a, b = ref.points(), eng.points()
        if not np.array_equal(a, b):
            rows = np.flatnonzero(np.any(a != b, axis=1))
            d = float(np.abs(a - b).max())
            pytest.fail(f"iteration {it + 1} ({phase}): {rows.size} nodes differ (max {d:.3e})")
        assert sa == sb, f"iteration {it + 1} ({phase}): stats {sa} != {sb}"


# ---- parity ----------------------------------------------------------------------------


@pytest.mark.parametrize("name", PLANAR)
def test_per_iteration_parity_on_shared_meshes(device, name):
    p, f = load2d(name)
    steps = (12, 8) if name == "naca_deform" else (25, 15)
    step_both(p, f, free_nodes(len(p), f), EEGTParams(), *steps)


@pytest.mark.parametrize(
    "params",
    [
        EEGTParams(scaling="area"),
        EEGTParams(a=0.35, eta=1.5, c=1.0, inverted_weight=3.0, distance_refresh=3),
        EEGTParams(eta=0.5, c=0.0),
    ],
    ids=["area", "general-pow", "sqrt-pow"],
)
def test_parity_with_other_parameters(device, params):
    p, f = load2d("mixed_quad_tri")
    step_both(p, f, free_nodes(len(p), f), params, 10, 10)


@pytest.mark.parametrize("c, eta", [(1.5, 2.7), (3.0, 1.3)])
@pytest.mark.parametrize("name", ["quad_hole", "mixed_quad_tri", "polygon_voronoi"])
def test_general_powers_bit_identical_on_shared_meshes(cpu_device, name, c, eta):
    """Non-special exponents: both engines use core.fpmath's exp(e log x), operation for
    operation, so the positions are the same bits (no libm pow on either side)."""
    p, f = load2d(name)
    params = EEGTParams(c=c, eta=eta, distance_refresh=3)
    step_exact(p, f, free_nodes(len(p), f), params, 12, 8)


@pytest.mark.parametrize(
    "name", ["quad_hole", "tri_two_holes", "mixed_quad_tri", "polygon_voronoi"]
)
def test_pipeline_same_result_and_iteration_counts(device, name):
    p, f = load2d(name)
    ra = untangle_and_smooth(p, f, backend="numpy")
    rb = untangle_and_smooth(p, f, backend="opencl")
    assert rb.backend == "opencl"
    assert (ra.status, ra.untangle_iterations, ra.smooth_iterations) == (
        rb.status,
        rb.untangle_iterations,
        rb.smooth_iterations,
    )
    assert_close(ra.points, rb.points, float(np.ptp(p, axis=0).max()), name)
    assert rb.after.n_inverted == ra.after.n_inverted == 0


def test_failed_run_returns_same_best_iterate(device):
    p, f = load2d("two_holes_twist")
    params = EEGTParams(max_untangle_iterations=60, untangle="eegt")
    ra = untangle_and_smooth(p, f, params=params, backend="numpy")
    rb = untangle_and_smooth(p, f, params=params, backend="opencl")
    assert ra.status == rb.status == "failed"
    assert ra.after.n_inverted == rb.after.n_inverted > 0
    assert rb.after.q_min == pytest.approx(ra.after.q_min, rel=REL, abs=REL)
    assert rb.after.q_avg == pytest.approx(ra.after.q_avg, rel=REL, abs=REL)
    assert_close(ra.points, rb.points, float(np.ptp(p, axis=0).max()), "failed run")


def test_naca_deform_outcome(device):
    """Untangling naca_deform is chaotic (round-off changes its trajectory): check the outcome
    (a NumPy run takes half a minute, too long here; bench/bench_opencl.py compares both)."""
    p, f = load2d("naca_deform")
    res = untangle_and_smooth(p, f, backend="opencl")
    assert res.backend == "opencl"
    assert res.status == "untangled" and res.after.n_inverted == 0 < res.before.n_inverted
    assert res.after.q_min > 0.0 and res.after.q_avg > res.before.q_avg


def test_tilted_plane_3d(device):
    v, f = load("tilted_plane")
    ra = untangle_and_smooth_3d(v, f, backend="numpy")
    rb = untangle_and_smooth_3d(v, f, backend="opencl")
    assert rb.backend == "opencl"
    assert (ra.untangle_iterations, ra.smooth_iterations) == (
        rb.untangle_iterations,
        rb.smooth_iterations,
    )
    assert_close(ra.points, rb.points, float(np.ptp(v, axis=0).max()), "tilted plane")


@st.composite
def polygon_meshes(draw, max_side: int = 7):
    """A jittered m x n grid of quads, some split into triangles, some pairs merged into
    hexagons; every face counterclockwise before the jitter, which may invert some."""
    m = draw(st.integers(3, max_side))
    n = draw(st.integers(3, max_side))
    seed = draw(st.integers(0, 2**31 - 1))
    jitter = draw(st.floats(0.05, 0.7))
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0 : m + 1, 0 : n + 1]
    pts = np.column_stack([xs.ravel(), ys.ravel()]).astype(np.float64)
    inner = ((xs > 0) & (xs < n) & (ys > 0) & (ys < m)).ravel()
    pts[inner] += rng.uniform(-jitter, jitter, (int(inner.sum()), 2))
    kind = rng.integers(0, 3, (m, n))  # 0 quad, 1 two triangles, 2 merge with right neighbour
    faces: list[list[int]] = []
    for i in range(m):
        j = 0
        while j < n:
            a, b = i * (n + 1) + j, i * (n + 1) + j + 1
            c, d = b + n + 1, a + n + 1
            if kind[i, j] == 2 and j + 1 < n:
                faces.append([a, b, b + 1, c + 1, c, d])
                j += 2
                continue
            faces += [[a, b, c], [a, c, d]] if kind[i, j] == 1 else [[a, b, c, d]]
            j += 1
    pinned = rng.random(len(pts)) < 0.1
    return pts, faces, pinned


@settings(
    max_examples=6,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(mesh=polygon_meshes())
def test_parity_on_random_polygon_meshes(device, mesh):
    pts, faces, pinned = mesh
    fs = as_faceset(faces, len(pts))
    free = free_nodes(len(pts), fs, pinned)
    assume(free.any())
    step_both(pts, fs, free, EEGTParams(), 12, 6)


@settings(
    max_examples=8,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    mesh=polygon_meshes(),
    c=st.floats(0.1, 4.0).filter(lambda v: v not in (0.5, 1.0, 2.0)),
    eta=st.floats(0.1, 4.0).filter(lambda v: v not in (0.5, 1.0, 2.0)),
)
def test_general_powers_bit_identical_on_random_meshes(cpu_device, mesh, c, eta):
    pts, faces, pinned = mesh
    fs = as_faceset(faces, len(pts))
    free = free_nodes(len(pts), fs, pinned)
    assume(free.any())
    step_exact(pts, fs, free, EEGTParams(c=c, eta=eta, distance_refresh=2), 10, 6)


@st.composite
def fuzz_cases(draw):
    """A small tangled polygon mesh (a jittered grid of quads / triangle pairs / hexagons,
    some neighbours merged into n-gons of up to 10 corners, some nodes pinned) and random
    parameters (paper mode included): what bench/fuzz.py runs, kept small for CI."""
    pts, faces, pinned = draw(polygon_meshes(max_side=5))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    faces = merge_faces(rng, faces, draw(st.integers(5, 10)), draw(st.integers(0, 8)))
    exps = st.sampled_from([0.0, 0.5, 1.0, 2.0]) | st.floats(0.05, 4.0)
    paper = EEGTParams.paper().with_(max_untangle_iterations=300, max_smooth_iterations=100)
    params = st.just(paper) | st.builds(
        EEGTParams,
        a=st.floats(0.05, 0.5),
        eta=exps,
        c=exps,
        tol=st.sampled_from([0.0, 1e-5, 1e-3]),
        distance_refresh=st.integers(1, 12),
        scaling=st.sampled_from(["edge", "area"]),
        untangle=st.sampled_from(["eegt", "eegt+global", "global"]),
        max_untangle_iterations=st.integers(0, 200),
        max_smooth_iterations=st.integers(0, 100),
        polish_iterations=st.integers(0, 100),
        lift_rounds=st.integers(0, 2),
    )
    return pts, faces, pinned, draw(params)


def run_both(pts, faces, pinned, params, targets=None):
    """(NumPy result, OpenCL result), or None when both refuse the input alike."""
    out = []
    for backend in ("numpy", "opencl"):
        try:
            out.append(
                untangle_and_smooth(pts, faces, pinned, params, backend=backend, targets=targets)
            )
        except ValueError as exc:
            out.append(str(exc))
    ra, rb = out
    if isinstance(ra, str) or isinstance(rb, str):
        assert ra == rb, f"only one backend refused the input: {ra!r} vs {rb!r}"
        return None
    assert rb.backend == "opencl", rb.backend
    return ra, rb


def assert_same_run(ra, rb) -> None:
    if not np.array_equal(ra.points, rb.points):
        rows = np.flatnonzero(np.any(ra.points != rb.points, axis=1))
        d = float(np.abs(ra.points - rb.points).max())
        pytest.fail(f"{rows.size} nodes differ (max {d:.3e}); {ra.message} | {rb.message}")
    counts = (ra.untangle_iterations, ra.smooth_iterations, ra.global_iterations)
    assert (ra.status, ra.after, counts) == (
        rb.status,
        rb.after,
        (rb.untangle_iterations, rb.smooth_iterations, rb.global_iterations),
    )


@pytest.mark.slow
@settings(
    max_examples=100,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(case=fuzz_cases())
def test_fuzz_pipeline_bit_identical(cpu_device, case):
    """Whole runs on both backends give the same bits, iteration counts and stats; and a few
    engine steps agree bit for bit, stats included (finds summation-order slips: a one-face
    n-gon group's corner sums, the stats' pairwise q sums)."""
    pts, faces, pinned, params = case
    both = run_both(pts, faces, pinned, params)
    if both is None:
        return
    assert_same_run(*both)
    fs = as_faceset(faces, len(pts))
    step_exact(pts, fs, both[0].moved, params, 4, 4)


# bench/fuzz.py seed 0, case 1015 (24 nodes, coincident nodes 7 and 8): the one octagon is
# a group of one face. NumPy sums a group's corners (centroid, shoelace area, corner-quality
# mean: X.sum(axis=0) of an (n, F) array) in order when F > 1, but with F == 1 its iterator
# drops the size-1 axis and the corners become the inner loop: pairwise_sum, which adds 8
# interleaved partial sums once n >= 8. The kernels summed in order: 2 nodes differed by
# 5.7e-14 after 294 iterations.
ONE_FACE_OCTAGON = (
    [
        (106.97854498677938, 351.25260615596625), (108.36320685594498, 351.5402022409167),
        (108.0756107709945, 352.9248641100823), (106.6909489018289, 352.63726802513185),
        (107.19482388013552, 349.9678036027798), (109.05964042888759, 352.0645335614305),
        (107.23533457316792, 353.18835425298283), (106.17948168425019, 352.917747388037),
        (106.17948168425019, 352.917747388037), (111.12970269482734, 350.45139809094786),
        (108.19538601016379, 355.350412273853), (105.26799237238944, 352.102581518899),
        (105.9487346767149, 350.06628111119915), (110.11621424835398, 350.49368919072),
        (110.428243936075, 355.02383471520073), (103.56939568116634, 353.5338650073891),
        (105.28354840017639, 348.6140158110483), (110.99305006716332, 350.82339057527213),
        (109.089541271455, 355.6418202174219), (104.45220876371218, 354.0666078741086),
        (104.23588052624162, 347.07196127067607), (112.54385174123517, 348.79753778037895),
        (110.81827523153227, 357.1055089953725), (102.51030401653871, 355.3799324856696),
    ],
    [
        [17, 21, 22, 18], [16, 20, 21], [12, 16, 17, 13, 14, 10, 9, 8], [17, 18, 19, 15, 14, 13],
        [7, 6, 5, 9, 10, 11], [7, 8, 4], [16, 12, 15, 19], [15, 12, 11, 10, 14], [8, 7, 11],
        [16, 21, 17], [8, 11, 12], [19, 18, 22, 23, 20, 16], [5, 4, 8, 9], [6, 2, 1, 5],
        [6, 7, 4, 0, 3, 2], [5, 1, 0, 4],
    ],
    EEGTParams(
        a=0.407678506143948, eta=2.761159663722, c=0.5, inverted_weight=9.844802316764822,
        max_untangle_iterations=294, max_smooth_iterations=44, distance_refresh=14,
        untangle="eegt", stall_iterations=22,
    ),
)

# bench/fuzz.py seed 0, case 1548 (a wheel of 13 triangles, tol 0): the device's q_avg was
# a different sum than NumPy's q.sum() (rows of 32 faces in order, then the rows pairwise,
# where NumPy adds a group's q pairwise with 8 partial sums, then the groups in order). One
# ulp decided the smoothing's stop: 4 smoothing iterations on NumPy, 116 on OpenCL.
WHEEL_TOL0 = (
    [
        (-1.2175641365296288, 0.12095000242683061), (-1.1780245452147793, 1.0111659826303239),
        (-1.6441361084660089, 0.9024095607644167), (-2.0063157714237927, 0.5894976874943755),
        (-2.1815925380425996, 0.14411470198949944), (-2.1298126134040842, -0.3317075212178763),
        (-1.8628381542271915, -0.7289638450703558), (-1.4418297917183343, -0.9566476332310214),
        (-0.9632354680275101, -0.962599273719363), (-0.5366953750254405, -0.7454553174245446),
        (-0.2599247076535388, -0.35496082786535454), (-0.19632829035858734, 0.11942661336894603),
        (-0.3604752959229468, 0.569030560479993), (-0.7147616235576862, 0.8908521674995832),
    ],
    [
        [3, 0, 2], [13, 1, 0], [0, 12, 13], [0, 8, 9], [0, 11, 12], [6, 7, 0], [5, 0, 4],
        [8, 0, 7], [4, 0, 3], [0, 10, 11], [1, 2, 0], [6, 0, 5], [0, 9, 10],
    ],
    EEGTParams(
        a=0.454860247418588, eta=2.93842281, c=0.164482389197, inverted_weight=3.9530179041074325,
        tol=0.0, max_untangle_iterations=26, max_smooth_iterations=116, distance_refresh=18,
        untangle="global", stall_iterations=39, polish_iterations=201, lift_rounds=10,
    ),
)


def test_bug_one_face_ngon_group_sums_pairwise(cpu_device):
    pts, faces, params = ONE_FACE_OCTAGON
    pts = np.array(pts)
    fs = as_faceset(faces, len(pts))
    assert [(g.n, g.size) for g in fs.groups if g.n >= 8] == [(8, 1)]
    ra, rb = run_both(pts, faces, None, params)
    assert_same_run(ra, rb)
    step_exact(pts, fs, free_nodes(len(pts), fs), params, 30, 10)


@pytest.mark.parametrize("n", [8, 9, 13, 16, 150])
def test_one_face_ngon_of_any_size_bit_identical(cpu_device, n):
    """A lone n-gon ringed by quads (n > 128: the pairwise split; n > 16: its own build)."""
    t = 2 * np.pi * np.arange(n) / n
    rng = np.random.default_rng(n)
    inner = np.column_stack([np.cos(t), np.sin(t)]) * (1 + 0.2 * rng.uniform(-1, 1, (n, 1)))
    pts = np.vstack([inner, 2.0 * np.column_stack([np.cos(t), np.sin(t)])])
    faces = [list(range(n))] + [[i, n + i, n + (i + 1) % n, (i + 1) % n] for i in range(n)]
    fs = as_faceset(faces, len(pts))
    assert [(g.n, g.size) for g in fs.groups] == [(4, n), (n, 1)]
    free = free_nodes(len(pts), fs)
    for scaling in ("edge", "area"):
        step_exact(pts, fs, free, EEGTParams(scaling=scaling, distance_refresh=2), 6, 4)


def test_bug_stats_q_avg_in_numpy_pairwise_order(cpu_device):
    pts, faces, params = WHEEL_TOL0
    ra, rb = run_both(np.array(pts), faces, None, params)
    assert_same_run(ra, rb)
    assert ra.smooth_iterations == rb.smooth_iterations


def block_sum(v) -> float:
    """pairwise_sum's base case as the kernels write it (np_block_sum, the quality blocks)."""
    v = [float(x) for x in v]
    if len(v) < 8:
        r = -0.0
        for x in v:
            r += x
        return r
    r = v[:8]
    i = 8
    while i < len(v) - len(v) % 8:
        r = [r[j] + v[i + j] for j in range(8)]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    return sum(v[i:], res)  # the rest in order


def pairwise(v) -> float:
    if len(v) <= 128:
        return block_sum(v)
    n2 = len(v) // 2 - (len(v) // 2) % 8
    return pairwise(v[:n2]) + pairwise(v[n2:])


def test_numpy_summation_orders_the_kernels_assume():
    """The orders the kernels and _SumPlan reproduce are NumPy's: X.sum(axis=0) of an (n, F)
    group in order for F > 1 and pairwise for F == 1; q.sum() pairwise per 8192-value buffer,
    buffers in order. If NumPy changes them, this says so before the parity tests do."""
    rng = np.random.default_rng(11)
    for n in (3, 5, 7, 8, 9, 12, 16, 17, 40, 150, 300):
        for F in (1, 2, 3):
            X = rng.standard_normal((n, F))
            seq = X[0].copy()
            for k in range(1, n):
                seq = seq + X[k]
            want = [0.0 + pairwise(X[:, 0])] if F == 1 else seq
            assert np.array_equal(X.sum(axis=0), want), (n, F)
    for n in (1, 7, 8, 100, 128, 129, 1000, 8191, 8192, 8193, 20000):
        q = rng.random(n) * (rng.random(n) < 0.8)
        plan = eo._SumPlan(n)
        blocks = [block_sum(q[a:b]) for a, b in zip(plan.bounds[:-1], plan.bounds[1:])]
        assert plan.total(np.array(blocks)) == q.sum(), n
        assert (np.diff(plan.bounds) <= 128).all() and plan.bounds[-1] == n


def big_ngon_mesh() -> tuple[np.ndarray, list[list[int]]]:
    """A 20-gon ringed by 20 quads (beyond the 16-corner n-gon kernel: its own build)."""
    k = 20
    t = 2 * np.pi * np.arange(k) / k
    inner = np.column_stack([np.cos(t), np.sin(t)])
    inner *= 1 + 0.3 * np.random.default_rng(3).uniform(-1, 1, (k, 1))
    pts = np.vstack([inner, 2.0 * np.column_stack([np.cos(t), np.sin(t)])])
    faces = [list(range(k))]
    faces += [[i, k + i, k + (i + 1) % k, (i + 1) % k] for i in range(k)]
    return pts, faces


def test_mixed_arity_with_a_big_ngon(device):
    pts, faces = big_ngon_mesh()
    fs = as_faceset(faces, len(pts))
    assert {g.n for g in fs.groups} == {4, 20}
    step_both(pts, fs, free_nodes(len(pts), fs), EEGTParams(), 10, 10)


def test_kernel_power_matches_fpmath_bits(device):
    """The kernels' fp_log / fp_exp / np_pow (mode 0) give core.fpmath's bits, subnormal,
    overflow and special inputs included."""
    from core import fpmath

    cl, rt = ort.import_cl(), ort.runtime()
    src = ocb.eegt_source() + """
    __kernel void probe(__global const double *x, const double e, __global double *out) {
        const int i = get_global_id(0);
        out[3 * i] = np_pow(x[i], e, 0);
        out[3 * i + 1] = fp_log(x[i]);
        out[3 * i + 2] = fp_exp(x[i]);
    }"""
    options = ["-DMAXN=16", "-DCH=32", "-DNCACHE=8", *ocb.fpmath_options()]
    prg = cl.Program(rt.ctx, src).build(options=options)
    rng = np.random.default_rng(5)
    special = [0.0, 5e-324, 1e-310, 2.2250738585072014e-308, 1.0, 0.5, np.inf, -1.0, np.nan]
    special += [709.78, 709.79, -745.1, -745.2, 1e308, -1e-300]
    x = np.concatenate(
        [rng.uniform(0, 1, 20000), 10.0 ** rng.uniform(-320, 308, 20000),
         rng.uniform(-800, 800, 20000), special]
    )
    mf = cl.mem_flags
    xb = cl.Buffer(rt.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=x)
    ob = cl.Buffer(rt.ctx, mf.WRITE_ONLY, 3 * x.nbytes)
    probe = cl.Kernel(prg, "probe")
    for e in (1.5, 2.7, 1.3, 0.1, 7.77, 250.0, -3.3):
        probe(rt.queue, (x.size,), None, xb, np.float64(e), ob)
        out = np.empty((x.size, 3))
        cl.enqueue_copy(rt.queue, out, ob)
        with np.errstate(all="ignore"):
            ref = np.column_stack([fpmath.power(x, e), fpmath.log(x), fpmath.exp(x)])
        same = (out == ref) | (np.isnan(out) & np.isnan(ref))
        for k, what in enumerate(("power", "log", "exp")):
            bad = np.flatnonzero(~same[:, k])
            got, want = out[bad[:3], k], ref[bad[:3], k]
            assert bad.size == 0, f"{what} e={e}: x={x[bad[:3]]}: {got} != {want}"


# ---- determinism, pinning, cancel ------------------------------------------------------


def test_two_runs_bit_identical(device):
    p, f = load2d("tri_two_holes")
    ra = untangle_and_smooth(p, f, backend="opencl")
    rb = untangle_and_smooth(p, f, backend="opencl")
    assert np.array_equal(ra.points, rb.points)
    assert ra.after == rb.after
    assert (ra.untangle_iterations, ra.smooth_iterations) == (
        rb.untangle_iterations,
        rb.smooth_iterations,
    )


def test_pinned_and_boundary_nodes_untouched(device):
    p, f = load2d("mixed_quad_tri")
    free = free_nodes(len(p), f)
    pinned = np.zeros(len(p), dtype=bool)
    pinned[np.flatnonzero(free)[::5]] = True
    res = untangle_and_smooth(p, f, fixed=pinned, backend="opencl")
    assert res.backend == "opencl"
    stay = ~res.moved
    assert stay.sum() > (~free).sum()
    assert np.array_equal(res.points[stay], p[stay])
    assert not np.array_equal(res.points[res.moved], p[res.moved])


@pytest.mark.parametrize("how", ["false", "raise"])
def test_cancel_via_progress(device, how):
    p, f = load2d("tri_two_holes")
    seen = []

    def progress(it, phase, stats):
        seen.append(it)
        if it == 3:
            if how == "raise":
                raise Cancelled
            return False
        return None

    res = untangle_and_smooth(p, f, params=EEGTParams(untangle="eegt"), backend="opencl",
                              progress=progress)
    assert res.status == "cancelled" and res.backend == "opencl"
    assert seen[-1] == 3
    assert np.array_equal(res.points, p)


# ---- fallbacks -------------------------------------------------------------------------


def numpy_result(name: str):
    p, f = load2d(name)
    return p, f, untangle_and_smooth(p, f, backend="numpy")


def assert_fallback_once(p, f, ref, backend: str, needle: str) -> None:
    """Two runs: both give NumPy's exact result and say why; the warning comes once."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r1 = untangle_and_smooth(p, f, backend=backend)
        r2 = untangle_and_smooth(p, f, backend=backend)
    for r in (r1, r2):
        assert r.backend.startswith("numpy (") and needle in r.backend, r.backend
        assert np.array_equal(r.points, ref.points)
    said = [w for w in caught if issubclass(w.category, RuntimeWarning)]
    assert len(said) == 1 and needle in str(said[0].message), [str(w.message) for w in said]


@pytest.mark.parametrize("backend", ["opencl", "auto"])
def test_fallback_when_pyopencl_missing(monkeypatch, backend):
    p, f, ref = numpy_result("mixed_quad_tri")
    monkeypatch.setitem(sys.modules, "pyopencl", None)  # import pyopencl -> ImportError
    cls, why = eo.available()
    assert cls is None and "pyopencl" in why
    assert eo.list_devices() == []
    assert_fallback_once(p, f, ref, backend, "pyopencl")


class _Dev:
    def __init__(self, name, kind, fp64=True, fault=None):
        self.name, self.type, self.fault = name, kind, fault  # fault: its compiler's error
        self.extensions = "cl_khr_byte_addressable_store" + (" cl_khr_fp64" if fp64 else "")
        self.double_fp_config = 63 if fp64 else 0


class _Plat:
    def __init__(self, name, devs):
        self.name, self._devs = name, devs

    def get_devices(self):
        return self._devs


def fake_cl(platforms=None, error: Exception | None = None, builds: list | None = None):
    """A stand-in for pyopencl: just what device discovery touches (a device's probe build
    fails with its `fault`; each build is appended to `builds`)."""
    kinds = types.SimpleNamespace(CPU=2, GPU=4, to_string=lambda t: {2: "CPU", 4: "GPU"}[t])

    def get_platforms():
        if error is not None:
            raise error
        return platforms or []

    def program(ctx, source):
        def build(options=None):
            (builds if builds is not None else []).append(ctx[0].name)
            if ctx[0].fault:
                raise RuntimeError(f"clBuildProgram failed: BUILD_PROGRAM_FAILURE\n{ctx[0].fault}")

        return types.SimpleNamespace(build=build)

    return types.SimpleNamespace(get_platforms=get_platforms, device_type=kinds, Error=Exception,
                                 Context=lambda devs: list(devs), CommandQueue=lambda ctx: None,
                                 Program=program)


def test_fallback_when_no_platform(monkeypatch):
    p, f, ref = numpy_result("mixed_quad_tri")
    err = RuntimeError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")
    monkeypatch.setattr(ort, "import_cl", lambda: fake_cl(error=err))
    cls, why = eo.available()
    assert cls is None and "no OpenCL platform" in why and "OCL_ICD_VENDORS" in why
    assert eo.list_devices() == []
    assert_fallback_once(p, f, ref, "auto", "no OpenCL platform")


def test_fallback_when_no_device_or_no_float64(monkeypatch):
    p, f, ref = numpy_result("mixed_quad_tri")
    monkeypatch.setattr(ort, "import_cl", lambda: fake_cl([_Plat("Empty", [])]))
    assert "no OpenCL device" in eo.available()[1]
    plats = [_Plat("Tiny", [_Dev("Half GPU", 4, fp64=False)])]
    monkeypatch.setattr(ort, "import_cl", lambda: fake_cl(plats))
    cls, why = eo.available()
    assert cls is None and "cl_khr_fp64" in why and "Half GPU" in why
    assert eo.list_devices() == [("0:0", "Half GPU (Tiny, GPU, no float64)")]
    assert_fallback_once(p, f, ref, "opencl", "cl_khr_fp64")


def test_fallback_when_chosen_device_missing(monkeypatch):
    p, f, ref = numpy_result("mixed_quad_tri")
    monkeypatch.setenv(eo.ENV_DEVICE, "no-such-device-xyz")
    cls, why = eo.available()
    assert cls is None and "no-such-device-xyz" in why
    assert_fallback_once(p, f, ref, "opencl", "no-such-device-xyz")


def test_auto_prefers_gpu_then_cpu_and_user_choice(monkeypatch):
    cpu, gpu = _Dev("Some CPU", 2), _Dev("Big GPU", 4)
    plats = [_Plat("P0", [cpu]), _Plat("P1", [_Dev("Old GPU", 4, fp64=False), gpu])]
    cl = fake_cl(plats)
    monkeypatch.delenv(eo.ENV_DEVICE, raising=False)
    assert ort.pick_device(cl)[0][2] is gpu
    monkeypatch.setenv(eo.ENV_DEVICE, "0:0")
    assert ort.pick_device(cl)[0][2] is cpu
    monkeypatch.setenv(eo.ENV_DEVICE, "big gpu")
    assert ort.pick_device(cl)[0][2] is gpu
    monkeypatch.setenv(eo.ENV_DEVICE, "old")
    entry, why = ort.pick_device(cl)
    assert entry is None and "cl_khr_fp64" in why
    monkeypatch.setattr(ort, "_device_override", None)
    eo.select_device("some cpu")  # the preferences' choice wins over the environment
    try:
        assert ort.pick_device(cl)[0][2] is cpu
    finally:
        eo.select_device(None)


def test_device_whose_compiler_fails_is_passed_over_and_named(monkeypatch):
    """pocl built with an LLVM older than the CPU lists a device that compiles nothing
    ("unknown target CPU 'generic'"): auto takes the next device, each probed once a process;
    with no other device, or that device asked for by name, the reason says why."""
    bad = "error: unknown target CPU 'generic'"
    cpu, gpu = _Dev("New CPU", 2, fault=bad), _Dev("Some GPU", 4)
    builds: list[str] = []
    cl = fake_cl([_Plat("P0", [cpu, gpu])], builds=builds)
    monkeypatch.delenv(eo.ENV_DEVICE, raising=False)
    assert ort.pick_device(cl)[0][2] is gpu
    gpu.type = 2  # now both CPUs: the first, which fails, is tried and passed over
    monkeypatch.setattr(ort, "_build_faults", {})
    builds.clear()
    assert ort.pick_device(cl)[0][2] is gpu and ort.pick_device(cl)[0][2] is gpu
    assert builds == ["New CPU", "Some GPU"]  # probed once each, not again
    monkeypatch.setenv(eo.ENV_DEVICE, "new cpu")
    entry, why = ort.pick_device(cl)
    assert entry is None and why == (
        "OpenCL device New CPU cannot build kernels (error: unknown target CPU 'generic'; the "
        "driver's compiler does not know this CPU: a newer OpenCL driver is needed); using NumPy")
    monkeypatch.delenv(eo.ENV_DEVICE)
    only = fake_cl([_Plat("P0", [_Dev("Odd GPU", 4, fault="error: no backend")])])
    entry, why = ort.pick_device(only)
    assert entry is None and why == "OpenCL device Odd GPU cannot build kernels (error: no " \
        "backend); using NumPy"


def test_fallback_when_no_device_can_build(monkeypatch):
    p, f, ref = numpy_result("mixed_quad_tri")
    plats = [_Plat("P0", [_Dev("New CPU", 2, fault="error: unknown target CPU 'generic'")])]
    monkeypatch.setattr(ort, "import_cl", lambda: fake_cl(plats))
    cls, why = eo.available()
    assert cls is None and "cannot build kernels" in why and "New CPU" in why
    assert_fallback_once(p, f, ref, "opencl", "cannot build kernels")
    monkeypatch.setattr(backends, "_warned", set())
    assert_fallback_once(p, f, ref, "auto", "cannot build kernels")


def test_fallback_when_kernel_build_fails(device, monkeypatch):
    p, f, ref = numpy_result("mixed_quad_tri")
    monkeypatch.setattr(ort, "runtimes", {})  # a fresh process: nothing built yet
    monkeypatch.setattr(ort, "eegt_source", lambda: "__kernel void broken( { syntax error")
    assert_fallback_once(p, f, ref, "opencl", "kernel build failed")


def test_kernels_built_once_per_device(device, monkeypatch):
    """Two engines with other parameters in a fresh process: one runtime, one build of the
    EEGT program, and the engines name the device of that runtime."""
    monkeypatch.setattr(ort, "runtimes", {})
    rt = ort.runtime()
    builds = []
    program = rt.cl.Program

    def counting_program(ctx, source):
        builds.append(len(source))
        return program(ctx, source)

    monkeypatch.setattr(rt.cl, "Program", counting_program)
    p, f = load2d("quad_hole")
    free = free_nodes(len(p), f)
    e1, _ = backends.make_engine("opencl", p, f, free, EEGTParams())
    e2, _ = backends.make_engine("opencl", p, f, free, EEGTParams(eta=1.0, scaling="area"))
    assert len(builds) == 1
    assert list(ort.runtimes.values()) == [rt]
    assert e1.prg is e2.prg and e1.rt is e2.rt is rt
    assert e1.device_name == e2.device_name == rt.name


def test_warm_up_builds_what_a_run_uses_and_the_run_reuses_it(device, monkeypatch):
    """warm_up makes the context, the EEGT kernels and the global stage's solver of a fresh
    process; the run that follows builds nothing more and gives the same bits."""
    import core.optimize.solver_parallel as sp

    p, f = load2d("tri_two_holes")
    ref = untangle_and_smooth(p, f, backend="auto")
    monkeypatch.setattr(ort, "runtimes", {})
    monkeypatch.setattr(sp, "_solvers", {})
    assert backends.warm_up("numpy") is None and ort.runtimes == {}
    assert backends.warm_up("auto") is None
    (rt,) = ort.runtimes.values()
    built = dict(rt.programs)
    # EEGT and parallel L-BFGS kernels, and on a CPU device the single-work-item one
    assert len(built) == (3 if rt.is_cpu else 2) and len(sp._solvers) == 1
    res = untangle_and_smooth(p, f, backend="auto")
    assert rt.programs == built and len(sp._solvers) == 1
    assert res.points.tobytes() == ref.points.tobytes() and res.after == ref.after


def test_warm_up_in_a_thread_while_a_run_starts_gives_the_same_run(device, monkeypatch):
    """A run that asks for the device while the warm-up thread is building waits for it:
    one runtime, each program built once, the run's bits unchanged."""
    import threading

    import core.optimize.solver_parallel as sp

    p, f = load2d("quad_hole")
    ref = untangle_and_smooth(p, f, backend="opencl")
    monkeypatch.setattr(ort, "runtimes", {})
    monkeypatch.setattr(sp, "_solvers", {})
    thread = threading.Thread(target=backends.warm_up, args=("opencl",))
    thread.start()
    res = untangle_and_smooth(p, f, backend="opencl")
    thread.join()
    assert len(ort.runtimes) == 1 and len(sp._solvers) == 1
    assert res.points.tobytes() == ref.points.tobytes()


def test_start_warm_up_only_for_runs_that_ask_for_the_device_engine(device):
    n = backends.AUTO_ENGINE_MIN_FACES
    assert backends.start_warm_up("numpy", 10**7) is None
    assert backends.start_warm_up("auto", n - 1) is None  # NumPy engine, device solver
    for backend, faces in (("auto", n), ("opencl", 10)):
        thread = backends.start_warm_up(backend, faces)
        assert thread is not None and thread.name == "eegt-warm-up"
        thread.join()


def test_large_auto_run_gets_the_device_ready_in_a_thread_with_the_same_bits(device,
                                                                            monkeypatch):
    """A fresh process's 'auto' run of 10k faces starts the warm-up in a thread of its own
    (before it checks its input), builds each program once and gives the bits of a run on a
    warm device."""
    import threading

    import core.optimize.solver_parallel as sp

    p, f = load2d("tri_two_holes")
    assert f.n_faces >= backends.AUTO_ENGINE_MIN_FACES
    ref = untangle_and_smooth(p, f, backend="auto")
    for thread in threading.enumerate():  # no earlier warm-up may still be building
        if thread.name == "eegt-warm-up":
            thread.join()
    monkeypatch.setattr(ort, "runtimes", {})
    monkeypatch.setattr(sp, "_solvers", {})
    callers, builds = [], []
    warm_up, program = backends.warm_up, ort.import_cl().Program

    def recording_warm_up(*args):
        callers.append(threading.current_thread().name)
        return warm_up(*args)

    def counting_program(ctx, source):
        builds.append(source)
        return program(ctx, source)

    monkeypatch.setattr(backends, "warm_up", recording_warm_up)
    monkeypatch.setattr(ort.import_cl(), "Program", counting_program)
    res = untangle_and_smooth(p, f, backend="auto")
    (rt,) = ort.runtimes.values()
    assert callers == ["eegt-warm-up"] and len(sp._solvers) == 1
    assert len(builds) == len(rt.programs) == (3 if rt.is_cpu else 2)
    assert res.points.tobytes() == ref.points.tobytes() and res.after == ref.after


def test_warm_up_says_why_without_raising(monkeypatch):
    monkeypatch.setenv(eo.ENV_DEVICE, "no-such-device-xyz")
    assert "no-such-device-xyz" in backends.warm_up("opencl")
    monkeypatch.setitem(sys.modules, "pyopencl", None)
    assert "pyopencl" in backends.warm_up("auto")


# ---- per-face targets --------------------------------------------------------------------


def random_targets(faces, rng, bad: float = 0.05, aspect=(0.2, 3.0)) -> np.ndarray:
    """Per-corner targets: each face's regular polygon stretched (by a factor in `aspect`),
    turned, jittered, moved and scaled at random; a fraction `bad` unusable (NaN, or a corner
    made concave)."""
    fs = faces if isinstance(faces, FaceSet) else as_faceset(faces, 1 + max(map(max, faces)))
    out = np.empty((fs.n_corners, 2))
    for a, b in zip(fs.offsets[:-1], fs.offsets[1:]):
        n = b - a
        t = 2 * np.pi * np.arange(n) / n
        shape = np.column_stack([np.cos(t), rng.uniform(*aspect) * np.sin(t)])
        shape += 0.05 * rng.standard_normal((n, 2))
        c, s = np.cos(rng.uniform(0, 7)), np.sin(rng.uniform(0, 7))
        shape = shape @ np.array([[c, -s], [s, c]]).T
        out[a:b] = rng.uniform(0.1, 10) * shape + rng.uniform(-5, 5, 2)
        roll = rng.random()
        if roll < bad / 2:
            out[a] = np.nan
        elif roll < bad:
            out[a] = out[a:b].mean(axis=0)  # corner a at the centroid: its neighbours cave in
    return out


@pytest.mark.parametrize(
    "name", ["quad_hole", "tri_two_holes", "mixed_quad_tri", "polygon_voronoi", "two_holes_twist"]
)
def test_targets_bit_identical_on_shared_meshes(cpu_device, name):
    p, f = load2d(name)
    T = random_targets(f, np.random.default_rng(len(name)))
    assert 0 < prepare_targets(T, f).n_fallback < f.n_faces
    step_exact(p, f, free_nodes(len(p), f), EEGTParams(distance_refresh=3), 12, 8, T)
    step_exact(p, f, free_nodes(len(p), f), EEGTParams(scaling="area", eta=1.7, c=1.3), 6, 4, T)


@pytest.mark.parametrize("n", [3, 5, 8, 20, 150])
def test_targets_one_face_ngon_bit_identical(cpu_device, n):
    """A lone n-gon (a group of one face: pairwise corner sums; n > 16: its own build; a
    lone triangle: the scalar triangle kernels) ringed by quads, with targets."""
    t = 2 * np.pi * np.arange(n) / n
    rng = np.random.default_rng(n)
    inner = np.column_stack([np.cos(t), np.sin(t)]) * (1 + 0.2 * rng.uniform(-1, 1, (n, 1)))
    pts = np.vstack([inner, 2.0 * np.column_stack([np.cos(t), np.sin(t)])])
    faces = [list(range(n))] + [[i, n + i, n + (i + 1) % n, (i + 1) % n] for i in range(n)]
    fs = as_faceset(faces, len(pts))
    T = random_targets(faces, rng, bad=0.0)
    step_exact(pts, fs, free_nodes(len(pts), fs), EEGTParams(distance_refresh=2), 6, 4, T)


@pytest.mark.slow
@settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(case=fuzz_cases(), seed=st.integers(0, 2**32 - 1))
def test_fuzz_pipeline_with_targets_bit_identical(cpu_device, case, seed):
    """Whole runs with random targets (some unusable) on both backends: same bits, counts,
    stats and fallback count; and a few engine steps bit for bit."""
    pts, faces, pinned, params = case
    T = random_targets(faces, np.random.default_rng(seed), bad=0.1)
    both = run_both(pts, faces, pinned, params, T)
    if both is None:
        return
    ra, rb = both
    assert_same_run(ra, rb)
    assert ra.n_target_fallback == rb.n_target_fallback
    fs = as_faceset(faces, len(pts))
    step_exact(pts, fs, ra.moved, params, 4, 4, T)


def test_targets_pipeline_same_result_on_opencl(device):
    p, f = load2d("mixed_quad_tri")
    T = random_targets(f, np.random.default_rng(4), aspect=(0.7, 1.4))
    params = EEGTParams(untangle="eegt", polish_iterations=0, lift_rounds=0)
    ra = untangle_and_smooth(p, f, params=params, targets=T, backend="numpy")
    rb = untangle_and_smooth(p, f, params=params, targets=T, backend="opencl")
    assert rb.backend == "opencl" and ra.status == rb.status == "untangled"
    assert (ra.untangle_iterations, ra.smooth_iterations) == (
        rb.untangle_iterations, rb.smooth_iterations)
    assert_close(ra.points, rb.points, float(np.ptp(p, axis=0).max()), "targets")
    assert ra.n_target_fallback == rb.n_target_fallback > 0


# ---- restarts (the pipeline's `_adopt`) ---------------------------------------------------


@pytest.mark.parametrize("name, params", [
    ("tri_two_holes", EEGTParams()),
    ("mixed_quad_tri", EEGTParams(distance_refresh=3)),
    ("polygon_voronoi", EEGTParams(c=1.5, eta=2.7)),
])
def test_restarted_engine_equals_numpy_restart_and_fresh_engine(cpu_device, name, params):
    """OpenCLEngine.restarted keeps its device tables and refreshes the distances on the
    device in its first step: every later step is the bits of NumpyEngine.restarted and of a
    new OpenCL engine built at the same points (whose distances the host computed)."""
    p, f = load2d(name)
    free = free_nodes(len(p), f)
    ref = NumpyEngine(p, f, free, params)
    eng, _ = backends.make_engine("opencl", p, f, free, params)
    for _ in range(4):
        ref.step("untangle")
        eng.step("untangle")
    moved = ref.points()
    rng = np.random.default_rng(3)
    scale = float(np.ptp(p, axis=0).max())
    moved[free] += rng.uniform(-2e-3, 2e-3, (int(free.sum()), 2)) * scale  # "the optimizer"
    ref, eng = ref.restarted(moved), eng.restarted(moved)
    fresh, _ = backends.make_engine("opencl", moved, f, free, params)
    assert eng.stats() == ref.stats() == fresh.stats()
    assert eng.lbar == ref.lbar == fresh.lbar
    for it in range(7):
        phase = "untangle" if it < 3 else "smooth"
        sa, sb, sc = ref.step(phase), eng.step(phase), fresh.step(phase)
        a, b, c = ref.points(), eng.points(), fresh.points()
        assert np.array_equal(a, b), f"step {it + 1}: restarted OpenCL engine left NumPy's bits"
        assert np.array_equal(b, c), f"step {it + 1}: restarted and fresh OpenCL engines differ"
        assert sa == sb == sc


def test_restarted_engine_moves_nothing_on_a_fixed_boundary(cpu_device):
    """Fixed rows stay the input's bits after a restart; a second restart of the restarted
    engine works the same way."""
    p, f = load2d("quad_hole")
    free = free_nodes(len(p), f)
    eng, _ = backends.make_engine("opencl", p, f, free, EEGTParams())
    eng.step("untangle")
    again = eng.restarted(eng.points()).restarted(p)
    again.step("untangle")
    out = again.points()
    assert np.array_equal(out[~free], p[~free])
    assert np.any(out[free] != p[free])


def test_a_run_whose_free_nodes_are_all_held_as_hopeless_gives_numpys_answer(device):
    """A boundary node dragged through the far side of a strip: its part is certified
    hopeless and every free node held (core/run/hopeless_winding.py). The device has nothing
    to move; the run fails at once as on NumPy instead of asking for empty buffers."""
    p, f = spiked_strip()
    ref = untangle_and_smooth(p, f, backend="numpy")
    res = untangle_and_smooth(p, f, backend="opencl")
    assert res.status == ref.status == "failed"
    assert np.array_equal(res.points, ref.points) and res.message == ref.message
