"""The global stage's L-BFGS on an OpenCL device: bit-identical to the host solver.

Needs a float64 OpenCL device (pocl's CPU device is enough); skips, saying why, without one.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from meshdata import load2d, spun_hole

from core.mesh.faces import as_faceset
from core.optimize import GlobalOptions, lift_min_quality, untangle_global
from core.optimize.energy import LiftEnergy
from core.optimize.solver import lbfgs
from core.optimize.stages import EPS_MIN
from core.optimize.state import TICK_EVERY, State
from core.params import EEGTParams
from core.run.pipeline import Cancelled, free_nodes, untangle_and_smooth

eo = pytest.importorskip("core.eegt.engine_opencl")
ort = pytest.importorskip("core.opencl.runtime")
lo = pytest.importorskip("core.optimize.solver_opencl")
from solver_recorder import Recorder  # noqa: E402  (same folder)
from test_opencl import big_ngon_mesh, polygon_meshes  # noqa: E402  (same folder)


@pytest.fixture(scope="module")
def solver():
    cls, why = eo.available()
    if cls is None:
        pytest.skip(f"no usable OpenCL device: {why}")
    return lo.OpenCLLbfgs()


def mesh(name: str):
    p, f = load2d(name)
    fs = as_faceset(f, len(p))
    groups = fs.by_arity()
    return p, fs, groups, free_nodes(len(p), fs)


SHARED = ["quad_hole", "mixed_quad_tri", "polygon_voronoi", "tri_two_holes"]


@pytest.mark.parametrize("name", SHARED)
def test_untangle_and_lift_bit_identical_to_host_call_by_call(solver, name):
    """Both energies (foldover-free with eps continuation, and the lift's with its sub-meshes),
    triangles (one corner each: corner counts not a multiple of 4), quads and n-gons."""
    p, _fs, groups, free = mesh(name)
    host, dev = Recorder(lbfgs), Recorder(solver)
    outs = []
    for rec in (host, dev):
        u, info = untangle_global(p, groups, free, GlobalOptions(polish_iter=300, solver=rec))
        lifted, linfo = lift_min_quality(u, groups, free, GlobalOptions(lift_rounds=10, solver=rec))
        outs.append((u, lifted, info["iterations"], linfo["iterations"]))
    assert info["status"] == "untangled" and linfo["iterations"] > 0
    assert len(host.results) == len(dev.results) >= 3
    for k, ((vh, ih), (vd, idv)) in enumerate(zip(host.results, dev.results, strict=True)):
        assert ih == idv, f"call {k}: {ih} host iterations, {idv} on the device"
        assert np.array_equal(vh, vd), f"call {k}: max difference {np.abs(vh - vd).max():.3e}"
    (u0, l0, i0, j0), (u1, l1, i1, j1) = outs
    assert np.array_equal(u0, u1) and np.array_equal(l0, l1) and (i0, j0) == (i1, j1)


def test_ticks_pause_and_cancel_like_the_host(solver):
    """A tick every TICK_EVERY iterations, showing the host's current point; False stops at
    that iteration with its point."""
    p, _fs, groups, free = mesh("quad_hole")
    u, _ = untangle_global(p, groups, free, GlobalOptions(polish_iter=0))
    en, st = LiftEnergy(u, groups, free), State(u, free)
    en.qc = 0.5
    v0 = st.pack(st.x, st.y)
    seen = {"host": [], "dev": []}
    points = {"host": [], "dev": []}
    res = {}
    for key, run in (("host", lbfgs), ("dev", solver)):

        def tick(it, point, key=key):
            seen[key].append(it)
            points[key].append(point())
            return it < 2 * TICK_EVERY

        res[key] = run(en, st, v0, EPS_MIN, max_it=150, guard=True, rel_tol=0.0, tick=tick)
    assert seen["host"] == seen["dev"] == [TICK_EVERY, 2 * TICK_EVERY]
    assert res["host"][1] == res["dev"][1] == 2 * TICK_EVERY
    assert np.array_equal(res["host"][0], res["dev"][0])
    assert all(np.array_equal(a, b) for a, b in zip(points["host"], points["dev"], strict=True))
    assert np.array_equal(points["dev"][-1], res["dev"][0])  # the point it stopped at
    assert not np.array_equal(points["dev"][0], points["dev"][1])  # the iterate moved


def test_powered_energy_falls_back_to_the_host_solver(solver):
    """polish_power != 1 is not in the kernel: the host solver runs, same result."""
    p, _fs, groups, free = mesh("quad_hole")
    a, ia = untangle_global(p, groups, free, GlobalOptions(polish_iter=40, polish_power=2.0))
    options = GlobalOptions(polish_iter=40, polish_power=2.0, solver=solver)
    b, ib = untangle_global(p, groups, free, options)
    assert np.array_equal(a, b) and ia["iterations"] == ib["iterations"] > 0


@pytest.mark.parametrize("name", ["quad_hole", "mixed_quad_tri", "polygon_voronoi"])
def test_pipeline_opencl_equals_numpy_bit_for_bit(solver, name):
    """Global stage on the device, EEGT on the device: the NumPy run's points exactly."""
    p, fs, _groups, _free = mesh(name)
    ra = untangle_and_smooth(p, fs, backend="numpy")
    rb = untangle_and_smooth(p, fs, backend="opencl")
    assert rb.backend == "opencl" and rb.after.n_inverted == 0
    assert ra.global_iterations == rb.global_iterations > 0
    assert np.array_equal(ra.points, rb.points)


def test_pipeline_cancel_during_device_global_stage(solver):
    """Cancelling from a progress tick of the device solver leaves the input unchanged."""
    p, fs, _groups, _free = mesh("quad_hole")
    phases = []

    def progress(it, phase, stats):
        phases.append(phase)
        if phase == "global" and it >= 40:
            raise Cancelled

    res = untangle_and_smooth(p, fs, backend="opencl", progress=progress)
    assert res.status == "cancelled" and "global" in phases
    assert np.array_equal(res.points, p)


def test_device_solver_failure_falls_back_to_host(monkeypatch):
    """A kernel that does not build: one warning, the host solver, the same result."""
    from core.optimize import solver_parallel
    from core.optimize.device import solver_for

    def broken():
        raise RuntimeError("L-BFGS kernel build failed on test device: line 1:1: boom")

    monkeypatch.setattr(solver_parallel, "device_solver", broken)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        solver = solver_for("opencl")
    assert solver is None
    assert any("global stage on NumPy" in str(w.message) for w in caught)
    assert solver_for("numpy") is None


def test_auto_small_mesh_numpy_steps_device_global_stage_same_result(solver):
    """'auto' under AUTO_ENGINE_MIN_FACES: NumPy EEGT steps, device global stage, and still
    the NumPy run's points bit for bit; at or above it, the OpenCL engine."""
    from core.eegt import backends

    p, fs, _groups, _free = mesh("quad_hole")
    ra = untangle_and_smooth(p, fs, backend="numpy")
    rb = untangle_and_smooth(p, fs, backend="auto")
    assert fs.n_faces < backends.AUTO_ENGINE_MIN_FACES
    assert rb.backend == backends.HYBRID
    assert np.array_equal(ra.points, rb.points) and ra.global_iterations == rb.global_iterations
    p, fs, _groups, _free = mesh("tri_two_holes")
    assert fs.n_faces >= backends.AUTO_ENGINE_MIN_FACES
    eng, name = backends.make_engine("auto", p, fs, free_nodes(len(p), fs), EEGTParams())
    assert name == "opencl" and type(eng).__name__ == "OpenCLEngine"


def test_device_solver_keeps_no_tables_after_a_run(solver):
    """The per-process solvers forget a run's energies and device tables when it ends."""
    from core.optimize import solver_parallel

    p, fs, _groups, _free = mesh("quad_hole")
    res = untangle_and_smooth(p, fs, backend="opencl")
    assert res.global_iterations > 0
    parallel = solver_parallel.device_solver()
    assert parallel._last is None and parallel.small is not None and parallel.small._last is None


@settings(
    max_examples=8,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(case=polygon_meshes())
def test_random_polygon_meshes_with_pins_bit_identical(solver, case):
    """Random tri/quad/hexagon meshes, some pinned nodes, some inverted faces: the device
    global stage (untangling, polish, lift) equals the host's."""
    pts, faces, pinned = case
    fs = as_faceset(faces, len(pts))
    free = free_nodes(len(pts), fs, pinned)
    assume(free.any())
    groups = fs.by_arity()
    host = untangle_global(pts, groups, free, GlobalOptions(polish_iter=100))
    dev = untangle_global(pts, groups, free, GlobalOptions(polish_iter=100, solver=solver))
    assert np.array_equal(host[0], dev[0]) and host[1]["iterations"] == dev[1]["iterations"]
    if host[1]["status"] == "untangled":
        a = lift_min_quality(host[0], groups, free, GlobalOptions(lift_rounds=3))
        b = lift_min_quality(host[0], groups, free, GlobalOptions(lift_rounds=3, solver=solver))
        assert np.array_equal(a[0], b[0]) and a[1]["iterations"] == b[1]["iterations"]


@pytest.mark.parametrize("what", ["20-gon", "one free node"])
def test_big_ngon_and_single_free_node(solver, what):
    """A 20-gon (20 corners in one element) and a mesh with one free node (2 unknowns,
    corner arrays padded from fewer than 4 corners on a triangle fan) match the host."""
    if what == "20-gon":
        pts, faces = big_ngon_mesh()
        pts = pts.copy()
        pts[0] += 0.3  # push a free inner node further off
    else:
        ang = np.linspace(0.0, 2 * np.pi, 7)[:-1]
        pts = np.vstack([np.column_stack([np.cos(ang), np.sin(ang)]), [[0.5, 0.2]]])
        faces = [[k, (k + 1) % 6, 6] for k in range(6)]
    fs = as_faceset(faces, len(pts))
    free = free_nodes(len(pts), fs)
    groups = fs.by_arity()
    host = untangle_global(pts, groups, free, GlobalOptions(polish_iter=50))
    dev = untangle_global(pts, groups, free, GlobalOptions(polish_iter=50, solver=solver))
    assert host[1]["iterations"] > 0 and np.array_equal(host[0], dev[0])
    a = lift_min_quality(host[0], groups, free, GlobalOptions(lift_rounds=2))
    b = lift_min_quality(host[0], groups, free, GlobalOptions(lift_rounds=2, solver=solver))
    assert np.array_equal(a[0], b[0])


def test_auto_small_mesh_on_a_gpu_runs_numpy_and_says_so(solver, monkeypatch):
    """With a GPU device, 'auto' on a small mesh is NumPy throughout (the device solver is
    for CPU devices) and its name does not claim OpenCL."""
    from core.eegt import backends

    monkeypatch.setattr(backends, "_device_is_cpu", lambda: False)
    p, fs, _groups, _free = mesh("quad_hole")
    res = untangle_and_smooth(p, fs, backend="auto")
    assert res.backend == backends.SMALL_ON_GPU and not res.backend.startswith("opencl")
    assert np.array_equal(res.points, untangle_and_smooth(p, fs, backend="numpy").points)


def test_on_a_gpu_every_global_solve_runs_on_the_parallel_kernels(solver, monkeypatch):
    """On a non-CPU device there is no single-work-item solver (it would be one GPU thread):
    the parallel kernels solve every problem, and an 'opencl' run still gives NumPy's bits."""
    from core.optimize import solver_parallel

    monkeypatch.setattr(ort.Runtime, "is_cpu", property(lambda self: False))
    assert lo.device_solver() is None
    gpu = solver_parallel.device_solver()
    assert gpu.small is None and gpu.small_corners == 0
    p, fs, _groups, _free = mesh("quad_hole")
    res = untangle_and_smooth(p, fs, backend="opencl")
    assert res.backend == "opencl" and res.global_iterations > 0
    assert np.array_equal(res.points, untangle_and_smooth(p, fs, backend="numpy").points)


def test_target_factors_bit_identical_to_host(solver):
    """Per-corner target factors (the faces' own shapes stretched 1 x 2): the device solver
    reads them per corner, the same bits as the host, both energies."""
    from core.metrics.targets import corner_factors

    p, fs, groups, free = mesh("mixed_quad_tri")
    T = p[fs.indices] * [1.0, 2.0]
    factors = corner_factors(T, fs)
    outs = []
    for run in (lbfgs, solver):
        opt = GlobalOptions(polish_iter=100, lift_rounds=3, solver=run)
        u, info = untangle_global(p, groups, free, opt, factors=factors)
        lifted, linfo = lift_min_quality(u, groups, free, opt, factors=factors)
        outs.append((u, lifted, info["iterations"], linfo["iterations"]))
    (uh, lh, ih, jh), (ud, ld, idv, jd) = outs
    assert info["status"] == "untangled" and jh > 0
    assert np.array_equal(uh, ud) and np.array_equal(lh, ld) and (ih, jh) == (idv, jd)


def test_harmonic_restart_bit_identical_to_host(solver):
    """The restart from the harmonic start (core.run.harmonic, host) runs its global stage on
    the device solver: the same points as the NumPy run."""
    pts, groups = spun_hole(8, 48, 270, True)
    prm = EEGTParams(max_untangle_iterations=200, polish_iterations=50)
    ref = untangle_and_smooth(pts, groups[3], params=prm, backend="numpy")
    got = untangle_and_smooth(pts, groups[3], params=prm, backend="opencl")
    assert ref.status == "untangled" and ref.global_iterations > 250
    assert np.array_equal(got.points, ref.points)
