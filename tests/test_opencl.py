"""OpenCL backend: parity with the NumPy reference, determinism, fallbacks, device choice.

Tests that need a real float64 OpenCL device (pocl's CPU device is enough) skip, saying why,
when none exists; the fallback and device-choice tests use stub modules and always run.
"""

from __future__ import annotations

import sys
import types
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core import backends
from core.engine_numpy import NumpyEngine
from core.faces import FaceSet, as_faceset
from core.obj_io import read_obj
from core.params import EEGTParams
from core.pipeline import Cancelled, free_nodes, untangle_and_smooth
from core.planar import untangle_and_smooth_3d

eo = pytest.importorskip("core.engine_opencl")

DATA = Path(__file__).resolve().parent / "data"
PLANAR = ["quad_hole", "tri_two_holes", "naca_deform", "mixed_quad_tri", "polygon_voronoi"]
PLANAR += ["two_holes_twist"]
REL = 1e-12


@pytest.fixture(scope="module")
def device() -> str:
    """Skip unless a float64 OpenCL device is usable; returns its description."""
    cls, why = eo.available()
    if cls is None:
        pytest.skip(f"no usable OpenCL device: {why}")
    return eo._runtime().name


@pytest.fixture(autouse=True)
def _fresh_warnings(monkeypatch):
    """Each test sees the 'said once' fallback messages afresh."""
    monkeypatch.setattr(backends, "_warned", set())


def load2d(name: str) -> tuple[np.ndarray, FaceSet]:
    v, f = read_obj(DATA / f"{name}.obj")
    return v[:, :2].copy(), f


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


def step_exact(p, f, free, params, n_untangle: int, n_smooth: int) -> None:
    """Step NumPy and OpenCL engines side by side: positions bit-identical every step."""
    ref = NumpyEngine(p, f, free, params)
    eng, name = backends.make_engine("opencl", p, f, free, params)
    assert name == "opencl", name
    for it in range(n_untangle + n_smooth):
        phase = "untangle" if it < n_untangle else "smooth"
        ref.step(phase)
        eng.step(phase)
        a, b = ref.points(), eng.points()
        if not np.array_equal(a, b):
            rows = np.flatnonzero(np.any(a != b, axis=1))
            d = float(np.abs(a - b).max())
            pytest.fail(f"iteration {it + 1} ({phase}): {rows.size} nodes differ (max {d:.3e})")


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
def test_general_powers_bit_identical_on_shared_meshes(device, name, c, eta):
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
    assert ra.after == rb.after or ra.after.n_inverted == rb.after.n_inverted
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
    v, f = read_obj(DATA / "tilted_plane.obj")
    ra = untangle_and_smooth_3d(v, f, backend="numpy")
    rb = untangle_and_smooth_3d(v, f, backend="opencl")
    assert rb.backend == "opencl"
    assert (ra.untangle_iterations, ra.smooth_iterations) == (
        rb.untangle_iterations,
        rb.smooth_iterations,
    )
    assert_close(ra.points, rb.points, float(np.ptp(v, axis=0).max()), "tilted plane")


@st.composite
def polygon_meshes(draw):
    """A jittered m x n grid of quads, some split into triangles, some pairs merged into
    hexagons; every face counterclockwise before the jitter, which may invert some."""
    m = draw(st.integers(3, 7))
    n = draw(st.integers(3, 7))
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
    if not free.any():
        return
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
def test_general_powers_bit_identical_on_random_meshes(device, mesh, c, eta):
    pts, faces, pinned = mesh
    fs = as_faceset(faces, len(pts))
    free = free_nodes(len(pts), fs, pinned)
    if not free.any():
        return
    step_exact(pts, fs, free, EEGTParams(c=c, eta=eta, distance_refresh=2), 10, 6)


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

    cl, rt = eo._import_cl(), eo._runtime()
    src = eo.kernel_source() + """
    __kernel void probe(__global const double *x, const double e, __global double *out) {
        const int i = get_global_id(0);
        out[3 * i] = np_pow(x[i], e, 0);
        out[3 * i + 1] = fp_log(x[i]);
        out[3 * i + 2] = fp_exp(x[i]);
    }"""
    options = ["-DMAXN=16", "-DCH=32", "-DNCACHE=8", *eo.fpmath_options()]
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
    def __init__(self, name, kind, fp64=True):
        self.name, self.type = name, kind
        self.extensions = "cl_khr_byte_addressable_store" + (" cl_khr_fp64" if fp64 else "")
        self.double_fp_config = 63 if fp64 else 0


class _Plat:
    def __init__(self, name, devs):
        self.name, self._devs = name, devs

    def get_devices(self):
        return self._devs


def fake_cl(platforms=None, error: Exception | None = None):
    """A stand-in for pyopencl: just what device discovery touches."""
    kinds = types.SimpleNamespace(CPU=2, GPU=4, to_string=lambda t: {2: "CPU", 4: "GPU"}[t])

    def get_platforms():
        if error is not None:
            raise error
        return platforms or []

    return types.SimpleNamespace(get_platforms=get_platforms, device_type=kinds, Error=Exception)


def test_fallback_when_no_platform(monkeypatch):
    p, f, ref = numpy_result("mixed_quad_tri")
    err = RuntimeError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")
    monkeypatch.setattr(eo, "_import_cl", lambda: fake_cl(error=err))
    cls, why = eo.available()
    assert cls is None and "no OpenCL platform" in why and "OCL_ICD_VENDORS" in why
    assert eo.list_devices() == []
    assert_fallback_once(p, f, ref, "auto", "no OpenCL platform")


def test_fallback_when_no_device_or_no_float64(monkeypatch):
    p, f, ref = numpy_result("mixed_quad_tri")
    monkeypatch.setattr(eo, "_import_cl", lambda: fake_cl([_Plat("Empty", [])]))
    assert "no OpenCL device" in eo.available()[1]
    plats = [_Plat("Tiny", [_Dev("Half GPU", 4, fp64=False)])]
    monkeypatch.setattr(eo, "_import_cl", lambda: fake_cl(plats))
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
    assert eo._pick_device(cl)[0][2] is gpu
    monkeypatch.setenv(eo.ENV_DEVICE, "0:0")
    assert eo._pick_device(cl)[0][2] is cpu
    monkeypatch.setenv(eo.ENV_DEVICE, "big gpu")
    assert eo._pick_device(cl)[0][2] is gpu
    monkeypatch.setenv(eo.ENV_DEVICE, "old")
    entry, why = eo._pick_device(cl)
    assert entry is None and "cl_khr_fp64" in why
    monkeypatch.setattr(eo, "_device_override", None)
    eo.select_device("some cpu")  # the preferences' choice wins over the environment
    try:
        assert eo._pick_device(cl)[0][2] is cpu
    finally:
        eo.select_device(None)


def test_fallback_when_kernel_build_fails(device, monkeypatch):
    p, f, ref = numpy_result("mixed_quad_tri")
    monkeypatch.setattr(eo, "_runtimes", {})  # a fresh process: nothing built yet
    monkeypatch.setattr(eo, "kernel_source", lambda: "__kernel void broken( { syntax error")
    assert_fallback_once(p, f, ref, "opencl", "kernel build failed")


def test_kernels_built_once_per_device(device):
    p, f = load2d("quad_hole")
    free = free_nodes(len(p), f)
    e1, _ = backends.make_engine("opencl", p, f, free, EEGTParams())
    e2, _ = backends.make_engine("opencl", p, f, free, EEGTParams(eta=1.0, scaling="area"))
    assert e1.prg is e2.prg and e1.rt is e2.rt
    assert device in e1.device_name or e1.device_name == device
