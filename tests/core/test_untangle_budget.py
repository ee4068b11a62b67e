"""The optimizer's untangling budget grows with the mesh's width beyond BUDGET_NODES free
nodes (its eps rounds do too), so a fold at 100k elements gets the rounds it needs."""

from __future__ import annotations

import math

import numpy as np

from core import EEGTParams, pipeline, untangle_and_smooth
from core.optimize import untangle_budget
from core.optimize.stages import BUDGET_NODES


def test_budget_is_as_given_up_to_budget_nodes_then_scales_with_the_width():
    assert untangle_budget(20000, 4860) == 20000  # the 10k-triangle corpus
    assert untangle_budget(20000, BUDGET_NODES) == 20000
    assert untangle_budget(20000, 4 * BUDGET_NODES) == 40000
    assert untangle_budget(20000, 49700) == math.ceil(20000 * math.sqrt(4.97)) == 44587
    assert untangle_budget(0, 10 * BUDGET_NODES) == 0
    assert untangle_budget(100, 11881) == 109 and untangle_budget(100, 11882) == 110


def test_pipeline_hands_the_whole_mesh_stage_the_scaled_budget(monkeypatch):
    """A 111 x 111 grid (11 881 free nodes) with a budget of 100: the stage runs with
    100 sqrt(1.1881) = 109 untangling iterations (exactly: integer arithmetic) plus the
    polish."""
    k = 110
    x, y = np.meshgrid(np.linspace(0.0, 1.0, k + 1), np.linspace(0.0, 1.0, k + 1))
    pts = np.column_stack([x.ravel(), y.ravel()])
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    a = (i * (k + 1) + j).ravel()
    b, c, d = a + 1, a + k + 2, a + k + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    pts[5 * (k + 1) + 5] = pts[5 * (k + 1) + 7]  # one node moved over two neighbours: folds
    seen = []
    real = pipeline.untangle_global

    def spy(start, groups, free, options, *a, **kw):
        seen.append((int(free.sum()), options.max_iter, options.polish_iter))
        return real(start, groups, free, options, *a, **kw)

    monkeypatch.setattr(pipeline, "untangle_global", spy)
    prm = EEGTParams(untangle="global", max_untangle_iterations=100, polish_iterations=7)
    res = untangle_and_smooth(pts, faces, params=prm)
    assert res.before.n_inverted > 0 and seen[0] == (109 * 109, 109 + 7, 7)
