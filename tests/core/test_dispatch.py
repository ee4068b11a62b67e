"""The one rule that picks the global stage's L-BFGS (core/optimize/dispatch.py): which runs
may use a device, which problems the kernels take, and where the single-work-item kernel's
share ends; and the line-search constants the kernels receive as build defines."""

from __future__ import annotations

import numpy as np
from meshdata import load2d

from core import choices
from core.mesh.faces import as_faceset
from core.opencl.build import cl_defines
from core.optimize import dispatch
from core.optimize.energy import FoldoverEnergy
from core.optimize.solver import lbfgs
from core.optimize.state import ARMIJO, CURVATURE, TRIALS, State, line_search_defines
from core.run.pipeline import free_nodes


def quad_hole():
    p, f = load2d("quad_hole")
    fs = as_faceset(f, len(p))
    free = free_nodes(len(p), fs)
    en = FoldoverEnergy(p, fs.by_arity(), free)
    return en, State(p, free)


def test_only_opencl_runs_without_sliding_nodes_use_a_device():
    assert dispatch.uses_device(choices.OPENCL_ENGINE, sliding=False)
    assert dispatch.uses_device(choices.HYBRID, sliding=False)
    assert not dispatch.uses_device(choices.OPENCL_ENGINE, sliding=True)
    assert not dispatch.uses_device(choices.NUMPY_ENGINE, sliding=False)
    assert not dispatch.uses_device(choices.SMALL_ON_GPU, sliding=False)


def test_a_label_starting_with_opencl_does_not_make_a_device_run():
    """The device is chosen by the engine's name, never by a label's prefix."""
    assert not dispatch.uses_device("opencl (global stage) + numpy", sliding=False)


def test_stages_run_the_host_solver_with_sliding_nodes_or_no_device_solver():
    def device(*args, **kw):
        raise AssertionError("not called")

    assert dispatch.solver_to_run(None, sliding=False) is lbfgs
    assert dispatch.solver_to_run(device, sliding=True) is lbfgs
    assert dispatch.solver_to_run(device, sliding=False) is device


def test_route_sends_small_problems_to_the_single_kernel_and_the_rest_in_parallel():
    en, st = quad_hole()
    n = en.i0.size
    assert n > 100
    assert dispatch.route(en, st, small=n + 1) == "single"
    assert dispatch.route(en, st, small=n) == "parallel"  # n corners: not under n
    assert dispatch.route(en, st, small=0) == "parallel"
    en.power = 2.0  # a powered polish is not in the kernels
    assert dispatch.route(en, st, small=n + 1) == "host"
    assert dispatch.on_host(en, st)


def test_single_kernel_share_is_cpu_devices_only():
    assert dispatch.single_kernel_corners(is_cpu=True) == dispatch.SMALL_CORNERS == 20_000
    assert dispatch.single_kernel_corners(is_cpu=False) == 0


def test_line_search_defines_are_the_exact_python_doubles():
    defs = line_search_defines()
    assert defs == {"TRIALS": 40, "ARMIJO": 1e-4, "CURVATURE": 1e-12}
    assert ARMIJO == 1e-4 and CURVATURE == 1e-12 and TRIALS == 40
    opts = cl_defines(defs)
    assert opts[0] == "-DTRIALS=40"
    for opt, value in zip(opts[1:], (ARMIJO, CURVATURE), strict=True):
        assert float.fromhex(opt.split("=(")[1].rstrip(")")) == value
    assert np.float64(ARMIJO).hex() == opts[1].split("=(")[1].rstrip(")")
