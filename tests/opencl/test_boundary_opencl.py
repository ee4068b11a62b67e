"""Boundary modes on the OpenCL engine: the same bits as NumPy (a CPU device), step by step
(the projection kernel, the moved flag, the parameter going back with a reverted node) and
for whole runs (the global stage runs on the host with sliding nodes)."""

from __future__ import annotations

import numpy as np
import pytest
from meshdata import load2d

from bench.fuzz import make_case
from core.eegt import backends
from core.eegt.boundary import boundary_motion
from core.eegt.engine_numpy import NumpyEngine
from core.mesh.faces import as_faceset
from core.params import EEGTParams
from core.run.pipeline import untangle_and_smooth

eo = pytest.importorskip("core.eegt.engine_opencl")
ort = pytest.importorskip("core.opencl.runtime")


@pytest.fixture(scope="module")
def cpu_device() -> str:
    cls, why = eo.available()
    if cls is None:
        pytest.skip(f"no usable OpenCL device: {why}")
    if not ort.runtime().is_cpu:
        pytest.skip("bit-identity is promised on CPU devices")
    return ort.runtime().name


def step_exact(p, f, fixed, params, n_untangle: int, n_smooth: int) -> int:
    """NumPy and OpenCL engines side by side, positions, parameters and stats
    bit-identical every step; returns how many smoothing steps sent a sliding node back."""
    fs = as_faceset(f, len(p))
    motion = boundary_motion(p, fs, fixed, params.boundary, params.feature_angle)
    ref = NumpyEngine(p, fs, motion.movable, params, None, motion)
    eng, name = backends.make_engine("opencl", p, fs, motion.movable, params, None, motion)
    assert name == "opencl", name
    reverted = 0
    revert = ref._revert_inverted

    def counting(old_x, old_y):  # did a sliding node go back in this step?
        nonlocal reverted
        before = ref.x.copy()
        revert(old_x, old_y)
        if ref.slide is not None:
            reverted += int(np.any(ref.x[ref.slide.node] != before[ref.slide.node]))

    ref._revert_inverted = counting
    for it in range(n_untangle + n_smooth):
        phase = "untangle" if it < n_untangle else "smooth"
        sa, sb = ref.step(phase), eng.step(phase)
        a, b = ref.points(), eng.points()
        if not np.array_equal(a, b):
            rows = np.flatnonzero(np.any(a != b, axis=1))
            pytest.fail(f"iteration {it + 1} ({phase}): {rows.size} nodes differ")
        assert sa == sb, f"iteration {it + 1} ({phase}): {sa} != {sb}"
        if ref.slide is not None:
            tau = np.empty(ref.slide.size)
            eng.cl.enqueue_copy(eng.queue, tau, eng.tau)
            assert np.array_equal(tau, ref.tau), f"iteration {it + 1}: parameters differ"
    return reverted


@pytest.mark.parametrize("name", ["quad_hole", "mixed_quad_tri", "tri_two_holes",
                                  "polygon_voronoi", "two_holes_twist"])
@pytest.mark.parametrize("mode", ["slide", "free"])
def test_boundary_modes_step_bit_identical_on_shared_meshes(cpu_device, name, mode):
    p, f = load2d(name)
    n = step_exact(p, f, None, EEGTParams.paper().with_(boundary=mode), 25, 15)
    n += step_exact(p, f, None, EEGTParams(boundary=mode, distance_refresh=3, scaling="area",
                                           feature_angle=10.0), 8, 8)
    if mode == "slide" and name in ("tri_two_holes", "two_holes_twist"):
        assert n > 0  # smoothing sent sliding nodes back (their parameters too) on both


def test_free_mode_without_anchors_bit_identical(cpu_device):
    """No fixed node at all: uniform distance weights on both engines."""
    p, f = load2d("quad_hole")
    step_exact(p, f, None, EEGTParams.paper().with_(boundary="free", c=1.5), 10, 10)


@pytest.mark.parametrize("index", range(24))
def test_boundary_modes_whole_runs_bit_identical(cpu_device, index):
    """Random small meshes (bench.fuzz: jittered boundaries, pins, n-gons) in both modes."""
    case = make_case(11, index)
    mode = ("slide", "free")[index % 2]
    params = EEGTParams(**case["params"]).with_(boundary=mode,
                                                 feature_angle=float(10 + 7 * index))
    out = []
    for backend in ("numpy", "opencl"):
        try:
            out.append(untangle_and_smooth(case["points"], case["faces"], case["fixed"], params,
                                           backend=backend))
        except ValueError as exc:
            out.append(str(exc))
    ra, rb = out
    if isinstance(ra, str) or isinstance(rb, str):
        assert ra == rb
        return
    assert rb.backend == "opencl"
    assert np.array_equal(ra.points, rb.points), (ra.message, rb.message)
    assert (ra.status, ra.after, ra.untangle_iterations, ra.smooth_iterations,
            ra.global_iterations) == (rb.status, rb.after, rb.untangle_iterations,
                                      rb.smooth_iterations, rb.global_iterations)


def dragged_grid(drag: int = 1, onto: int = 0) -> tuple[np.ndarray, list]:
    """5 x 5 unit quads (nodes row by row, 6 a row) with boundary node `drag` moved onto its
    loop neighbour `onto`: a stack that only sliding can open."""
    xs, ys = np.meshgrid(np.arange(6.0), np.arange(6.0))
    p = np.column_stack([xs.ravel(), ys.ravel()])
    p[drag] = p[onto]
    return p, [[6 * j + i, 6 * j + i + 1, 6 * j + i + 7, 6 * j + i + 6]
               for j in range(5) for i in range(5)]


@pytest.mark.parametrize("drag, onto", [(1, 0), (6, 0), (2, 1), (3, 4)])
def test_stacked_boundary_nodes_slide_bit_identical(cpu_device, drag, onto):
    """A node dragged onto its neighbour: the engines step the stack apart with the same
    bits, and whole slide runs agree (the global stage lets the stack's nodes slide)."""
    p, f = dragged_grid(drag, onto)
    step_exact(p, f, None, EEGTParams.paper().with_(boundary="slide"), 10, 10)
    for untangle in ("auto", "eegt"):
        params = EEGTParams(boundary="slide", untangle=untangle)
        ra = untangle_and_smooth(p, f, params=params)
        rb = untangle_and_smooth(p, f, params=params, backend="opencl")
        assert ra.status == "untangled" and ra.after.n_inverted == 0, ra.message
        assert rb.backend == "opencl" and np.array_equal(ra.points, rb.points)
        assert (ra.status, ra.after, ra.untangle_iterations, ra.smooth_iterations,
                ra.global_iterations) == (rb.status, rb.after, rb.untangle_iterations,
                                          rb.smooth_iterations, rb.global_iterations)
