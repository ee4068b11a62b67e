"""Corners kept as given in UV runs (core.metrics.kept, issue 40 item 1): a UV face with a
straight corner, or a concave corner of a simple counterclockwise n-gon, made of fixed UV
vertices only (island border, pinned, border of the selection) is valid, as in the mesh
path: what a knife cut, a partial loop cut or a bevel leaves, then unwrapped."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from core import EEGTParams, boundary_nodes
from core.mesh.faces import faces_from_csr
from core.metrics import face_shapes_2d
from core.uv.uv_layout import UVLayout, weld_uv
from core.uv.uv_overlap import overlapping_faces
from core.uv.uv_untangle import (
    flipped_faces,
    kept_as_given,
    kept_face_mask,
    measure,
    tangled_faces,
    untangle_uv,
)

N = 4  # quads per side


@dataclass
class UVMap:
    """A flat mesh (z = 0) with one UV per loop, UV = the vertex xy unless changed."""

    co: np.ndarray
    faces: list[list[int]]
    uv: np.ndarray  # (L, 2) float32

    @property
    def loop_total(self) -> np.ndarray:
        return np.array([len(f) for f in self.faces], dtype=np.int64)

    @property
    def loop_start(self) -> np.ndarray:
        return np.concatenate([[0], np.cumsum(self.loop_total)[:-1]]).astype(np.int64)

    @property
    def corner_verts(self) -> np.ndarray:
        return np.concatenate(self.faces).astype(np.int64)

    def layout(self) -> UVLayout:
        return weld_uv(self.loop_start, self.loop_total, self.corner_verts, self.uv)

    def targets(self) -> np.ndarray:
        """3D face shapes (what the operator's default target, 3D Faces, passes)."""
        fs = faces_from_csr(self.loop_start, self.loop_total, self.corner_verts,
                            self.co.shape[0])
        return face_shapes_2d(self.co, fs)

    def move(self, vertex: int, to: tuple[float, float]) -> None:
        """Every loop of ``vertex`` to the UV ``to``."""
        self.uv[self.corner_verts == vertex] = to


def uv_map(points: np.ndarray, faces: list[list[int]]) -> UVMap:
    co = np.column_stack([points, np.zeros(len(points))])
    cv = np.concatenate(faces)
    return UVMap(co, faces, co[cv, :2].astype(np.float32))


def _v(i: int, j: int) -> int:
    return j * (N + 1) + i


def knife_grid() -> UVMap:
    """4 x 4 unit quads; face 0 a pentagon with a vertex at (0.5, 0) in the middle of its
    straight island-border edge (a knife cut, then unwrapped)."""
    pts = [(float(i), float(j)) for j in range(N + 1) for i in range(N + 1)] + [(0.5, 0.0)]
    faces = []
    for j in range(N):
        for i in range(N):
            f = [_v(i, j), _v(i + 1, j), _v(i + 1, j + 1), _v(i, j + 1)]
            if i == j == 0:
                f.insert(1, len(pts) - 1)
            faces.append(f)
    return uv_map(np.array(pts), faces)


def inner_vertices() -> list[int]:
    return [_v(i, j) for j in range(1, N) for i in range(1, N)]


def jittered(amount: float, seed: int = 1) -> UVMap:
    m = knife_grid()
    rng = np.random.default_rng(seed)
    for v in inner_vertices():
        m.move(v, tuple(m.co[v, :2] + rng.uniform(-amount, amount, 2)))
    return m


def l_island() -> UVMap:
    """An L-shaped island whose hexagon at the reentrant corner (2, 2) is concave there."""
    pts = [(0, 0), (1, 0), (3, 0), (4, 0), (0, 1), (1, 1), (3, 1), (4, 1), (2, 2), (3, 2),
           (4, 2), (0, 3), (1, 3), (2, 3), (0, 4), (1, 4), (2, 4)]
    k = {v: i for i, v in enumerate(pts)}
    faces = [[(0, 0), (1, 0), (1, 1), (0, 1)], [(1, 0), (3, 0), (3, 1), (1, 1)],
             [(3, 0), (4, 0), (4, 1), (3, 1)], [(3, 1), (4, 1), (4, 2), (3, 2)],
             [(0, 1), (1, 1), (1, 3), (0, 3)], [(1, 1), (3, 1), (3, 2), (2, 2), (2, 3), (1, 3)],
             [(0, 3), (1, 3), (1, 4), (0, 4)], [(1, 3), (2, 3), (2, 4), (1, 4)]]
    return uv_map(np.array(pts, dtype=float), [[k[v] for v in f] for f in faces])


def every(lay: UVLayout) -> np.ndarray:
    return np.ones(lay.faces.n_faces, dtype=bool)


KEPT_NOTE = ("1 face kept as given (1 straight corner of fixed vertices only: valid, measured "
             "without those vertices)")


@pytest.mark.parametrize("targets", [False, True], ids=["regular", "3d"])
def test_knife_cut_pentagon_untouched_is_valid(targets):
    m = knife_grid()
    lay = m.layout()
    sel = every(lay)
    tg = m.targets() if targets else None
    before = measure(lay, lay.points, sel, tg)
    assert (before.flipped, before.inverted, before.overlapping, before.kept) == (0, 0, 0, 1)
    assert before.distortion_worst == before.distortion_mean == 1.0  # measured as its square
    assert not flipped_faces(lay, lay.points, corners=True).any()
    assert not tangled_faces(lay, lay.points, sel).any()
    res = untangle_uv(lay, sel, targets=tg)
    assert res.status == "valid" and res.message == "" and not res.moved.any()
    assert res.n_kept == 1 and res.notes == [KEPT_NOTE]
    assert [(r.status, r.inverted_left, r.n_kept) for r in res.islands] == [("valid", 0, 1)]
    after = measure(lay, res.points, sel, tg)
    assert (after.flipped, after.inverted, after.kept) == (0, 0, 1)


def test_paper_mode_counts_every_corner():
    lay = knife_grid().layout()
    sel = every(lay)
    assert measure(lay, lay.points, sel, keep=False).inverted == 1
    assert measure(lay, lay.points, sel, keep=False).kept == 0
    assert np.flatnonzero(flipped_faces(lay, lay.points, corners=True, keep=False)).tolist() \
        == [0]
    res = untangle_uv(lay, sel, params=EEGTParams(untangle="eegt"))
    assert res.status == "failed" and res.n_kept == 0 and res.islands[0].n_kept == 0
    assert res.message.startswith("1 face stays inverted")


def test_jittered_interior_smooths_and_untangles():
    m = jittered(0.3)  # no fold: smoothed
    lay = m.layout()
    sel = every(lay)
    before = measure(lay, lay.points, sel)
    assert before.inverted == 0
    res = untangle_uv(lay, sel)
    after = measure(lay, res.points, sel)
    assert res.status == "valid" and res.notes == [KEPT_NOTE]
    assert after.inverted == 0 and after.kept == 1
    assert after.distortion_mean > before.distortion_mean
    assert after.distortion_worst > before.distortion_worst
    border = boundary_nodes(lay.n_nodes, lay.faces)
    assert np.array_equal(res.points[border], lay.points[border]) and res.moved[~border].all()
    m = jittered(0.7)  # folds: untangled
    lay = m.layout()
    before = measure(lay, lay.points, sel)
    assert before.inverted > 0 and before.kept == 1
    res = untangle_uv(lay, sel)
    after = measure(lay, res.points, sel)
    assert res.status == "untangled" and res.message == ""
    assert (after.flipped, after.inverted, after.overlapping) == (0, 0, 0)
    assert after.distortion_mean > before.distortion_mean


@pytest.mark.parametrize("scope", ["tangles", "selection"])
def test_dragged_interior_vertex_untangles(scope):
    m = knife_grid()
    m.move(_v(2, 2), (3.6, 3.4))  # the centre dragged across its neighbours
    lay = m.layout()
    sel = every(lay)
    before = measure(lay, lay.points, sel)
    assert before.inverted == 3 and before.flipped == 1 and before.kept == 1
    res = untangle_uv(lay, sel, scope=scope)
    after = measure(lay, res.points, sel)
    assert res.status == "untangled" and res.message == ""
    assert (after.flipped, after.inverted, after.overlapping) == (0, 0, 0)
    assert after.distortion_worst > 0.9
    assert [r.status for r in res.islands] == ["untangled"]


def test_reentrant_hexagon_island_is_valid():
    m = l_island()
    lay = m.layout()
    sel = every(lay)
    before = measure(lay, lay.points, sel)
    assert (before.inverted, before.kept, before.overlapping) == (0, 1, 0)
    res = untangle_uv(lay, sel)
    assert res.status == "valid" and res.message == ""
    assert res.notes == ["1 face kept as given (1 concave corner of fixed vertices only: "
                         "valid, measured without those vertices)"]
    after = measure(lay, res.points, sel)
    assert after.inverted == 0 and after.distortion_mean >= before.distortion_mean


def test_truly_inverted_fixed_face_still_fails():
    # the knife's vertex moved along the border past its neighbour (1, 0): the pentagon's
    # border runs back over itself (not a simple polygon), every corner fixed once (1, 1)
    # is pinned
    m = knife_grid()
    m.move((N + 1) ** 2, (1.5, 0.0))
    lay = m.layout()
    sel = every(lay)
    pins = np.zeros(lay.n_nodes, dtype=bool)
    pins[lay.loop_node[m.corner_verts == _v(1, 1)]] = True
    assert measure(lay, lay.points, sel, fixed=pins).kept == 0
    res = untangle_uv(lay, sel, fixed=pins)
    assert res.status == "failed" and res.n_kept == 0
    assert res.message == ("1 face stays inverted: every corner of it is pinned or on an "
                           "island border")
    assert np.flatnonzero(flipped_faces(lay, res.points, corners=True, fixed=pins)).tolist() \
        == [0]


def test_pinned_concave_quad_is_kept():
    # a dart quad whose concave corner and its neighbours are pinned: no move changes it,
    # it is valid (the mesh path's rule); unpinned, it is untangled
    m = knife_grid()
    m.move(_v(2, 2), (1.4, 1.4))  # face [(1,1), (2,1), (2,2), (1,2)] concave at (2, 2)
    lay = m.layout()
    sel = every(lay)
    node = lay.loop_node[m.corner_verts == _v(2, 2)][0]
    pins = np.zeros(lay.n_nodes, dtype=bool)
    pins[[lay.loop_node[m.corner_verts == v][0] for v in (_v(2, 1), _v(2, 2), _v(1, 2))]] = True
    found = kept_as_given(lay, sel, pins)
    dart = int(np.flatnonzero(kept_face_mask(lay, found) & ~kept_face_mask(
        lay, kept_as_given(lay, sel))).item())
    assert node in lay.faces.indices[lay.faces.offsets[dart]:lay.faces.offsets[dart + 1]]
    assert measure(lay, lay.points, sel).inverted > 0
    res = untangle_uv(lay, sel, fixed=pins)
    assert res.status in ("valid", "untangled") and res.n_kept == 2
    assert measure(lay, res.points, sel, fixed=pins).inverted == 0
    assert np.array_equal(res.points[pins], lay.points[pins])


def cut_across() -> UVMap:
    """4 x 4 quads whose inner edge (2, 1)-(2, 2) is split at (2, 1.5): the faces either
    side are pentagons (a partial loop cut)."""
    m = knife_grid()
    pts = np.vstack([m.co[:, :2], [(2.0, 1.5)]])
    faces = [list(f) for f in m.faces]
    mid = len(pts) - 1
    left, right = 1 * N + 1, 1 * N + 2  # faces (1, 1) and (2, 1)
    faces[left].insert(2, mid)  # (1,1) (2,1) [mid] (2,2) (1,2)
    faces[right].insert(4, mid)  # (2,1) (3,1) (3,2) (2,2) [mid]
    return uv_map(pts, faces)


def test_straight_corner_on_the_selection_border_is_kept():
    m = cut_across()
    lay = m.layout()
    left, right = N + 1, N + 2
    sel = every(lay)
    sel[right] = False  # the cut edge is the selection's border
    assert measure(lay, lay.points, sel).inverted == 0
    assert measure(lay, lay.points, sel).kept == 2  # with the knife's pentagon
    res = untangle_uv(lay, sel)
    assert res.status == "valid" and res.n_kept == 2
    assert np.flatnonzero(kept_face_mask(lay, kept_as_given(lay, sel))).tolist() == [0, left]
    # everything selected: the cut vertex is free (inside the island), so the straight
    # corners count; the pair has it as an inner corner of two faces only
    every_face = every(lay)
    assert measure(lay, lay.points, every_face).inverted == 2
    assert np.flatnonzero(flipped_faces(lay, lay.points, corners=True)).tolist() == [left, right]


def notch_filled() -> tuple[UVMap, list[int]]:
    """The L island with its notch filled by four quads (one island, a square); the
    hexagon starts at (3, 1), so a fan from its first corner covers the notch. The
    reentrant corner and its neighbours, pinned, make the hexagon kept as given."""
    m = l_island()
    pts = [tuple(p) for p in m.co[:, :2].tolist()] + [(3.0, 3.0), (4.0, 3.0), (3.0, 4.0),
                                                        (4.0, 4.0)]
    k = {(float(x), float(y)): i for i, (x, y) in enumerate(pts)}
    faces = [list(f) for f in m.faces]
    faces[5] = faces[5][1:] + faces[5][:1]  # (3,1) (3,2) (2,2) (2,3) (1,3) (1,1)
    for quad in ([(2, 2), (3, 2), (3, 3), (2, 3)], [(3, 2), (4, 2), (4, 3), (3, 3)],
                 [(2, 3), (3, 3), (3, 4), (2, 4)], [(3, 3), (4, 3), (4, 4), (3, 4)]):
        faces.append([k[(float(x), float(y))] for x, y in quad])
    out = uv_map(np.array(pts), faces)
    return out, [k[(3.0, 2.0)], k[(2.0, 2.0)], k[(2.0, 3.0)]]


def test_overlap_check_cuts_kept_concave_faces_inside_them():
    m, corner = notch_filled()
    lay = m.layout()
    sel = every(lay)
    pins = np.zeros(lay.n_nodes, dtype=bool)
    pins[[lay.loop_node[m.corner_verts == v][0] for v in corner]] = True
    assert lay.n_islands == 1
    fanned = overlapping_faces(lay.points, lay.faces, lay.island)
    assert fanned[5] and fanned.sum() >= 2  # the fan across the notch covers its quads
    found = kept_as_given(lay, sel, pins)
    assert np.flatnonzero(kept_face_mask(lay, found)).tolist() == [5]
    exact = overlapping_faces(lay.points, lay.faces, lay.island,
                              exact=kept_face_mask(lay, found))
    assert not exact.any()
    got = measure(lay, lay.points, sel, fixed=pins)
    assert (got.inverted, got.overlapping, got.kept) == (0, 0, 1)
    assert not tangled_faces(lay, lay.points, sel, fixed=pins).any()
    res = untangle_uv(lay, sel, fixed=pins)
    assert res.status == "valid" and res.n_kept == 1
    # unpinned, (2, 2) is an inner UV vertex: the hexagon's reflex corner can move
    assert measure(lay, lay.points, sel).inverted == 1


def test_mirrored_island_keeps_the_same_corners():
    m = jittered(0.7)
    mirrored = jittered(0.7)
    mirrored.uv[:, 0] *= -1.0  # exact
    a, b = m.layout(), mirrored.layout()
    assert b.orientation().tolist() == [-1]
    sel = every(a)
    ra, rb = untangle_uv(a, sel), untangle_uv(b, sel)
    assert ra.status == rb.status == "untangled" and ra.n_kept == rb.n_kept == 1
    assert np.array_equal(rb.points * [-1.0, 1.0], ra.points)  # bit for bit
    assert measure(b, b.points, sel).kept == 1 and measure(b, rb.points, sel).inverted == 0
