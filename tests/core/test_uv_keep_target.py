"""Target "Keep Shapes" of a UV run (core.uv.uv_targets, issue 37 item 3): each UV face is
pulled towards its own laid-out shape, a tangled face (folded, or dragged over another by the
fold) towards a same-arity neighbour's, else its 3D face's; with scope "tangles"
(``repair``) only the tangles and a margin move."""

from __future__ import annotations

import numpy as np
from uvdata import grid_uv

from core import boundary_nodes
from core.mesh.faces import faces_from_csr
from core.metrics import face_shapes_2d
from core.run.repair import grow_region
from core.uv import (
    flipped_faces,
    keep_shape_targets,
    measure,
    tangled_faces,
    untangle_uv,
    weld_uv,
)

N = 12  # vertices per side of the grid
GROWTH = 1.08  # each column of cells this much wider than the one before
DRAGGED = 5 * N + 5  # the interior vertex (5, 5)


def graded_grid(drag: bool = True, mirror: bool = False):
    """An (N-1) x (N-1) quad grid, unit squares in 3D; its UVs anisotropic and graded:
    cells of height 1, column i of width 4 * GROWTH**i (aspect 4:1 growing to 8.6:1). With
    ``drag`` the UV vertex (5, 5) is dragged across its right neighbour (to the middle of
    column 6, 0.3 up): two faces fold (a crossed corner), four more overlap. ``mirror``:
    u -> -u (exact)."""
    grid = grid_uv(N)  # the mesh; its UVs are set here
    co, ls, lt, cv = grid.co, grid.loop_start, grid.loop_total, grid.corner_verts
    width = 4.0 * GROWTH ** np.arange(N - 1)
    u = np.concatenate([[0.0], np.cumsum(width)])
    uv = np.stack([u[np.tile(np.arange(N), N)], co[:, 1]], axis=1)
    if drag:
        uv[DRAGGED] = (u[6] + 0.5 * width[6], 5.3)
    if mirror:
        uv[:, 0] = -uv[:, 0]
    lay = weld_uv(ls, lt, cv, uv[cv].astype(np.float32))
    shapes3d = face_shapes_2d(co, faces_from_csr(ls, lt, cv, co.shape[0]))
    column = np.tile(np.arange(N - 1), N - 1)  # of each face
    return lay, shapes3d, width[column]


def aspect(corners: np.ndarray) -> np.ndarray:
    """(F,) width / height of quads (F, 4, 2) whose first edge runs along u."""
    e = np.roll(corners, -1, axis=1) - corners
    length = np.hypot(e[..., 0], e[..., 1])
    return (length[:, 0] + length[:, 2]) / (length[:, 1] + length[:, 3])


def every(lay) -> np.ndarray:
    return np.ones(lay.faces.n_faces, dtype=bool)


def edge_neighbours(lay, f: int) -> set[int]:
    """Faces sharing an edge (two UV vertices) with face ``f``."""
    quads = lay.faces.indices.reshape(-1, 4)
    share = np.isin(quads, quads[f]).sum(axis=1)
    return set(np.flatnonzero(share == 2).tolist())


def test_untangled_faces_keep_their_own_corners_tangled_ones_a_neighbours_shape():
    lay, shapes3d, layout_aspect = graded_grid()
    sel = every(lay)
    ks = keep_shape_targets(lay, shapes3d=shapes3d)
    folded = flipped_faces(lay, lay.points, corners=True)
    assert np.flatnonzero(folded).tolist() == [49, 60]  # right of (5, 5), rows 4 and 5
    # the folded faces and the faces the fold drags over others (left and right of them)
    assert np.flatnonzero(ks.tangled).tolist() == [48, 49, 50, 59, 60, 61]
    assert np.array_equal(ks.tangled, tangled_faces(lay, lay.points, sel))
    assert np.array_equal(ks.from_neighbour, ks.tangled) and not ks.from_3d.any()
    assert ks.note() == "6 tangled faces took the shape of: 6 a neighbour's"
    own = lay.points[lay.faces.indices]
    rows = np.repeat(ks.tangled, 4)
    assert np.array_equal(ks.targets[~rows], own[~rows])  # bit for bit
    tq, oq = ks.targets.reshape(-1, 4, 2), own.reshape(-1, 4, 2)
    spread = ks.targets.copy()  # the neighbours' shapes (or the shapes they were given)
    for f in np.flatnonzero(ks.tangled):  # a neighbour's corners, turned half a turn
        assert any(np.array_equal(tq[f], -np.roll(spread.reshape(-1, 4, 2)[g], k, axis=0))
                   for g in edge_neighbours(lay, f) for k in range(4))
    assert all(any(np.array_equal(tq[f], -np.roll(oq[g], k, axis=0))
                   for g in edge_neighbours(lay, f) if not ks.tangled[g] for k in range(4))
               for f in (49, 60))  # both folded faces: an untangled neighbour's own corners
    got = aspect(tq[ks.tangled])
    # each has a neighbour's aspect (its own column's, the one left or right: 5.4 to 6.9),
    # the layout's 4:1-and-wider, not 1:1
    near = layout_aspect[ks.tangled][:, None] * GROWTH ** np.array([-1.0, 0.0, 1.0])
    assert np.isclose(got[:, None], near, rtol=1e-6).any(axis=1).all()
    assert np.allclose(got, [5.442, 5.877, 6.347, 5.442, 5.877, 6.855], rtol=1e-3)


def test_targets_of_a_mirrored_island_are_its_corners_turned_counterclockwise():
    lay, shapes3d, _ = graded_grid(mirror=True)
    assert lay.orientation().tolist() == [-1]
    ks = keep_shape_targets(lay, shapes3d=shapes3d)
    assert np.flatnonzero(ks.tangled).tolist() == [48, 49, 50, 59, 60, 61]
    own = lay.points[lay.faces.indices] * [-1.0, 1.0]
    rows = np.repeat(ks.tangled, 4)
    assert np.array_equal(ks.targets[~rows], own[~rows])
    plain = keep_shape_targets(graded_grid()[0], shapes3d=shapes3d)
    assert np.array_equal(ks.targets, plain.targets)


def test_keep_repair_untangles_and_keeps_everything_outside_the_margin_bit_for_bit():
    lay, shapes3d, _ = graded_grid()
    sel = every(lay)
    ks = keep_shape_targets(lay, shapes3d=shapes3d)
    before = measure(lay, lay.points, sel, ks.targets)
    assert (before.flipped, before.inverted, before.overlapping) == (0, 2, 6)  # crossed
    res = untangle_uv(lay, sel, targets=ks.targets, repair=True)
    assert res.status == "untangled"
    assert not flipped_faces(lay, res.points, corners=True).any()  # 0 flipped, 0 inverted
    after = measure(lay, res.points, sel, ks.targets)
    assert (after.flipped, after.inverted, after.overlapping) == (0, 0, 0)
    # the tangled faces and two rings of faces around them (the first margin) move, and
    # nothing else: every UV vertex of a face outside keeps its bits
    tangled = tangled_faces(lay, lay.points, sel)
    assert np.flatnonzero(tangled).tolist() == [48, 49, 50, 59, 60, 61]
    region = grow_region(lay.faces, lay.n_nodes, tangled, 2)
    outside = np.zeros(lay.n_nodes, dtype=bool)
    outside[lay.faces.indices[np.repeat(~region, 4)]] = True
    assert np.array_equal(res.points[outside], lay.points[outside])
    assert not res.moved[outside].any()
    assert res.moved.sum() == (~outside).sum() == 30 and res.moved[DRAGGED]
    # without the repair, target 3D smooths the whole island once its tangle is undone
    whole = untangle_uv(lay, sel, targets=shapes3d)
    assert whole.moved[outside].any()


def test_moved_faces_keep_the_layouts_aspect_far_better_than_regular():
    lay, shapes3d, layout_aspect = graded_grid()
    sel = every(lay)
    ks = keep_shape_targets(lay, shapes3d=shapes3d)
    keep = untangle_uv(lay, sel, targets=ks.targets, repair=True)
    regular = untangle_uv(lay, sel)  # target Regular as the operator runs it
    assert not flipped_faces(lay, regular.points, corners=True).any()
    quads = lay.faces.indices.reshape(-1, 4)
    moved = keep.moved[quads].any(axis=1)  # the 42 faces the repair reshaped
    assert moved.sum() == 42

    def change(points):
        return np.abs(np.log(aspect(points[quads[moved]]) / layout_aspect[moved]))

    # measured |log aspect change| of those faces against the layout (before the drag):
    # keep median 0.0002, worst 0.039; regular median 0.191, worst 1.378 (target 3D gives
    # the same: the 3D cells are squares)
    kc, rc = change(keep.points), change(regular.points)
    assert np.median(kc) < 0.002 and kc.max() < 0.06
    assert np.median(rc) > 0.15 and rc.max() > 1.0
    assert np.median(kc) * 50 < np.median(rc)


def test_island_without_tangles_is_left_as_laid_out():
    lay, shapes3d, _ = graded_grid(drag=False)
    sel = every(lay)
    ks = keep_shape_targets(lay, shapes3d=shapes3d)
    assert not ks.tangled.any() and ks.note() == ""
    assert np.array_equal(ks.targets, lay.points[lay.faces.indices])
    res = untangle_uv(lay, sel, targets=ks.targets, repair=True)
    assert res.status == "valid" and not res.moved.any()
    assert np.array_equal(res.points, lay.points)
    assert [(r.status, r.message) for r in res.islands] == [
        ("valid", "no tangles: island kept as laid out")]
    m = measure(lay, res.points, sel, ks.targets)
    assert m.distortion_worst == m.distortion_mean == 1.0


def two_triangles():
    """3 x 3 unit cells, quads but for the middle cell, split into two triangles (a, b, c)
    and (a, c, d); in 3D the mesh is twice as tall as wide (its triangles are not the UV
    ones). The UV vertex a (1, 1) is dragged past c (2, 2): both triangles fold, and their
    only neighbours across an edge are quads or each other; the quads around a are tangled
    too (folded or overlapping), the four others are not."""
    def v(i, j):
        return 4 * j + i

    faces = []
    for j in range(3):
        for i in range(3):
            a, b, c, d = v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)
            faces += [[a, b, c], [a, c, d]] if (i, j) == (1, 1) else [[a, b, c, d]]
    g = np.arange(4, dtype=np.float64)
    x, y = np.meshgrid(g, g)
    co = np.stack([x.ravel(), 2.0 * y.ravel(), np.zeros(16)], axis=1)
    lt = np.array([len(f) for f in faces], dtype=np.int64)
    ls = np.concatenate([[0], np.cumsum(lt)[:-1]]).astype(np.int64)
    cv = np.concatenate(faces).astype(np.int64)
    uv = np.stack([x.ravel(), y.ravel()], axis=1)
    uv[v(1, 1)] = (2.5, 2.5)
    lay = weld_uv(ls, lt, cv, uv[cv].astype(np.float32))
    return lay, face_shapes_2d(co, faces_from_csr(ls, lt, cv, 16))


UNIT = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def test_tangled_face_without_a_same_arity_neighbour_takes_its_3d_shape():
    lay, shapes3d = two_triangles()
    fs = lay.faces
    tri = fs.counts == 3  # faces 4 and 5
    quads = np.isin(np.arange(fs.n_faces), [0, 1, 3, 6, 8, 9])  # those around a
    ks = keep_shape_targets(lay, shapes3d=shapes3d)
    assert np.array_equal(ks.tangled, tri | quads)
    assert np.array_equal(ks.from_3d, tri) and np.array_equal(ks.from_neighbour, quads)
    assert ks.note() == "8 tangled faces took the shape of: 6 a neighbour's, 2 their 3D face's"
    rows = np.repeat(tri, fs.counts)
    assert np.array_equal(ks.targets[rows], shapes3d[rows])  # bit for bit
    for f in np.flatnonzero(quads):  # a unit square of the layout, turned half a turn
        t = ks.targets[fs.offsets[f]:fs.offsets[f + 1]]
        assert np.array_equal(t - t.min(axis=0), UNIT)
    own = ~np.repeat(tri | quads, fs.counts)
    assert np.array_equal(ks.targets[own], lay.points[fs.indices[own]])
    # without 3D shapes the triangles keep their folded corners: the core's regular polygon
    bare = keep_shape_targets(lay)
    assert bare.n_own == 2 and not bare.from_3d.any()
    assert bare.note() == "8 tangled faces took the shape of: 6 a neighbour's, 2 their own"
    assert np.array_equal(bare.targets[rows], lay.points[fs.indices[rows]])
    res = untangle_uv(lay, every(lay), targets=ks.targets, repair=True)
    assert res.status == "untangled" and res.n_target_fallback == 0
    assert not flipped_faces(lay, res.points, corners=True).any()
    assert res.moved.sum() == 4  # the inner UV vertices (the island border stays)
    assert not res.moved[boundary_nodes(lay.n_nodes, fs)].any()
