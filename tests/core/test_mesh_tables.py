"""The global stage's integer tables and reference sizes, against their plain definitions:
`mesh_tables` fills its arrays in place, `bincount_csr` skips the sort of keys already in
order, `reference_sizes` works in pieces; each must give exactly the plain result."""

from __future__ import annotations

import numpy as np
import pytest

import core.optimize.mesh_tables as mt
from core.mesh.csr import bincount_csr
from core.optimize.mesh_tables import mesh_tables, reference_sizes


def plain_tables(groups):
    """The definition: arities sorted, each polygon's edges (k, k + 1) in corner order."""
    faces = [np.asarray(groups[n], dtype=np.int64).reshape(-1, n) for n in sorted(groups)
             if np.asarray(groups[n]).size]
    arity = np.concatenate([np.full(len(f), f.shape[1]) for f in faces])
    tail = np.concatenate([f.ravel() for f in faces])
    head = np.concatenate([np.roll(f, -1, axis=1).ravel() for f in faces])
    elem = np.repeat(np.arange(arity.size), arity)
    return faces, arity, np.stack([tail, head]), elem


def mixed_groups(rng, dtype=np.int64):
    return {5: rng.integers(0, 60, (7, 5)).astype(dtype), 3: rng.integers(0, 60, (40, 3)),
            4: rng.integers(0, 60, (30, 4)), 6: np.zeros((0, 6), dtype=np.int64)}


@pytest.mark.parametrize("dtype", [np.int64, np.int32])
def test_mesh_tables_fill_in_place_gives_the_plain_tables(dtype):
    groups = mixed_groups(np.random.default_rng(3), dtype)
    got, want = mesh_tables(groups), plain_tables(groups)
    assert [f.shape for f in got[0]] == [(40, 3), (30, 4), (7, 5)]
    for a, b in zip(got[0], want[0], strict=True):
        assert np.array_equal(a, b)
    for a, b in zip(got[1:], want[1:], strict=True):
        assert a.dtype == np.int64 and a.shape == b.shape and np.array_equal(a, b)


def test_mesh_tables_of_no_polygons_and_of_two_node_polygons():
    faces, arity, edges, elem = mesh_tables({})
    assert faces == [] and arity.size == 0 and edges.shape == (2, 0) and elem.size == 0
    with pytest.raises(ValueError, match="at least 3 nodes"):
        mesh_tables({2: np.array([[0, 1]])})


@pytest.mark.parametrize("keys", [
    np.array([0, 0, 1, 3, 3, 3, 7]),  # in order: no sort
    np.array([3, 0, 3, 1, 0, 7, 3]),  # a stable sort
    np.array([5]), np.zeros(0, dtype=np.int64),
])
def test_bincount_csr_rows_list_positions_in_ascending_order(keys):
    ptr, pos = bincount_csr(keys, 8)
    assert ptr.shape == (9,) and ptr[-1] == keys.size
    for k in range(8):
        assert np.array_equal(pos[ptr[k] : ptr[k + 1]], np.flatnonzero(keys == k))


def test_reference_sizes_in_pieces_match_whole_array_passes(monkeypatch):
    rng = np.random.default_rng(5)
    groups = mixed_groups(rng)
    points = rng.random((60, 2))
    _, arity, edges, elem = mesh_tables(groups)
    whole = reference_sizes(points, arity, edges, elem)  # one piece: 275 edges < EDGE_PIECE
    monkeypatch.setattr(mt, "EDGE_PIECE", 16)
    pieces = reference_sizes(points, arity, edges, elem)
    for a, b in zip(whole, pieces, strict=True):
        assert np.array_equal(a, b)
    assert whole[0].shape == (77,) and whole[1].shape == (60,)
    assert np.all(whole[0] > 0.0) and np.all(whole[1] > 0.0)
