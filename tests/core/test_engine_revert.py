"""The EEGT smoothing step's revert (core/eegt/engine_numpy.py): nodes of faces a step
inverted go back, pass after pass, until no face is inverted."""

from __future__ import annotations

import numpy as np

from bench.meshgen import jittered_square
from core import EEGTParams
from core.eegt.engine_numpy import NumpyEngine
from core.mesh.topology import free_nodes
from core.metrics.mean_ratio import group_quality


def _reverted_by_full_passes(fs, x, y, old_x, old_y):
    """The rule measured the plain way: every face again after each pass. (x, y, q, passes)."""
    x, y = x.copy(), y.copy()
    passes = 0
    while True:
        q = [group_quality(x[g.nodes], y[g.nodes]) for g in fs.groups]
        back = np.zeros(x.size, dtype=bool)
        for g, qg in zip(fs.groups, q):
            back[g.nodes[:, qg == 0.0].ravel()] = True
        back &= (x != old_x) | (y != old_y)
        if not back.any():
            return x, y, q, passes
        x[back], y[back] = old_x[back], old_y[back]
        passes += 1


def test_revert_spreading_over_many_rings_equals_measuring_every_face_each_pass():
    """A disk of a jittered square moved by three cells at once folds the faces at its rim;
    moving the rim's nodes back folds the next ring in, and so on to the centre: a pass a
    ring. The revert, which measures again only the faces with a node it moved back, ends
    at the same positions and qualities, bit for bit, with no face inverted."""
    p, fs = jittered_square(3000, jitter=0.2, seed=5)
    free = free_nodes(p.shape[0], fs, np.zeros(p.shape[0], dtype=bool))
    disk = (np.hypot(p[:, 0] - 0.5, p[:, 1] - 0.5) < 0.3) & free
    moved = p.copy()
    moved[disk] += [0.075, 0.0]
    engine = NumpyEngine(moved, fs, free, EEGTParams())
    x, y, q, passes = _reverted_by_full_passes(fs, moved[:, 0], moved[:, 1], p[:, 0], p[:, 1])
    assert passes >= 10
    engine._revert_inverted(p[:, 0].copy(), p[:, 1].copy())
    assert np.array_equal(engine.x, x) and np.array_equal(engine.y, y)
    for a, b in zip(engine.q, q):
        assert np.array_equal(a, b) and (a > 0.0).all()
