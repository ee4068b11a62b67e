"""The optimizer's untangling budget grows with the mesh's width beyond BUDGET_NODES free
nodes (its eps rounds do too), so a fold at 100k elements gets the rounds it needs."""

from __future__ import annotations

import math

import numpy as np
from meshdata import spun_hole

from core import EEGTParams, untangle_and_smooth
from core.optimize import untangle_budget, untangle_global
from core.optimize.energy import FoldoverEnergy
from core.optimize.options import GlobalOptions
from core.optimize.stages import BUDGET_NODES
from core.run import pipeline


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


def blended_turn(degrees: float) -> tuple[np.ndarray, dict[int, np.ndarray], np.ndarray]:
    """An annulus (8 x 48 triangles) whose hole is turned by `degrees`, every node following
    in proportion to its nearness to the hole (a moved boundary's blend): the middle rings
    fold. Returns points, groups and the free (interior) nodes."""
    pts, groups = spun_hole(8, 48, 0.0, True)
    r = np.hypot(*pts.T)
    t = np.radians(degrees)
    turned = pts @ np.array([[np.cos(t), np.sin(t)], [-np.sin(t), np.cos(t)]])
    free = (r > 1.0 + 1e-9) & (r < 2.0 - 1e-9)
    return pts + (2.0 - r)[:, None] * (turned - pts), groups, free


def scripted_rounds(monkeypatch, tangled, valid, shares):
    """Each untangling round's solve returns the point `share` of the way from `valid` to
    `tangled` (the next share in turn), having spent its whole cap; a polish round stops at
    once. Returns the shares used."""
    used: list[float] = []

    def solve(_view, st, v, _eps, max_it, guard, tick=None):
        if guard:
            return v, 0
        s = shares[len(used)]
        used.append(s)
        p = valid + s * (tangled - valid)
        return st.pack(p[:, 0], p[:, 1]), max_it

    monkeypatch.setattr(GlobalOptions, "run", lambda self, sliding=False: solve)
    return used


def test_spent_budget_gets_more_rounds_while_the_worst_corner_closes_in(monkeypatch):
    """Three rounds of 1000 iterations spend a budget of 3000 with the mesh still folded: when
    the worst corner det came well over twice closer to 0 in the last two rounds, the run
    goes on (up to half the budget more) and untangles; when it crept, the run stops at the
    budget, tangled."""
    tangled, groups, free = blended_turn(150.0)
    valid, info = untangle_global(tangled, groups, free, GlobalOptions(max_iter=20_000))
    assert info["status"] == "untangled" and info["n_inverted_in"] > 100
    en = FoldoverEnergy(tangled, groups, free)

    def dmin(s: float) -> float:
        p = valid + s * (tangled - valid)
        return float(np.min(en.dets(p[:, 0], p[:, 1])))

    lo, hi = 0.0, 1.0  # the share where the mesh folds: dmin(lo) > 0 >= dmin(hi)
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if dmin(mid) > 0 else (lo, mid)
    gap = 1.0 - hi
    options = GlobalOptions(max_iter=3000, polish_iter=0)

    closing = [hi + gap * f for f in (0.4, 0.16, 0.064)] + [0.5 * lo, 0.0]
    used = scripted_rounds(monkeypatch, tangled, valid, closing)
    assert -dmin(closing[2]) < 0.5 * -dmin(closing[0])
    told: list[tuple[int, int]] = []
    _, info = untangle_global(tangled, groups, free, options,
                              progress=lambda it, most, _n, _p: told.append((it, most)))
    assert info["status"] == "untangled" and info["iterations"] == 4000 and len(used) == 4
    assert told == [(1000, 3000), (2000, 3000), (3000, 3000), (4000, 4000)]  # the budget grew

    creeping = [hi + gap * f for f in (0.5, 0.45, 0.4, 0.35, 0.3)]
    used = scripted_rounds(monkeypatch, tangled, valid, creeping)
    assert -dmin(creeping[2]) > 0.5 * -dmin(creeping[0])
    _, info = untangle_global(tangled, groups, free, options)
    assert info["status"] == "failed" and info["iterations"] == 3000 and len(used) == 3
