"""The UI path's worker thread: progress, cancel (ESC) leaves the mesh untouched."""

from __future__ import annotations

import pytest

from .conftest import import_obj, positions

pytestmark = pytest.mark.blender


def test_worker_runs_and_cancels(bpy, ext):
    ops = ext.operators.shared.run_mixin
    runner = ext.operators.mesh.runner
    obj = import_obj(bpy, "quad_hole")
    params = ext.core.EEGTParams()
    job = runner.prepare(obj)
    w = ops._Worker([job], params, "numpy", None, runner.compute)
    w.thread.start()
    w.thread.join(timeout=60)
    assert not w.thread.is_alive() and w.error is None
    assert job.result.status == "untangled" and job.new_co is not None
    assert w.iteration > 0 and w.phase == "smooth" and w.n_inverted == 0

    # ESC sets `cancel` while the thread runs: the next progress call stops the core and
    # nothing is left to write (ESC is simulated at iteration 3, deterministically)
    before = positions(obj)
    job = runner.prepare(obj)
    w = ops._Worker([job], params, "numpy", None, runner.compute)
    own_progress = w._progress

    def esc_at_3(iteration, phase, stats):
        if iteration >= 3:
            w.cancel = True
        return own_progress(iteration, phase, stats)

    w._progress = esc_at_3
    w.thread.start()
    w.thread.join(timeout=30)
    assert not w.thread.is_alive() and w.error is None
    assert job.result.status == "cancelled" and job.new_co is None
    res = runner.apply(obj, job)
    assert res.status == "cancelled" and not res.written
    assert (positions(obj) == before).all()
