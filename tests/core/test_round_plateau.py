"""A repair's untangling rounds end on a plateau (GlobalOptions.end_round_on_plateau):
only a region "folds" run's attempts use it; the rest keep running rounds to their cap."""

import numpy as np
import pytest

import core.run.pipeline as pipeline
from core import EEGTParams, untangle_and_smooth


def _cgridtri():
    """A structured C-grid of triangles (2 000 cells) whose wall turned 15 degrees."""
    from bench.repair_meshes import Spec, make

    return make(Spec("cgridtri", 2000, "turn", {"angle": 15.0, "reach": 0.15}))


def _repair(c):
    return untangle_and_smooth(c.points, c.faces, fixed=c.fixed,
                               params=EEGTParams(region="folds", target="keep"))


def test_repair_rounds_end_on_a_plateau_and_take_fewer_iterations(monkeypatch):
    """With the share left open (PLATEAU_LEFT past every count), the C-grid's untangling
    rounds end at the first check that betters neither the inverted count nor the worst
    det: fewer optimizer iterations than with rounds run to their cap (2 784 against 3 948
    here; the mesh's last bits, and so the counts, vary with the CPU's float code), also
    untangled, every node outside the region bit-identical."""
    from core.optimize import stages

    c = _cgridtri()
    monkeypatch.setattr(stages, "PLATEAU_LEFT", 1e9)
    ended = _repair(c)
    monkeypatch.setattr(stages, "PLATEAU_EVERY", 10**9)  # no check: rounds run to their cap
    capped = _repair(c)
    for res in (ended, capped):
        assert res.status == "untangled" and res.after.n_inverted == 0
        assert np.array_equal(np.asarray(res.points)[~res.moved], c.points[~res.moved])
    assert ended.global_iterations < 0.8 * capped.global_iterations


def test_a_round_with_more_than_plateau_left_inverted_runs_on(monkeypatch):
    """An O-grid of triangles with its cylinder slid 0.2 chords: its first round levels off
    with about 60 % of its inverted cells still inverted, more than PLATEAU_LEFT (a region
    whose fold is far from open: ended there, give_up_early would judge it too tight); it
    runs on: the same points, bit for bit, and iterations as without the checks."""
    from bench.repair_meshes import Spec, make
    from core.optimize import stages

    c = make(Spec("ogridtri", 2000, "slide", {"dx": 0.2, "reach": 0.2}))
    gated = _repair(c)
    monkeypatch.setattr(stages, "PLATEAU_EVERY", 10**9)
    capped = _repair(c)
    assert gated.status == capped.status == "untangled"
    assert np.array_equal(gated.points, capped.points)
    assert gated.global_iterations == capped.global_iterations


def test_a_round_with_at_most_plateau_left_inverted_ends_on_its_plateau(monkeypatch):
    """The C-grid's first round levels off with 6-7 % of its inverted cells left (at most
    PLATEAU_LEFT): it ends there and the next eps opens them, in fewer iterations than the
    round run to its cap."""
    from core.optimize import stages

    c = _cgridtri()
    gated = _repair(c)
    monkeypatch.setattr(stages, "PLATEAU_EVERY", 10**9)
    capped = _repair(c)
    assert gated.status == capped.status == "untangled"
    assert gated.global_iterations < capped.global_iterations


def test_only_a_repairs_attempts_end_rounds_on_a_plateau(monkeypatch):
    """The global stage's options: a region "folds" run's attempts end rounds on a plateau
    (and give up early while their region is smaller than the mesh); a run on the whole
    mesh (region "mesh", the default) does neither, so it keeps its results bit for bit."""
    seen = []
    real = pipeline.untangle_global

    def recording(*args, **kwargs):
        opt = args[3]
        seen.append((opt.end_round_on_plateau, opt.give_up_early))
        return real(*args, **kwargs)

    monkeypatch.setattr(pipeline, "untangle_global", recording)
    c = _cgridtri()
    untangle_and_smooth(c.points, c.faces, fixed=c.fixed, params=EEGTParams(target="keep"))
    assert seen and all(s == (False, False) for s in seen)
    seen.clear()
    _repair(c)
    assert seen and all(plateau for plateau, _ in seen)
    assert all(early for _, early in seen)  # the C-grid's fold opens in a region


def test_an_unknown_attempt_is_refused_with_one_line():
    """`attempt` is None, REGION or WHOLE; anything else is a ValueError naming the value,
    before any work."""
    from core.run.repair import REGION, WHOLE

    p = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match=f"attempt must be None, '{REGION}' or '{WHOLE}', "
                                         "got 'bogus'"):
        untangle_and_smooth(p, [[0, 1, 2]], attempt="bogus")
