"""The lift's and the local untangle's sub-meshes: `Neighbourhood` (built once, each
sub-mesh costs its own size) against the plain whole-mesh definition, and
`LiftEnergy.element_quality_of` against `element_quality`, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from meshdata import load2d

from core.mesh.faces import as_faceset
from core.metrics.targets import corner_factors, prepare_targets
from core.optimize.energy import LiftEnergy
from core.optimize.submesh import Neighbourhood, active_submesh
from core.run.pipeline import free_nodes


def dense_submesh(groups, free, seed, rings):
    """The definition, over whole-mesh masks: nodes within `rings` rings of the seed
    elements, the elements touching such a free node, local numbers in node order."""
    faces = [np.asarray(groups[n]).reshape(-1, n) for n in sorted(groups)]
    near = np.zeros(free.size, dtype=bool)
    base = 0
    for f in faces:
        near[f[seed[base : base + len(f)]]] = True
        base += len(f)
    for _ in range(rings):
        grow = near.copy()
        for f in faces:
            grow[f[near[f].any(axis=1)]] = True
        near = grow
    move = near & free
    sub = [f[move[f].any(axis=1)] for f in faces]
    nodes = np.unique(np.concatenate([s.ravel() for s in sub]))
    local = np.full(free.size, -1)
    local[nodes] = np.arange(nodes.size)
    return {s.shape[1]: local[s] for s in sub if len(s)}, nodes, move[nodes]


@pytest.mark.parametrize("name", ["mixed_quad_tri", "polygon_voronoi", "tri_two_holes"])
@pytest.mark.parametrize("rings", [0, 1, 3, 6])
def test_neighbourhood_submesh_is_the_dense_definition(name, rings):
    p, f = load2d(name)
    fs = as_faceset(f, len(p))
    groups, free = fs.by_arity(), free_nodes(len(p), fs)
    n_elem = sum(len(np.asarray(g).reshape(-1, n)) for n, g in groups.items())
    near = Neighbourhood(groups, free)
    rng = np.random.default_rng(rings)
    for k in (1, 3, 20):
        seed = np.zeros(n_elem, dtype=bool)
        seed[rng.choice(n_elem, k, replace=False)] = True
        (sub, nodes, sfree, _), elems = near.submesh(seed, rings)
        want_sub, want_nodes, want_free = dense_submesh(groups, free, seed, rings)
        assert np.array_equal(nodes, want_nodes)
        assert np.array_equal(sfree, want_free)
        assert sorted(sub) == sorted(want_sub)
        for n in sub:
            assert np.array_equal(sub[n], want_sub[n])
        assert elems.size == sum(len(s) for s in sub.values())
        assert np.all(np.diff(elems) > 0)


def test_neighbourhood_carries_target_factors_and_empty_seed():
    p, f = load2d("mixed_quad_tri")
    fs = as_faceset(f, len(p))
    groups, free = fs.by_arity(), free_nodes(len(p), fs)
    corners = np.concatenate([p[g.nodes.T].reshape(-1, 2) for g in fs.groups])
    factors = corner_factors(prepare_targets(corners * [1.0, 0.5], fs), fs)
    seed = np.zeros(fs.n_faces, dtype=bool)
    seed[[0, 5, 40]] = True
    got = Neighbourhood(groups, free, factors).submesh(seed, 2)[0]
    want = active_submesh(groups, free, seed, 2, factors)
    for n in want[3]:
        for a, b in zip(got[3][n], want[3][n], strict=True):
            assert np.array_equal(a, b)
    (sub, nodes, sfree, _), elems = Neighbourhood(groups, free).submesh(
        np.zeros(fs.n_faces, dtype=bool), 3)
    assert sub == {} and nodes.size == 0 and sfree.size == 0 and elems.size == 0


@pytest.mark.parametrize("name", ["mixed_quad_tri", "polygon_voronoi", "quad_hole"])
def test_element_quality_of_is_element_quality_bit_for_bit(name):
    p, f = load2d(name)
    fs = as_faceset(f, len(p))
    free = free_nodes(len(p), fs)
    en = LiftEnergy(p, fs.by_arity(), free)
    rng = np.random.default_rng(7)
    x, y = p[:, 0] + rng.normal(0, 1e-3, len(p)), p[:, 1] + rng.normal(0, 1e-3, len(p))
    whole = en.element_quality(x, y)
    for elems in (np.arange(en.n_elem), np.sort(rng.choice(en.n_elem, 17, replace=False)),
                  np.array([en.n_elem - 1])):
        got = en.element_quality_of(elems, x, y)
        assert np.array_equal(got, whole[elems])
    node = int(np.flatnonzero(free)[0])  # fold the faces around one node: qualities of 0
    x[node] += 10.0 * float(np.ptp(p[:, 0]))
    whole = en.element_quality(x, y)
    folded = np.flatnonzero(whole == 0.0)
    assert folded.size > 0
    assert np.array_equal(en.element_quality_of(folded, x, y), np.zeros(folded.size))
    assert np.array_equal(en.element_quality_of(np.arange(en.n_elem), x, y), whole)


@pytest.mark.parametrize("sort_below", [0, 10**9])
def test_submesh_by_marks_and_by_sorting_give_the_same_sub_mesh(monkeypatch, sort_below):
    import core.optimize.submesh as sm

    p, f = load2d("polygon_voronoi")
    fs = as_faceset(f, len(p))
    groups, free = fs.by_arity(), free_nodes(len(p), fs)
    seed = np.zeros(fs.n_faces, dtype=bool)
    seed[[2, 30, 31]] = True
    want = Neighbourhood(groups, free).submesh(seed, 2)
    monkeypatch.setattr(sm, "DISTINCT_SORT", sort_below)  # 0: always sort; huge: always mark
    got = Neighbourhood(groups, free).submesh(seed, 2)
    assert np.array_equal(got[1], want[1]) and got[1].size > 10
    for a, b in zip(got[0][1:3], want[0][1:3], strict=True):
        assert np.array_equal(a, b)
    assert sorted(got[0][0]) == sorted(want[0][0])
    for n in want[0][0]:
        assert np.array_equal(got[0][0][n], want[0][0][n])
