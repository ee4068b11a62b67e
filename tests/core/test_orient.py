"""Consistent face orientation (core/mesh/orient.py): which faces to reverse so every
interior edge is walked once each way, each component counterclockwise, decided by topology
(folded faces stay as they are), and a non-orientable strip refused with one line."""

import numpy as np
import pytest

from core.mesh import FaceSet, as_faceset, orient_faces, reverse_faces
from core.mesh.topology import EdgeInfo, free_nodes


def _grid(nx: int, ny: int, tris: bool = False) -> tuple[np.ndarray, FaceSet]:
    """A counterclockwise nx x ny grid of unit quads (or each quad as two triangles, every
    other row, so the arities mix)."""
    xs, ys = np.meshgrid(np.arange(nx + 1.0), np.arange(ny + 1.0))
    pts = np.column_stack([xs.ravel(), ys.ravel()])
    faces = []
    for j in range(ny):
        for i in range(nx):
            a = j * (nx + 1) + i
            b, c, d = a + 1, a + nx + 2, a + nx + 1
            if tris and j % 2:
                faces += [[a, b, c], [a, c, d]]
            else:
                faces.append([a, b, c, d])
    return pts, as_faceset(faces, pts.shape[0])


def _signed_areas(pts: np.ndarray, fs: FaceSet) -> np.ndarray:
    out = np.zeros(fs.n_faces)
    for f, face in enumerate(fs.to_lists()):
        p = pts[face]
        q = np.roll(p, -1, axis=0)
        out[f] = 0.5 * np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1])
    return out


def _consistent(fs: FaceSet, n: int) -> bool:
    return EdgeInfo(fs, n).first_conflict() is None


def test_reverse_faces_keeps_the_first_corner_and_the_face_order():
    fs = as_faceset([[0, 1, 2, 3], [1, 4, 2]], 5)
    out = reverse_faces(fs, np.array([True, False]))
    assert out.to_lists() == [[0, 3, 2, 1], [1, 4, 2]]
    assert reverse_faces(out, np.array([True, False])).to_lists() == fs.to_lists()
    assert reverse_faces(fs, np.zeros(2, bool)) is fs
    with pytest.raises(ValueError, match="flip must be"):
        reverse_faces(fs, np.zeros(3, bool))


@pytest.mark.parametrize("tris", [False, True])
def test_mixed_orientation_grid_is_turned_back_face_by_face(tris):
    pts, fs = _grid(12, 9, tris)
    rng = np.random.default_rng(3)
    mixed = rng.random(fs.n_faces) < 0.45
    read = reverse_faces(fs, mixed)
    with pytest.raises(ValueError, match="not consistently oriented"):
        free_nodes(pts.shape[0], read)
    o = orient_faces(read, pts.shape[0], pts)
    assert np.array_equal(o.flip, mixed) and o.n_flipped == int(mixed.sum())
    assert o.n_components == 1 and not o.component.any()
    back = o.apply(read)
    assert np.array_equal(back.indices, fs.indices) and np.array_equal(back.offsets, fs.offsets)
    free_nodes(pts.shape[0], back)  # accepted now
    assert (_signed_areas(pts, back) > 0).all()


def test_clockwise_only_mesh_is_reversed_whole():
    pts, fs = _grid(7, 5, tris=True)
    cw = fs.reversed()  # every face clockwise, consistently
    assert _consistent(cw, pts.shape[0])
    o = orient_faces(cw, pts.shape[0], pts)
    assert o.flip.all()
    assert (_signed_areas(pts, o.apply(cw)) > 0).all()
    # 3D points in z = 0 and a tilted plane: the same choice (seen from +z)
    pts3 = np.column_stack([pts, np.zeros(len(pts))])
    assert orient_faces(cw, len(pts), pts3).flip.all()
    tilt = np.column_stack([pts[:, 0], 0.8 * pts[:, 1], 0.6 * pts[:, 1] + 5.0])
    assert orient_faces(cw, len(pts), tilt).flip.all()  # normal (0, -0.6, 0.8) once turned
    assert not orient_faces(fs, len(pts), tilt).flip.any()
    steep = np.column_stack([pts[:, 0], 0.6 * pts[:, 1], 0.8 * pts[:, 1]])  # (0, -0.8, 0.6):
    assert not orient_faces(cw, len(pts), steep).flip.any()  # seen from +y, cw is ccw
    # without points, consistent faces are left as they are (the first face decides)
    assert not orient_faces(cw, len(pts)).flip.any()


def test_folded_faces_of_a_tangled_mesh_are_not_flipped():
    pts, fs = _grid(6, 6, tris=True)
    n = pts.shape[0]
    tangled = pts.copy()
    inner = 3 * 7 + 3  # the centre node, dragged past its neighbours
    tangled[inner] += [2.5, 2.2]
    folded = _signed_areas(tangled, fs) < 0
    assert folded.sum() >= 2  # faces with a negative own area, still counterclockwise
    o = orient_faces(fs, n, tangled)
    assert not o.flip.any()
    rng = np.random.default_rng(7)
    mixed = rng.random(fs.n_faces) < 0.5
    mixed[np.flatnonzero(folded)[0]] = True  # a folded face read clockwise too
    mixed[np.flatnonzero(folded)[1]] = False
    o = orient_faces(reverse_faces(fs, mixed), n, tangled)
    assert np.array_equal(o.flip, mixed)
    assert np.array_equal(o.apply(reverse_faces(fs, mixed)).indices, fs.indices)


def test_each_component_is_oriented_by_its_own_area():
    pts, fs = _grid(4, 3)
    n = pts.shape[0]
    far = pts + np.array([10.0, 0.0])  # a second copy beside the first, read clockwise
    both = np.vstack([pts, far])
    faces = fs.to_lists() + [list(reversed([v + n for v in f])) for f in fs.to_lists()]
    two = as_faceset(faces, 2 * n)
    o = orient_faces(two, 2 * n, both)
    assert o.n_components == 2
    assert np.array_equal(o.component, np.repeat([0, 1], fs.n_faces))
    assert np.array_equal(o.flip, np.repeat([False, True], fs.n_faces))


def test_non_manifold_edges_relate_nothing():
    # three triangles on edge (0, 1): the edge is held, each triangle turned on its own
    pts = np.array([[0, 0], [1, 0], [0.5, 1], [0.5, -1], [0.7, 0.8]], dtype=float)
    fs = as_faceset([[0, 1, 2], [0, 3, 1], [1, 0, 4]], 5)
    o = orient_faces(fs, 5, pts)
    assert o.n_components == 3
    assert np.array_equal(o.flip, [False, False, True])
    free_nodes(5, o.apply(fs))


def _moebius(n: int = 8) -> tuple[np.ndarray, list[list[int]]]:
    """A ring of n quads whose last one closes with a half twist (a Moebius strip),
    flattened into the plane (inner node k, outer node n + k)."""
    t = 2 * np.pi * np.arange(n) / n
    pts = np.vstack([np.column_stack([np.cos(t), np.sin(t)]),
                     2 * np.column_stack([np.cos(t), np.sin(t)])])
    faces = [[k, n + k, n + k + 1, k + 1] for k in range(n - 1)]
    faces.append([n - 1, 2 * n - 1, 0, n])  # inner meets outer: the twist
    return pts, faces


def test_moebius_strip_is_refused_with_one_line():
    pts, faces = _moebius()
    with pytest.raises(ValueError, match="cannot be oriented consistently") as info:
        orient_faces(faces, pts.shape[0], pts)
    assert "\n" not in str(info.value) and "edge (" in str(info.value)
    # the same ring without the twist is an annulus: oriented
    n = pts.shape[0] // 2
    ring = [[k, n + k, n + (k + 1) % n, (k + 1) % n] for k in range(n)]
    o = orient_faces(ring, 2 * n, pts)
    assert not o.flip.any() and o.n_components == 1  # inner, outer, outer, inner: ccw
    o = orient_faces([f[::-1] for f in ring[:3]] + ring[3:], 2 * n, pts)
    assert np.array_equal(o.flip, np.arange(n) < 3)


def test_large_shuffled_mesh_in_few_passes():
    pts, fs = _grid(120, 90, tris=True)
    rng = np.random.default_rng(11)
    perm = rng.permutation(fs.n_faces)  # faces in no spatial order
    lists = fs.to_lists()
    shuffled = as_faceset([lists[k] for k in perm], pts.shape[0])
    mixed = rng.random(fs.n_faces) < 0.5
    o = orient_faces(reverse_faces(shuffled, mixed), pts.shape[0], pts)
    assert np.array_equal(o.flip, mixed)


def test_points_are_checked():
    pts, fs = _grid(2, 2)
    with pytest.raises(ValueError, match="points must be"):
        orient_faces(fs, pts.shape[0], pts[:-1])
    bad = pts.copy()
    bad[4, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        orient_faces(fs, pts.shape[0], bad)
