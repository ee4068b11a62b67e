"""The lift's settle with `GlobalOptions.stiff_settle` (the pipeline's runs with target
shapes): the stiffness preconditioner and its shorter cap; without it the size-based
preconditioner and its cap, target factors or not."""

from __future__ import annotations

import numpy as np
from meshdata import load2d

from core.mesh.faces import as_faceset
from core.metrics.targets import corner_factors
from core.optimize import GlobalOptions, lift_min_quality, untangle_global
from core.optimize.energy import FoldoverEnergy, LiftEnergy
from core.optimize.solver import lbfgs
from core.optimize.stages import SETTLE_ITER, SETTLE_ITER_SHAPED
from core.run.pipeline import free_nodes


def _quad_hole(stretch: float | None):
    """The shared quad_hole mesh, its groups and free nodes, and target factors from its own
    shapes stretched 1 x stretch (None: regular targets)."""
    p, f = load2d("quad_hole")
    fs = as_faceset(f, len(p))
    factors = None if stretch is None else corner_factors(p[fs.indices] * [1.0, stretch], fs)
    return p, fs.by_arity(), free_nodes(len(p), fs), factors


def _by_hand(en: FoldoverEnergy) -> np.ndarray:
    """The stiffness preconditioner corner by corner: node i of corner (i0, i1, i2) adds
    w |its row of W^-1|^2 (i1: (w00, w01), i2: (0, w11), i0: -(w00, w01 + w11))."""
    d = np.zeros(en.n_nodes)
    for k in range(en.i0.size):
        w, a, b, c = en.weight[k], en.w00[k], en.w01[k], en.w11[k]
        d[en.i1[k]] += w * (a * a + b * b)
        d[en.i2[k]] += w * c * c
        d[en.i0[k]] += w * (a * a + (b + c) ** 2)
    pre = np.ones(en.n_nodes)
    has = d > 0.0
    pre[has] = 1.0 / np.sqrt(d[has])
    pre[has] /= pre[has].mean()
    return pre


def test_stiffness_precond_is_the_normalised_inverse_root_of_the_jacobi_diagonal():
    p, groups, free, factors = _quad_hole(3.0)
    en = LiftEnergy(p, groups, free, factors)
    got = en.stiffness_precond()
    assert got.shape == (len(p),)
    np.testing.assert_allclose(got, _by_hand(en), rtol=1e-13, atol=0.0)
    # stretched targets: a node's entry follows its cells' thin side, not their mean edge
    assert not np.allclose(got, en.precond, rtol=0.1)


def test_stiffness_precond_ignores_the_mesh_scale():
    p, groups, free, factors = _quad_hole(3.0)
    small = LiftEnergy(p, groups, free, factors).stiffness_precond()
    big = LiftEnergy(p * 1000.0, groups, free, factors).stiffness_precond()
    np.testing.assert_allclose(big, small, rtol=1e-12, atol=0.0)


def test_with_precond_is_a_copy_with_its_own_scratch():
    p, groups, free, factors = _quad_hole(3.0)
    en = LiftEnergy(p, groups, free, factors)
    en.qc = 0.25
    x, y = p[:, 0], p[:, 1]
    dets = en.dets(x, y)  # a host evaluation: en now holds its corner scratch
    assert en._blocks is not None
    pre = en.stiffness_precond()
    other = en.with_precond(pre)
    assert other is not en and other.precond is pre and en.precond is not pre
    assert other.qc == 0.25 and other.i0 is en.i0 and other._blocks is None
    assert np.array_equal(other.dets(x, y), dets) and other._blocks is not en._blocks
    assert other.value(x, y, 0.0) == en.value(x, y, 0.0)


def _settle_call(stretch: float | None, stiff: bool
                 ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """(max_it, preconditioner) of the lift's last L-BFGS call (the settle) on quad_hole
    after the global stage, and the lift energy's own size-based and stiffness ones."""
    p, groups, free, factors = _quad_hole(stretch)
    calls = []

    def recording(en, st, v0, eps, **kw):
        calls.append((kw["max_it"], en.precond))
        return lbfgs(en, st, v0, eps, **kw)

    opt = GlobalOptions(solver=recording, stiff_settle=stiff)
    u, info = untangle_global(p, groups, free, opt, factors=factors)
    assert info["status"] == "untangled"
    _, linfo = lift_min_quality(u, groups, free, opt, factors=factors)
    assert linfo["rounds"] > 0  # the climb kept rounds: the settle ran last
    en = LiftEnergy(u, groups, free, factors)
    return calls[-1][0], calls[-1][1], en.precond, en.stiffness_precond()


def test_stiff_settle_runs_with_the_stiffness_precond_and_its_cap():
    cap, used, size_based, stiffness = _settle_call(2.0, True)
    assert cap == SETTLE_ITER_SHAPED
    assert np.array_equal(used, stiffness) and not np.array_equal(used, size_based)


def test_settle_without_the_option_keeps_the_size_precond_and_its_cap():
    for stretch in (2.0, None):
        cap, used, size_based, _ = _settle_call(stretch, False)
        assert cap == SETTLE_ITER
        assert np.array_equal(used, size_based)


def test_pipeline_asks_for_the_stiff_settle_with_target_shapes_only(monkeypatch):
    """`untangle_and_smooth` hands the lift stiff_settle=True with target "keep" and False
    with the regular target."""
    from core import EEGTParams
    from core.run import pipeline
    from core.run.pipeline import untangle_and_smooth

    seen = []

    def lift(points, groups, free, options, **kw):
        seen.append(options.stiff_settle)
        return points, {"iterations": 0, "rounds": 0, "status": "unchanged"}

    monkeypatch.setattr(pipeline, "lift_min_quality", lift)
    p, f = load2d("quad_hole")
    for target in ("keep", "regular"):
        untangle_and_smooth(p, f, params=EEGTParams(target=target))
    assert seen == [True, False]
