"""The global stage's parallel L-BFGS (core/optimize/solver_parallel.py): bit-identical to the host
solver for every energy, argument and path, whatever the work-group size and lane count.

Needs a float64 OpenCL device (pocl's CPU device is enough); skips, saying why, without one.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from meshdata import load2d

from bench.meshgen import holed_square
from core.mesh.faces import as_faceset
from core.optimize import GlobalOptions, lift_min_quality, untangle_global
from core.optimize.energy import FoldoverEnergy, LiftEnergy
from core.optimize.solver import lbfgs
from core.optimize.stages import EPS_MIN
from core.optimize.state import State
from core.run.pipeline import free_nodes

eo = pytest.importorskip("core.eegt.engine_opencl")
ort = pytest.importorskip("core.opencl.runtime")
lp = pytest.importorskip("core.optimize.solver_parallel")
from solver_recorder import Recorder  # noqa: E402  (same folder)
from test_opencl import big_ngon_mesh, polygon_meshes  # noqa: E402  (same folder)


@pytest.fixture(scope="module")
def device() -> None:
    cls, why = eo.available()
    if cls is None:
        pytest.skip(f"no usable OpenCL device: {why}")


@pytest.fixture(scope="module")
def solver(device):
    return lp.ParallelLbfgs()


def mesh(name: str):
    p, f = load2d(name)
    fs = as_faceset(f, len(p))
    return p, fs.by_arity(), free_nodes(len(p), fs)


def run_stage(p, groups, free, run, polish_iter=300, lift_rounds=10):
    """untangle_global, then lift_min_quality on its result, through the solver `run`."""
    u, info = untangle_global(p, groups, free, GlobalOptions(polish_iter=polish_iter, solver=run))
    lifted, linfo = lift_min_quality(u, groups, free,
                                     GlobalOptions(lift_rounds=lift_rounds, solver=run))
    return u, info, lifted, linfo


def assert_same_calls(host: Recorder, dev: Recorder) -> None:
    assert len(host.results) == len(dev.results)
    for k, ((vh, ih), (vd, idv)) in enumerate(zip(host.results, dev.results, strict=True)):
        assert ih == idv, f"call {k}: {ih} host iterations, {idv} on the device"
        assert np.array_equal(vh, vd), f"call {k}: max difference {np.abs(vh - vd).max():.3e}"


def assert_same_runs(a, b) -> None:
    (ua, ia, la, ja), (ub, ib, lb, jb) = a, b
    assert np.array_equal(ua, ub) and np.array_equal(la, lb)
    skip = {"seconds", "seconds_per_iter"}
    assert {k: v for k, v in ia.items() if k not in skip} == {
        k: v for k, v in ib.items() if k not in skip
    }
    assert {k: v for k, v in ja.items() if k != "seconds"} == {
        k: v for k, v in jb.items() if k != "seconds"
    }


SHARED = ["quad_hole", "mixed_quad_tri", "polygon_voronoi", "tri_two_holes", "two_holes_twist"]


@pytest.mark.parametrize("name", SHARED)
def test_untangle_and_lift_bit_identical_to_host_call_by_call(solver, name):
    """Both energies (foldover-free with its eps continuation, unguarded then guarded, and
    the lift's with its sub-meshes and floor), triangles, quads and n-gons: every solve gives
    the host's point and iteration count, and the stages the host's points and info."""
    p, groups, free = mesh(name)
    host, dev = Recorder(lbfgs), Recorder(solver)
    a = run_stage(p, groups, free, host)
    b = run_stage(p, groups, free, dev)
    assert a[1]["status"] == "untangled" and a[3]["iterations"] > 0
    assert len(host.results) >= 3
    assert_same_calls(host, dev)
    assert_same_runs(a, b)


def test_naca_deform_untangles_bit_identically(solver):
    """The hardest shared mesh (hundreds of unguarded iterations, many eps rounds)."""
    p, groups, free = mesh("naca_deform")
    a = untangle_global(p, groups, free, GlobalOptions(polish_iter=100))
    b = untangle_global(p, groups, free, GlobalOptions(polish_iter=100, solver=solver))
    assert a[1]["iterations"] == b[1]["iterations"] > 100
    assert np.array_equal(a[0], b[0])


@pytest.mark.parametrize(
    "lanes, local_size", [(1, 64), (8, 16), (2, None), (4, 256)], ids=str
)
def test_result_does_not_depend_on_lanes_or_work_group_size(device, lanes, local_size):
    """A generated mesh whose vectors and corner arrays span several 8192-term chunks (so
    the chunk kernel and irregular last chunks run): the host's bits with every lane count
    and work-group size."""
    p, fs = holed_square(20_000, seed=3)
    groups, free = fs.by_arity(), free_nodes(len(p), fs)
    en = FoldoverEnergy(p, groups, free)
    assert en.i0.size > 2 * lp.CHUNK and 2 * int(free.sum()) > 2 * lp.CHUNK
    solver = lp.ParallelLbfgs(lanes=lanes, local_size=local_size)
    a = untangle_global(p, groups, free, GlobalOptions(max_iter=150, polish_iter=40))
    b = untangle_global(p, groups, free, GlobalOptions(max_iter=150, polish_iter=40,
                                                          solver=solver))
    assert a[1]["iterations"] == b[1]["iterations"] > 40
    assert np.array_equal(a[0], b[0])
    la = lift_min_quality(a[0], groups, free, GlobalOptions(lift_rounds=2))
    lb = lift_min_quality(a[0], groups, free, GlobalOptions(lift_rounds=2, solver=solver))
    assert la[1]["iterations"] == lb[1]["iterations"] > 0
    assert np.array_equal(la[0], lb[0])


# ---- NumPy's pairwise sum on the device ---------------------------------------------------

PROBE = r"""
__kernel void probe_leaf(__global const int *PI, __global double *PD, __global const double *x)
{
    const Plan pl = plan_of(PI, PD);
    LEAF_HEAD(pl)
    double mn = INFINITY;
    LEAF_SUMS(1, pl,
        mn = MIN_NAN(mn, x[k]);
        t[0] = x[k];)
    pl.PMIN[w] = mn;
}

__kernel void probe_total(__global const int *PI, __global double *PD, __global double *out)
{
    const Plan pl = plan_of(PI, PD);
    out[0] = total(&pl, 0);
    out[1] = total_min(&pl);
}
"""


def device_sum(rt, prg, lanes: int, x: np.ndarray, local_size: int) -> tuple[float, float]:
    """(np.add.reduce(x), np.min(x)) as the solver's kernels compute them."""
    cl, mf = rt.cl, rt.cl.mem_flags
    plan = lp._Plan(SimpleNamespace(lanes=lanes), x.size, 1)

    def buf(a):
        return cl.Buffer(rt.ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=a)

    PI, X = buf(plan.ints.astype(np.int32)), buf(x)
    PD = cl.Buffer(rt.ctx, mf.READ_WRITE, 8 * plan.pd_len)
    out = np.zeros(2)
    OUT = buf(out)
    leaf, chunk, fin = (cl.Kernel(prg, k) for k in ("probe_leaf", "chunk_sums", "probe_total"))
    leaf.set_args(PI, PD, X)
    chunk.set_args(PI, PD, np.int32(1), np.int32(1))
    fin.set_args(PI, PD, OUT)
    gs = -(-plan.leaf_items // local_size) * local_size
    cl.enqueue_nd_range_kernel(rt.queue, leaf, (gs,), (local_size,))
    if lanes > 1:  # a work-group of 64 per chunk, always
        cl.enqueue_nd_range_kernel(rt.queue, chunk, (64 * plan.n_chunks,), (64,))
    elif plan.n_chunks > 1:  # a work-item per chunk; one chunk: the finish walks it
        cl.enqueue_nd_range_kernel(rt.queue, chunk, (plan.n_chunks,), None)
    cl.enqueue_nd_range_kernel(rt.queue, fin, (1,), (1,))
    cl.enqueue_copy(rt.queue, out, OUT)
    return float(out[0]), float(out[1])


@pytest.mark.parametrize("lanes", [1, 2, 8])
def test_device_sums_are_numpys_pairwise_sums_bit_for_bit(device, lanes):
    """Leaves, chunk trees and the chunks in order: np.add.reduce's bits for lengths around
    every boundary of NumPy's scheme (8, 128, 8192), on values spanning 30 decades where any
    other order of additions gives other bits; the minimum with NumPy's NaN rule."""
    rt = ort.runtime()
    src = lp.kernel_source() + PROBE
    prg = rt.cl.Program(rt.ctx, src).build(options=lp.build_options(lanes))
    rng = np.random.default_rng(lanes)
    sizes = [1, 5, 8, 9, 15, 127, 128, 129, 136, 1000, 8191, 8192, 8193, 8200, 20_000, 70_001]
    other = 0
    for n in sizes:
        x = rng.standard_normal(n) * np.exp(rng.uniform(-35.0, 35.0, n))
        s, m = device_sum(rt, prg, lanes, x, local_size=16)
        assert s == float(np.add.reduce(x)), n
        assert m == float(np.min(x)), n
        other += float(np.cumsum(x)[-1]) != s  # a sequential sum: another result
        if n > 9:
            x[n // 3] = np.nan
            s, m = device_sum(rt, prg, lanes, x, local_size=16)
            assert np.isnan(s) and np.isnan(m)
    assert other >= 8  # the data tells the summation orders apart


def test_reduction_plan_cuts_like_numpy():
    """Leaves of at most 128 terms, full chunks of 64 leaves, chunk starts at multiples of
    8192, and the leaves of an irregular last chunk where NumPy's halving puts them."""
    bounds, first = lp.reduction_plan(8192 * 2 + 300)
    assert np.all(np.diff(bounds) <= 128) and bounds[-1] == 8192 * 2 + 300
    assert list(bounds[first[:-1]]) == [0, 8192, 16384]
    # 300 -> 144 | 156; 144 -> 72 | 72; 156 -> 72 | 84
    assert list(bounds[first[2] :] - 16384) == [0, 72, 144, 216, 300]
    assert lp.reduction_plan(5)[0].tolist() == [0, 5]


def test_sweep_and_first_touch_are_permutations():
    """The memory orders (corner sweep, node places) are permutations whatever the input:
    random corners, repeated and unused nodes, NaN positions, fewer than two corners."""
    rng = np.random.default_rng(5)
    for n in (1, 2, 7, 500):
        nodes = rng.integers(0, n, 3 * n)
        pos, order = lp._first_touch(nodes, n + 3)  # three nodes never touched
        assert np.array_equal(np.sort(order), np.arange(n + 3))
        assert np.array_equal(pos[order], np.arange(n + 3))
        _, first = np.unique(nodes, return_index=True)
        assert np.array_equal(order[: first.size], nodes[np.sort(first)])
        xy = rng.random((n, 2))
        xy[0] = np.nan
        corners = [rng.integers(0, n, 2 * n) for _ in range(3)]
        assert np.array_equal(np.sort(lp._sweep_order(xy[:, 0], xy[:, 1], *corners)),
                              np.arange(2 * n))
    assert lp._sweep_order(np.zeros(3), np.zeros(3), *(np.array([1]),) * 3).tolist() == [0]


# ---- solver paths --------------------------------------------------------------------------


def test_ticks_pause_and_cancel_like_the_host(solver):
    """A tick every tick_every iterations; False stops at that iteration with its point."""
    p, groups, free = mesh("quad_hole")
    u, _ = untangle_global(p, groups, free, GlobalOptions(polish_iter=0))
    for en in (LiftEnergy(u, groups, free), FoldoverEnergy(u, groups, free)):
        st = State(u, free)
        en.qc = 0.5
        v0 = st.pack(st.x, st.y)
        seen: dict[str, list[int]] = {"host": [], "dev": []}
        points: dict[str, list[np.ndarray]] = {"host": [], "dev": []}
        res = {}
        for key, run in (("host", lbfgs), ("dev", solver)):

            def tick(it, point, calls=seen[key], at=points[key], stop=2 * en.tick_every):
                calls.append(it)
                at.append(point())
                return it < stop

            res[key] = run(en, st, v0, EPS_MIN, max_it=150, guard=True, rel_tol=0.0,
                           tick=tick)
        assert seen["host"] == seen["dev"] == [en.tick_every, 2 * en.tick_every]
        assert res["host"][1] == res["dev"][1] == 2 * en.tick_every
        assert np.array_equal(res["host"][0], res["dev"][0])
        # the ticks show the current point, the host's bits, the last one the point returned
        assert all(np.array_equal(a, b) for a, b in zip(points["host"], points["dev"],
                                                         strict=True))
        assert np.array_equal(points["dev"][-1], res["dev"][0])
        assert not np.array_equal(points["dev"][0], points["dev"][1])


def test_untangle_progress_cancel_bit_identical(solver):
    """untangle_global's progress callback cancelling from inside a device solve: the same
    status, iterations and points as the host."""
    p, groups, free = mesh("tri_two_holes")
    out = []
    for run in (None, solver):
        calls = []

        def progress(it, total, n_inv, current, calls=calls):
            calls.append((it, n_inv, current().tobytes()))
            return it < 90

        res = untangle_global(p, groups, free, GlobalOptions(solver=run), progress=progress)
        out.append((res, calls))
    (a, ca), (b, cb) = out
    assert a[1]["status"] == b[1]["status"] == "cancelled" and ca == cb
    assert a[1]["iterations"] == b[1]["iterations"] and np.array_equal(a[0], b[0])


def test_max_it_and_every_stop_rule_match(solver):
    """max_it 0, 1 and 7, rel_tol that stops at once, guard off on a valid mesh (stops after
    one iteration): the host's iterations and points."""
    p, groups, free = mesh("mixed_quad_tri")
    u, _ = untangle_global(p, groups, free, GlobalOptions(polish_iter=0))
    en, st = FoldoverEnergy(u, groups, free), State(u, free)
    v0 = st.pack(st.x, st.y)
    cases = [
        {"max_it": 0, "guard": True},
        {"max_it": 1, "guard": True},
        {"max_it": 7, "guard": True, "rel_tol": 0.0},
        {"max_it": 50, "guard": True, "rel_tol": 0.5},
        {"max_it": 50, "guard": False},
    ]
    for kw in cases:
        a = lbfgs(en, st, v0, EPS_MIN, **kw)
        b = solver(en, st, v0, EPS_MIN, **kw)
        assert a[1] == b[1] and np.array_equal(a[0], b[0]), kw


def test_lift_from_an_invalid_point_restarts_and_stops_like_the_host(solver):
    """The lift energy at a point with an inverted corner: infinite energy, no gradient, so
    the direction is no descent even after the restart: one iteration, the start point."""
    p, groups, free = mesh("quad_hole")
    en, st = LiftEnergy(p, groups, free), State(p, free)
    en.qc = 0.3
    v0 = st.pack(st.x, st.y)
    assert en.n_inverted(st.x, st.y) > 0
    a = lbfgs(en, st, v0, EPS_MIN, max_it=20, guard=True)
    b = solver(en, st, v0, EPS_MIN, max_it=20, guard=True)
    assert a[1] == b[1] == 1 and np.array_equal(a[0], b[0]) and np.array_equal(b[0], v0)


@pytest.mark.slow
@settings(
    max_examples=6,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(case=polygon_meshes())
def test_random_polygon_meshes_with_pins_bit_identical(solver, case):
    """Random tri/quad/hexagon meshes, some pinned nodes, some inverted faces: untangling,
    polish and lift give the host's points and iterations."""
    pts, faces, pinned = case
    fs = as_faceset(faces, len(pts))
    free = free_nodes(len(pts), fs, pinned)
    assume(free.any())
    groups = fs.by_arity()
    a = run_stage(pts, groups, free, None, polish_iter=100, lift_rounds=3)
    b = run_stage(pts, groups, free, solver, polish_iter=100, lift_rounds=3)
    assert_same_runs(a, b)


@pytest.mark.parametrize("what", ["20-gon", "one free node"])
def test_big_ngon_and_single_free_node(solver, what):
    """A 20-gon (20 corners in one element) and a mesh with one free node (2 unknowns, 6
    corners: vectors far shorter than one leaf) match the host."""
    if what == "20-gon":
        pts, faces = big_ngon_mesh()
        pts = pts.copy()
        pts[0] += 0.3
    else:
        ang = np.linspace(0.0, 2 * np.pi, 7)[:-1]
        pts = np.vstack([np.column_stack([np.cos(ang), np.sin(ang)]), [[0.5, 0.2]]])
        faces = [[k, (k + 1) % 6, 6] for k in range(6)]
    fs = as_faceset(faces, len(pts))
    groups, free = fs.by_arity(), free_nodes(len(pts), fs)
    a = run_stage(pts, groups, free, None, polish_iter=50, lift_rounds=2)
    b = run_stage(pts, groups, free, solver, polish_iter=50, lift_rounds=2)
    assert a[1]["iterations"] > 0
    assert_same_runs(a, b)


# ---- fallbacks and lifetime -----------------------------------------------------------------


def test_powered_energy_falls_back_to_the_host_solver(solver):
    """polish_power != 1 is not in the kernels: the host solver runs, same result."""
    p, groups, free = mesh("quad_hole")
    a, ia = untangle_global(p, groups, free, GlobalOptions(polish_iter=40, polish_power=2.0))
    options = GlobalOptions(polish_iter=40, polish_power=2.0, solver=solver)
    b, ib = untangle_global(p, groups, free, options)
    assert np.array_equal(a, b) and ia["iterations"] == ib["iterations"] > 0


def test_tables_beyond_32_bit_indices_fall_back_to_the_host(solver, monkeypatch):
    """Indices the kernels cannot address (the limit lowered to this mesh's size): the host
    solver runs, same result, and no tables are kept."""
    p, groups, free = mesh("quad_hole")
    monkeypatch.setattr(lp, "INDEX_LIMIT", 64)
    solver.release()
    a = untangle_global(p, groups, free, GlobalOptions(polish_iter=40))
    b = untangle_global(p, groups, free, GlobalOptions(polish_iter=40, solver=solver))
    assert np.array_equal(a[0], b[0]) and a[1]["iterations"] == b[1]["iterations"] > 0
    assert solver._last is None


def test_release_forgets_tables_and_factory_caches_per_setting(device):
    p, groups, free = mesh("quad_hole")
    s = lp.device_solver(small_corners=0)
    assert lp.device_solver(small_corners=0) is s
    assert lp.device_solver(lanes=8, small_corners=0) is not s
    untangle_global(p, groups, free, GlobalOptions(polish_iter=10, solver=s))
    assert s._last is not None
    s.release()
    assert s._last is None
    with pytest.raises(ValueError, match="lanes"):
        lp.ParallelLbfgs(lanes=3)


def test_small_problems_go_to_the_small_solver_same_result(device):
    """Under small_corners energy corners the delegate solves (on CPU devices the factory's
    is the single-work-item kernel); above, the parallel kernels; the host's bits either
    way."""
    p, groups, free = mesh("mixed_quad_tri")
    n_corners = FoldoverEnergy(p, groups, free).i0.size
    calls = []

    def small(*args, **kw):
        calls.append(args[0].i0.size)
        return lbfgs(*args, **kw)

    s = lp.ParallelLbfgs(small=small, small_corners=n_corners)  # the whole mesh: parallel
    a = untangle_global(p, groups, free, GlobalOptions(polish_iter=30))
    b = untangle_global(p, groups, free, GlobalOptions(polish_iter=30, solver=s))
    assert np.array_equal(a[0], b[0]) and not calls and s._last is not None
    la = lift_min_quality(a[0], groups, free, GlobalOptions(lift_rounds=4))
    # the lift's sub-meshes are small: the single-work-item kernel solves them
    lb = lift_min_quality(a[0], groups, free, GlobalOptions(lift_rounds=4, solver=s))
    assert np.array_equal(la[0], lb[0]) and calls and max(calls) < n_corners
    if ort.runtime().is_cpu:
        factory = lp.device_solver()
        assert factory.small_corners == lp.SMALL_CORNERS
        assert type(factory.small).__name__ == "OpenCLLbfgs"


def test_step_limit_kernel_is_the_host_limit_and_skips_like_it(solver):
    """limit_corner/finish_limit against FoldoverEnergy.step_limit and skipped_trials on a
    jittered mesh: the same limit bits, the same first step and skip count."""
    from core.optimize.state import skipped_trials

    p, f = load2d("tri_two_holes")
    fs = as_faceset(f, len(p))
    groups, free = fs.by_arity(), free_nodes(len(p), fs)
    en = LiftEnergy(p, groups, free)
    st = State(p, free)
    tb = solver._tables_for(en, st)
    rng = np.random.default_rng(5)
    v = st.pack(st.x, st.y)
    layout, fixed = en.packed(st)
    cl, queue = solver.cl, solver.queue
    for scale in (1e-4, 1e-2, 1.0):
        q = rng.normal(0.0, scale, v.size)
        z = np.concatenate([v, fixed])
        dz = np.zeros(z.size)
        dz[: v.size] = q
        want = en.step_limit(z, dz, layout[0], 1.0)
        s = np.zeros_like(solver._S_host)
        s[lp._S_GUARD], s[7] = 1.0, 1.0  # guarded, first step 1
        cl.enqueue_copy(queue, solver.S, s)
        cl.enqueue_copy(queue, tb.v, v)
        cl.enqueue_copy(queue, tb.q, q)
        solver._go("place", tb.n2 // 2)  # the point in Z: v
        skip = solver._limit(tb)
        lim = np.empty(tb.nc)
        cl.enqueue_copy(queue, lim, tb.LIM)
        assert float(lim.min()) == want
        step, k = skipped_trials(1.0, want)
        assert (skip, float(solver._rb[7])) == (k, step)
    solver.release()


def test_lift_on_a_large_jittered_mesh_bit_identical_with_fewer_trials(solver, monkeypatch):
    """The case the limit is for: the lift's whole-mesh run on a just-untangled 20k mesh,
    where unit steps fold some corner; the device run keeps the host's bits."""
    p, fs = holed_square(20_000, seed=3)
    groups, free = fs.by_arity(), free_nodes(len(p), fs)
    u, _ = untangle_global(p, groups, free, GlobalOptions(polish_iter=0))
    trials = []
    original = solver._trial
    monkeypatch.setattr(solver, "_trial", lambda *a: trials.append(1) or original(*a))
    host = Recorder(lbfgs)
    dev = Recorder(solver)
    opts = dict(lift_first_iter=60, lift_rounds=3, lift_chunk=10, lift_rel_tol=1e-4)
    a, _ = lift_min_quality(u, groups, free, GlobalOptions(solver=host, **opts))
    b, _ = lift_min_quality(u, groups, free, GlobalOptions(solver=dev, **opts))
    assert np.array_equal(a, b)
    assert_same_calls(host, dev)
    its = sum(i for _, i in dev.results)
    assert len(trials) < 2 * its, (len(trials), its)


def test_device_repair_computes_the_step_limit_after_the_same_iterations_as_the_host(
        device, monkeypatch):
    """A repair ("folds", target "keep") whose lift's trials mostly miss sufficient decrease
    (after which a limit skips nothing), every solve on the parallel solver: the host's
    points, and the device computes the limit exactly as often as the host (after an
    iteration with a trial rejected for a det <= 0: `state.folded_trial`)."""
    from bench.repair_meshes import Spec, make
    from core import EEGTParams, untangle_and_smooth
    from core.run import pipeline

    c = make(Spec("ogridtri", 1000, "slide", {"dx": 0.2, "reach": 0.2}))
    params = EEGTParams(region="folds", target="keep")
    host_limits, dev_limits = [], []
    host_limit = FoldoverEnergy.step_limit
    monkeypatch.setattr(FoldoverEnergy, "step_limit",
                        lambda *a, **k: host_limits.append(1) or host_limit(*a, **k))
    host = untangle_and_smooth(c.points, c.faces, fixed=c.fixed, params=params)
    n_host = len(host_limits)
    everywhere = lp.ParallelLbfgs(small_corners=0)  # every problem on it, however small
    device_limit = everywhere._limit
    monkeypatch.setattr(everywhere, "_limit",
                        lambda *a: dev_limits.append(1) or device_limit(*a))
    monkeypatch.setattr(pipeline, "solver_for", lambda *a, **k: everywhere)
    dev = untangle_and_smooth(c.points, c.faces, fixed=c.fixed, params=params)
    assert np.array_equal(host.points, dev.points)
    assert host.global_iterations == dev.global_iterations
    assert len(host_limits) == n_host  # no solve of the device run went to the host
    assert 0 < len(dev_limits) == n_host, (len(dev_limits), n_host)
    everywhere.release()


def test_device_lift_holds_no_host_corner_scratch(solver, monkeypatch):
    """A lift whose solves run on the device (whole-mesh run and rounds) never makes the
    host's per-corner scratch (its measures work in pieces), and keeps the host's bits."""
    from core.optimize import energy as energy_mod

    p, fs = holed_square(20_000, seed=3)
    groups, free = fs.by_arity(), free_nodes(len(p), fs)
    u, _ = untangle_global(p, groups, free, GlobalOptions(polish_iter=0))
    made = []
    real = energy_mod._Blocks
    monkeypatch.setattr(energy_mod, "_Blocks", lambda *a: made.append(a[0]) or real(*a))
    opts = dict(lift_first_iter=60, lift_rounds=3, lift_chunk=10, lift_rel_tol=1e-4)
    b, info = lift_min_quality(u, groups, free, GlobalOptions(solver=solver, **opts))
    assert made == [] and info["rounds"] >= 1
    a, _ = lift_min_quality(u, groups, free, GlobalOptions(**opts))
    assert made and np.array_equal(a, b)  # the host's run evaluates on its scratch
