"""The lift energy's whole-mesh measures (`value`, `element_quality`) work in pieces without
the per-corner scratch of a host evaluation, with the evaluation's bits: a run whose solves
are on a device never holds that scratch (about 43 doubles per corner: 365 MB at 1M
triangles)."""

from __future__ import annotations

import numpy as np
import pytest
from meshdata import load2d

from bench.meshgen import holed_quads, holed_square
from core.mesh.faces import as_faceset
from core.optimize import energy as energy_mod
from core.optimize.energy import LiftEnergy
from core.optimize.slide import make_state
from core.run.pipeline import free_nodes


def naca():
    p, f = load2d("naca_undeformed")
    return p, as_faceset(f, len(p))


MESHES = {  # valid meshes: triangles, quads, and the airfoil's graded triangles
    "triangles": lambda: holed_square(3000, jitter=0.2, seed=1),
    "quads": lambda: holed_quads(3000, jitter=0.2, seed=1),
    "naca_undeformed": naca,
}


def jittered(name: str, scale: float):
    p, fs = MESHES[name]()
    free = free_nodes(len(p), fs)
    rng = np.random.default_rng(3)
    x = p[:, 0] + np.where(free, rng.normal(0, scale, len(p)), 0.0)
    y = p[:, 1] + np.where(free, rng.normal(0, scale, len(p)), 0.0)
    return p, fs, free, x, y


@pytest.mark.parametrize("name", sorted(MESHES))
def test_value_is_the_evaluation_bit_for_bit_without_its_scratch(name, monkeypatch):
    p, fs, free, x, y = jittered(name, 1e-6 if name == "naca_undeformed" else 1e-3)
    made = []
    real = energy_mod._Blocks
    monkeypatch.setattr(energy_mod, "_Blocks", lambda *a: made.append(1) or real(*a))
    en = LiftEnergy(p, fs.by_arity(), free)
    en.qc = 0.8  # some elements under the floor: the penalty term counts
    v = en.value(x, y, 1e-9)
    q = en.element_quality(x, y)
    both = en.value_and_quality(x, y)
    assert not made  # no measure made the host's corner scratch
    assert both[0] == v and np.array_equal(both[1], q)
    assert 0.0 < q.min() < 0.8 < q.max()
    z = np.concatenate([x, y])
    assert v == en.evaluate(z, en.flat_layout(np.arange(z.size).reshape(2, -1)), 1e-9)[0]
    assert made == [1]  # the evaluation made it, once


def test_value_is_infinite_where_a_corner_folds():
    p, fs, free, x, y = jittered("quads", 1e-4)
    en = LiftEnergy(p, fs.by_arity(), free)
    en.qc = 0.5
    assert np.isfinite(en.value(x, y, 1e-9))
    node = int(np.flatnonzero(free)[0])
    x[node] += 10.0 * float(np.ptp(p[:, 0]))
    assert en.value(x, y, 1e-9) == np.inf
    assert (en.element_quality(x, y) == 0.0).sum() >= 2


def test_triangle_lift_skips_per_element_sums_with_the_same_bits():
    """On triangles corner k is element k: the element means and the gradient's gather are
    copies, and the general per-element path gives the same bits."""
    p, fs = naca()
    free = free_nodes(len(p), fs)
    en = LiftEnergy(p, fs.by_arity(), free)
    assert en._one_each
    en.qc = 0.5
    rng = np.random.default_rng(4)
    x, y = p[:, 0] + rng.normal(0, 1e-4, len(p)), p[:, 1] + rng.normal(0, 1e-4, len(p))
    st = make_state(np.column_stack([x, y]), free, None)
    layout, fixed = en.packed(st)
    z = np.concatenate([st.pack(st.x, st.y), fixed])
    fast = (en.value_and_quality(x, y), en.evaluate(z, layout, 0.0), en.gradient(layout).copy())
    en._one_each = False
    slow = (en.value_and_quality(x, y), en.evaluate(z, layout, 0.0), en.gradient(layout).copy())
    assert fast[0][0] == slow[0][0] and np.array_equal(fast[0][1], slow[0][1])
    assert fast[1] == slow[1] and np.array_equal(fast[2], slow[2])
    mixed_p, mixed_f = load2d("mixed_quad_tri")
    mixed_fs = as_faceset(mixed_f, len(mixed_p))
    mixed = LiftEnergy(mixed_p, mixed_fs.by_arity(), free_nodes(len(mixed_p), mixed_fs))
    assert not mixed._one_each
