"""The edge analysis from an edge table (what a Blender mesh carries) against the sorted
search: the same edges, counts and conflicts, so the same boundary, the same open edges in
the same order (the same frame bits) and the same run, bit for bit."""

import numpy as np
import pytest
from meshdata import load2d as load

from core import EEGTParams, PlaneFrame, untangle_and_smooth
from core.mesh.faces import FaceSet, as_faceset
from core.mesh.plane import open_edges
from core.mesh.topology import EdgeInfo, free_nodes


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


def _rows(info: EdgeInfo) -> list[tuple[int, int, int, int, bool]]:
    """Every kept edge (open, non-manifold, conflicting) as (lo, hi, count, net, conflict),
    in key order."""
    order = np.lexsort((info.hi, info.lo))
    return list(zip(info.lo[order].tolist(), info.hi[order].tolist(),
                    info.counts[order].tolist(), info.net[order].tolist(),
                    info.conflict[order].tolist()))


def _same(got, want):
    assert got is not None
    for g, w in zip(got, want):
        assert g.dtype == w.dtype and g.tobytes() == w.tobytes()


SHARED = ["tri_two_holes", "mixed_quad_tri", "polygon_voronoi", "quad_hole", "naca_deform"]


@pytest.mark.parametrize("name", SHARED)
def test_table_analysis_equals_the_sorted_one_on_shared_meshes(name):
    p, fs = load(name)
    n = p.shape[0]
    a, b, edge_of, table = _table(fs, n)
    got, want = EdgeInfo.from_table(a, b, edge_of, table, n), EdgeInfo(fs, n)
    assert got is not None and not got.in_key_order
    assert _rows(got) == _rows(want) and len(_rows(want)) > 20
    assert np.array_equal(got.boundary_mask(), want.boundary_mask())
    assert want.open_edges()[0].size > 0 and np.all(want.open_edges()[2] != 0)
    _same(got.open_edges(), want.open_edges())
    _same(got.open_edges(), open_edges(fs, n))
    assert np.array_equal(free_nodes(n, fs, edges=got), free_nodes(n, fs))


@pytest.mark.parametrize("name", SHARED)
def test_plane_frame_from_the_table_analysis_is_bit_identical(name):
    p, fs = load(name)
    n = p.shape[0]
    a, b, edge_of, table = _table(fs, n)
    p3 = np.column_stack([p[:, 0], p[:, 1], 0.3 * p[:, 0] - 0.2 * p[:, 1]])
    for project in (False, True):
        f1 = PlaneFrame.fit(p3, fs, project=project)
        f2 = PlaneFrame.fit(p3, fs, project=project,
                            edges=EdgeInfo.from_table(a, b, edge_of, table, n))
        for attr in ("origin", "u", "v", "normal"):
            assert getattr(f1, attr).tobytes() == getattr(f2, attr).tobytes()


@pytest.mark.parametrize(("name", "boundary"), [("quad_hole", "fixed"),
                                              ("mixed_quad_tri", "fixed"),
                                              ("mixed_quad_tri", "slide")])
def test_a_run_given_the_table_analysis_is_bit_identical(name, boundary):
    p, fs = load(name)
    n = p.shape[0]
    info = EdgeInfo.from_table(*_table(fs, n, seed=5), n)
    prm = EEGTParams(boundary=boundary)
    r1 = untangle_and_smooth(p, fs, params=prm)
    r2 = untangle_and_smooth(p, fs, params=prm, edges=info)
    assert r1.points.tobytes() == r2.points.tobytes()
    assert (r1.after, r1.status) == (r2.after, r2.status)


def test_non_manifold_and_flipped_faces_keep_their_net_counts_and_conflict():
    # Three triangles on edge 0-1 (non-manifold, net +1 -1 +1 = +1) and a quad whose
    # corners run the wrong way round next to a right one (their shared edge walked twice
    # the same way: net 2, a conflict).
    faces = [[0, 1, 2], [1, 0, 3], [0, 1, 4], [5, 6, 7, 8], [6, 9, 10, 7][::-1]]
    fs = as_faceset(faces, 11)
    a, b, edge_of, table = _table(fs, 11, seed=3)
    got, want = EdgeInfo.from_table(a, b, edge_of, table, 11), EdgeInfo(fs, 11)
    nets = dict(zip(zip(want.open_edges()[0].tolist(), want.open_edges()[1].tolist()),
                    want.open_edges()[2].tolist()))
    assert nets[(0, 1)] == 1.0 and nets[(6, 7)] == 2.0
    assert _rows(got) == _rows(want)
    _same(got.open_edges(), want.open_edges())
    assert got.first_conflict() == want.first_conflict() == (6, 7)
    with pytest.raises(ValueError, match=r"edge \(6, 7\) is used twice in the same direction"):
        free_nodes(11, fs, edges=got)


def test_the_first_conflict_is_the_smallest_edge_whatever_the_table_order():
    # two quads each flipped against its neighbour: conflicts on edges 1-4 and 7-10
    faces = [[0, 1, 4, 3], [1, 2, 5, 4][::-1], [6, 7, 10, 9], [7, 8, 11, 10][::-1]]
    fs = as_faceset(faces, 12)
    for seed in range(6):
        info = EdgeInfo.from_table(*_table(fs, 12, seed=seed), 12)
        assert info.first_conflict() == EdgeInfo(fs, 12).first_conflict() == (1, 4)
        assert int(info.conflict.sum()) == 2


def test_a_table_that_does_not_fit_the_faces_is_refused():
    fs = as_faceset([[0, 1, 2], [0, 2, 3]], 4)
    a, b, edge_of, table = _table(fs, 4)
    wrong = table.copy()
    wrong[edge_of[0]] = [3, 1]  # the corner 0 -> 1 names an edge 1-3
    assert EdgeInfo.from_table(a, b, edge_of, wrong, 4) is None
    assert EdgeInfo.from_table(a, b, edge_of + table.shape[0], table, 4) is None  # no edge
    corner = {(int(x), int(y)): k for k, (x, y) in enumerate(zip(a, b))}
    one = corner[(1, 2)]  # a boundary edge: its one corner moves to a second copy of it
    twin = np.vstack([table, table[edge_of[one]]])
    split = edge_of.copy()
    split[one] = twin.shape[0] - 1
    _same(EdgeInfo.from_table(a, b, split, twin, 4).open_edges(), open_edges(fs, 4))
    inner = corner[(0, 2)]  # the shared edge 0-2: its two walks on two copies
    split = edge_of.copy()
    split[inner] = twin.shape[0] - 1
    both = np.vstack([table, table[edge_of[inner]]])
    assert EdgeInfo.from_table(a, b, split, both, 4) is None


def test_two_used_copies_of_an_interior_edge_are_refused_even_when_each_looks_interior():
    # four triangles on edge 0-1 (non-manifold), its uses split two and two over two table
    # edges: each copy alone looks like an interior edge, the faces say the nodes are fixed
    faces = [[0, 1, 2], [1, 0, 3], [0, 1, 4], [1, 0, 5]]
    fs = as_faceset(faces, 6)
    a, b, edge_of, table = _table(fs, 6)
    assert EdgeInfo(fs, 6).boundary_mask()[[0, 1]].all()
    uses = np.flatnonzero(np.minimum(a, b) * 6 + np.maximum(a, b) == 1)
    copy = np.vstack([table, table[edge_of[uses[0]]]])
    split = edge_of.copy()
    split[uses[2:]] = copy.shape[0] - 1
    assert EdgeInfo.from_table(a, b, split, copy, 6) is None


def test_renumbered_analysis_equals_the_analysis_of_the_renumbered_faces():
    p, fs = load("mixed_quad_tri")
    n = p.shape[0]
    a, b, edge_of, table = _table(fs, n, seed=2)
    # the mesh's vertices with three unused ones spread in: nodes are the used vertices
    spread = np.arange(n) + np.searchsorted([n // 3, n // 2, 2 * n // 3], np.arange(n),
                                            side="right")
    info = EdgeInfo.from_table(spread[a], spread[b], edge_of, spread[table], n + 3)
    lut = np.zeros(n + 3, dtype=np.int64)
    lut[spread] = np.arange(n)
    local = info.renumbered(lut, n)
    assert local.n_nodes == n and _rows(local) == _rows(EdgeInfo(fs, n))
    _same(local.open_edges(), open_edges(fs, n))


def test_an_analysis_of_other_faces_is_refused():
    p, fs = load("quad_hole")
    with pytest.raises(ValueError, match="edges must be the EdgeInfo of these faces"):
        untangle_and_smooth(p, fs, edges=EdgeInfo(fs, p.shape[0] + 1))
