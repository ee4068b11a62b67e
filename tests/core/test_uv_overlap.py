"""Overlapping faces inside UV islands (core.uv.uv_overlap)."""

from __future__ import annotations

import numpy as np
from uvdata import grid_uv

from core import as_faceset
from core.uv.uv_layout import weld_uv
from core.uv.uv_overlap import candidate_pairs, overlapping_faces, triangles_overlap


def test_touching_triangles_do_not_overlap_crossing_ones_do():
    p = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [2, 2], [0.2, 0.2], [3, 0]], float)
    pairs = [
        ((0, 1, 2), (1, 3, 2), False),  # shared edge
        ((0, 1, 2), (3, 4, 6), False),  # apart
        ((0, 1, 3), (3, 4, 6), False),  # shared corner only
        ((0, 1, 2), (5, 3, 6), True),  # a corner inside
        ((0, 1, 2), (2, 1, 0), True),  # the same triangle, reversed
        ((0, 1, 3), (0, 3, 2), False),  # the two halves of a square
    ]
    ta = np.array([a for a, _, _ in pairs])
    tb = np.array([b for _, b, _ in pairs])
    assert triangles_overlap(p, ta, tb).tolist() == [want for _, _, want in pairs]


def test_candidate_pairs_equal_brute_force_with_big_boxes():
    rng = np.random.default_rng(4)
    lo = rng.uniform(0, 100, (600, 2))
    size = rng.exponential(1.5, (600, 2))
    size[:5] *= 60  # a few boxes spanning many cells
    hi = lo + size
    got = {tuple(x) for x in candidate_pairs(lo, hi).tolist()}
    ov = ((lo[:, None, 0] < hi[None, :, 0]) & (lo[None, :, 0] < hi[:, None, 0])
          & (lo[:, None, 1] < hi[None, :, 1]) & (lo[None, :, 1] < hi[:, None, 1]))
    i, j = np.nonzero(np.triu(ov, 1))
    assert got == set(zip(i.tolist(), j.tolist()))
    assert len(got) == 385  # not a trivial case: hundreds of pairs


def test_valid_grid_has_no_overlap_a_fold_has():
    g = grid_uv(6)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    assert not overlapping_faces(lay.points, lay.faces, lay.island).any()
    p = lay.points.copy()
    centre = int(np.flatnonzero((p == (2.0, 2.0)).all(axis=1))[0])
    p[centre] = (3.6, 2.0)  # pushed over its right neighbours: a fold
    over = overlapping_faces(p, lay.faces, lay.island)
    cen = g.face_centres()
    assert over.sum() >= 4
    assert (np.abs(cen[over] - (2.5, 2.0)).max(axis=1) <= 1.5).all()  # only around it


def test_overlap_between_islands_is_layout_not_reported():
    g = grid_uv(5, seam_x=2.0, gap=-1.0)  # the right island slid one unit over the left one
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    assert lay.n_islands == 2
    assert not overlapping_faces(lay.points, lay.faces, lay.island).any()
    one = np.zeros(lay.n_islands, int)[lay.island]  # the same faces as one island: overlap
    assert overlapping_faces(lay.points, lay.faces, one).sum() == 8


def test_fold_with_consistent_orientation_is_found():
    # A strip of 6 quads whose far end is folded back over its start: every face is
    # counterclockwise (no flipped face) but faces 0 and 5 cover each other.
    top = [(0, 1), (1, 1), (2, 1), (2.5, 1.5), (2, 2), (1, 2)]
    bot = [(0, 0), (1, 0), (2, 0), (3.5, 1.5), (2, 3), (1, 3)]
    p = np.array(bot + top, float)
    p[5] = (0.5, 2.7)
    p[11] = (0.5, 1.8)
    p[4] = (1.5, 2.9)
    p[10] = (1.5, 1.9)
    faces = [[k, k + 1, k + 7, k + 6] for k in range(5)]
    fs = as_faceset(faces, 12)
    from core.metrics import signed_face_areas
    assert (signed_face_areas(p, fs) > 0).all()
    p[5] = (0.5, 0.3)  # the last quad lies on the first one
    p[11] = (0.5, 0.8)
    over = overlapping_faces(p, fs, np.zeros(5, int))
    assert over[0] and over[4]


def _sat_reference(a: np.ndarray, b: np.ndarray) -> bool:
    """Plain separating-axis test of two triangles (3 x 2 arrays), one pair at a time."""
    for tri in (a, b):
        for k in range(3):
            e = tri[(k + 1) % 3] - tri[k]
            n = np.array([e[1], -e[0]])
            pa, pb = a @ n, b @ n
            if min(pa.max(), pb.max()) - max(pa.min(), pb.min()) <= 1e-12 * np.linalg.norm(n):
                return False
    return True


def test_neighbour_rule_agrees_with_separating_axes():
    rng = np.random.default_rng(11)
    g = grid_uv(7)
    lay = weld_uv(g.loop_start, g.loop_total, g.corner_verts, g.uv)
    p = lay.points + rng.uniform(-0.6, 0.6, lay.points.shape)  # many folds
    quads = lay.faces.indices.reshape(-1, 4)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]], quads[:, [1, 2, 3]]])
    i, j = np.triu_indices(len(tris), 1)
    shared = (tris[i][:, :, None] == tris[j][:, None, :]).sum(axis=(1, 2))
    assert (shared == 2).sum() > 100 and (shared == 1).sum() > 100
    got = triangles_overlap(p, tris[i], tris[j])
    want = np.array([_sat_reference(p[tris[a]], p[tris[b]]) for a, b in zip(i, j)])
    assert np.array_equal(got, want)
    assert 50 < got.sum() < got.size
