"""Open edges from an edge table (what a Blender mesh carries) against the sorted search:
the plane fit must get the same edges, in the same order, so the same frame bits."""

import numpy as np
import pytest
from meshdata import load2d as load

from core import PlaneFrame
from core.faces import FaceSet, as_faceset
from core.plane import open_edges, open_edges_from_table


def _table(fs: FaceSet, n: int, seed: int = 0):
    """Directed corner edges a -> b, an edge table in a shuffled order with shuffled ends
    (as a mesh editor leaves it) and every corner's edge in it."""
    a = np.concatenate([g.nodes.ravel() for g in fs.groups])
    b = np.concatenate([np.roll(g.nodes, -1, axis=0).ravel() for g in fs.groups])
    key = np.minimum(a, b) * n + np.maximum(a, b)
    uniq, inv = np.unique(key, return_inverse=True)
    rng = np.random.default_rng(seed)
    perm = rng.permutation(uniq.size)
    table = np.column_stack([uniq // n, uniq % n])[perm]
    flip = rng.random(uniq.size) < 0.5
    table[flip] = table[flip][:, ::-1]
    where = np.empty(uniq.size, dtype=np.int64)
    where[perm] = np.arange(uniq.size)
    return a, b, where[inv], table


def _same(got, want):
    assert got is not None
    for g, w in zip(got, want):
        assert g.dtype == w.dtype and g.tobytes() == w.tobytes()


@pytest.mark.parametrize(
    "name", ["tri_two_holes", "mixed_quad_tri", "polygon_voronoi", "quad_hole", "naca_deform"])
def test_table_gives_the_sorted_open_edges_bit_for_bit_on_shared_meshes(name):
    p, fs = load(name)
    n = p.shape[0]
    a, b, edge_of, table = _table(fs, n)
    want = open_edges(fs, n)
    assert want[0].size > 0 and np.all(want[2] != 0)
    _same(open_edges_from_table(a, b, edge_of, table, n), want)
    p3 = np.column_stack([p[:, 0], p[:, 1], 0.3 * p[:, 0] - 0.2 * p[:, 1]])
    f1 = PlaneFrame.fit(p3, fs, project=True)
    f2 = PlaneFrame.fit(p3, fs, project=True, edges=open_edges_from_table(a, b, edge_of, table, n))
    for attr in ("origin", "u", "v", "normal"):
        assert getattr(f1, attr).tobytes() == getattr(f2, attr).tobytes()


def test_non_manifold_and_flipped_faces_keep_their_net_counts():
    # Three triangles on edge 0-1 (non-manifold, net +1 -1 +1 = +1) and a quad whose
    # corners run the wrong way round next to a right one (their shared edge walked twice
    # the same way: net 2).
    faces = [[0, 1, 2], [1, 0, 3], [0, 1, 4], [5, 6, 7, 8], [6, 9, 10, 7][::-1]]
    fs = as_faceset(faces, 11)
    a, b, edge_of, table = _table(fs, 11, seed=3)
    want = open_edges(fs, 11)
    nets = dict(zip(zip(want[0].tolist(), want[1].tolist()), want[2].tolist()))
    assert nets[(0, 1)] == 1.0 and nets[(6, 7)] == 2.0
    _same(open_edges_from_table(a, b, edge_of, table, 11), want)


def test_a_table_that_does_not_fit_the_faces_is_refused():
    fs = as_faceset([[0, 1, 2], [0, 2, 3]], 4)
    a, b, edge_of, table = _table(fs, 4)
    wrong = table.copy()
    wrong[edge_of[0]] = [3, 1]  # the corner 0 -> 1 names an edge 1-3
    assert open_edges_from_table(a, b, edge_of, wrong, 4) is None
    corner = {(int(x), int(y)): k for k, (x, y) in enumerate(zip(a, b))}
    one = corner[(1, 2)]  # a boundary edge: its one corner moves to a second copy of it
    twin = np.vstack([table, table[edge_of[one]]])
    split = edge_of.copy()
    split[one] = twin.shape[0] - 1
    _same(open_edges_from_table(a, b, split, twin, 4), open_edges(fs, 4))
    inner = corner[(0, 2)]  # the shared edge 0-2: its two walks on two copies cancel nothing
    split = edge_of.copy()
    split[inner] = twin.shape[0] - 1
    both = np.vstack([table, table[edge_of[inner]]])
    assert open_edges_from_table(a, b, split, both, 4) is None
