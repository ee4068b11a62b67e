"""Region "folds" (core/run/repair.py): only the folded faces and a margin grown while needed
move, every other node keeps its bits; target "keep" pulls faces towards their own shapes."""

from types import SimpleNamespace

import numpy as np
import pytest

from core import EEGTParams, mesh_stats, quality, untangle_and_smooth
from core.mesh.faces import as_faceset
from core.run.repair import (
    DRAGGED_RINGS,
    FIRST_RINGS,
    ROOM,
    folded_faces,
    grow_region,
    keep_targets,
    repair_folds,
)


def _grid(n: int) -> tuple[np.ndarray, list[list[int]]]:
    m = n + 1
    xs, ys = np.meshgrid(np.arange(m, dtype=float), np.arange(m, dtype=float))
    p = np.column_stack([xs.ravel(), ys.ravel()])
    return p, [[m * j + i, m * j + i + 1, m * j + i + m + 1, m * j + i + m]
               for j in range(n) for i in range(n)]


def _o_grid(n_around: int = 48, first: float = 1e-3, growth: float = 1.25
            ) -> tuple[np.ndarray, list[list[int]]]:
    """Quads around a unit circle, rows growing geometrically from `first` to radius 8 (a
    boundary layer: aspect about 2 pi / n_around / first at the wall)."""
    radii, h = [1.0], first
    while radii[-1] + h < 8.0:
        radii.append(radii[-1] + h)
        h *= growth
    radii[-1] = 8.0
    r = np.asarray(radii)
    t = 2.0 * np.pi * np.arange(n_around) / n_around
    p = np.column_stack([np.outer(r, np.cos(t)).ravel(), np.outer(r, np.sin(t)).ravel()])
    faces = [[i * n_around + j, (i + 1) * n_around + j, (i + 1) * n_around + (j + 1) % n_around,
              i * n_around + (j + 1) % n_around]
             for i in range(r.size - 1) for j in range(n_around)]
    return p, faces


def _turned_wall(p: np.ndarray, degrees: float, shift: tuple[float, float] = (0.3, 0.1),
                 reach: float = 1.6) -> np.ndarray:
    """The wall (unit circle) turned about the centre and shifted; nodes follow by a weight
    falling from 1 at the wall to 0 at radius `reach` (the thin cells fold where it falls
    and the wall comes closer)."""
    r = np.hypot(p[:, 0], p[:, 1])
    s = np.clip((r - 1.0) / (reach - 1.0), 0.0, 1.0)
    w = ((1.0 - s) ** 3 * (1.0 + 3.0 * s))[:, None]
    a = np.radians(degrees)
    c, si = np.cos(a), np.sin(a)
    moved = np.column_stack([c * p[:, 0] - si * p[:, 1] + shift[0],
                             si * p[:, 0] + c * p[:, 1] + shift[1]])
    return p + w * (moved - p)


def _first_heights(p: np.ndarray, n_around: int) -> np.ndarray:
    """Height of each wall cell's first layer: the distance from the wall node to the node
    above it."""
    return np.hypot(*(p[n_around:2 * n_around] - p[:n_around]).T)


@pytest.mark.parametrize("target", ["keep", "regular", "reference"])
def test_folds_only_moves_a_margin_around_the_folds_and_keeps_every_other_bit(target):
    p, faces = _o_grid()
    bent = _turned_wall(p, 25.0)
    before = mesh_stats(bent, faces)
    assert before.n_inverted > 0
    wall = np.hypot(p[:, 0], p[:, 1]) < 1.0 + 1e-12
    res = untangle_and_smooth(bent, faces, fixed=wall, reference_points=None if target != \
                              "reference" else p, params=EEGTParams(region="folds", target=target))
    assert res.status == "untangled", res.message
    assert mesh_stats(res.points, faces).n_inverted == 0
    assert res.message.startswith("folds only: ")
    stay = ~res.moved
    assert np.array_equal(res.points[stay], bent[stay])  # bit for bit
    assert 0 < res.moved.sum() < 0.5 * len(p)
    assert np.array_equal(res.points[wall], bent[wall])


def test_whole_mesh_run_pulls_the_boundary_layer_to_squares_folds_only_keeps_it():
    """The first layer at the wall: region 'mesh' with regular targets makes it tens of times
    taller (towards squares); region 'folds' with target 'keep' leaves every wall cell's first
    layer that is outside the region as it was, bit for bit, and the rest within 2 x."""
    n_around = 48
    p, faces = _o_grid(n_around)
    bent = _turned_wall(p, 25.0)
    wall = np.hypot(p[:, 0], p[:, 1]) < 1.0 + 1e-12
    h0 = _first_heights(bent, n_around)
    whole = untangle_and_smooth(bent, faces, fixed=wall)
    folds = untangle_and_smooth(bent, faces, fixed=wall,
                                params=EEGTParams(region="folds", target="keep"))
    assert whole.after.n_inverted == 0 and folds.after.n_inverted == 0
    assert np.median(_first_heights(whole.points, n_around) / h0) > 10.0
    ratio = _first_heights(folds.points, n_around) / h0
    assert np.max(np.abs(np.log(ratio))) < np.log(2.0)


def test_a_pinned_handle_dragged_far_grows_the_margin_until_the_fold_opens():
    """A pinned node dragged 6.3 cells across a 30 x 30 grid: the first margin (FIRST_RINGS
    rings) cannot hold the neighbours it pushes; the region doubles until it can."""
    p, faces = _grid(30)
    c = 15 * 31 + 15
    q = p.copy()
    q[c] += [6.3, 0.4]
    pin = np.zeros(len(p), dtype=bool)
    pin[c] = True
    res = untangle_and_smooth(q, faces, fixed=pin, params=EEGTParams(region="folds",
                                                                     target="keep"))
    assert res.status == "untangled" and res.after.n_inverted == 0, res.message
    assert f"({4 * FIRST_RINGS} rings around the folded ones)" in res.message, res.message
    assert np.array_equal(res.points[~res.moved], q[~res.moved])


def _mirrored_disk(radius: float) -> tuple[np.ndarray, object, np.ndarray]:
    """A 40 x 40 grid whose nodes within `radius` of the centre are mirrored across it and
    stretched 4 times in x (the disk's cells inverted, 4 times their area): (points, faces,
    free)."""
    from core import boundary_nodes

    p, faces = _grid(40)
    fs = as_faceset(faces, len(p))
    inside = np.hypot(p[:, 0] - 20.0, p[:, 1] - 20.0) < radius
    p[inside, 0] = 20.15 - 4.0 * (p[inside, 0] - 20.0)
    return p, fs, ~boundary_nodes(len(p), fs)


def _inverted_share(p, fs, free, rings: int) -> float:
    """The inverted faces' area over the valid faces' area in the region of `rings`."""
    from core.mesh.faces import face_subset
    from core.metrics.face_quality import signed_face_areas

    region = grow_region(fs, len(p), folded_faces(p, fs, free), rings)
    sub, nodes, _ = face_subset(fs, np.flatnonzero(region))
    a = signed_face_areas(p[nodes], sub)
    return float(-a[a < 0].sum() / a[a > 0].sum())


@pytest.mark.parametrize(("radius", "rings"),
                         [(2.5, FIRST_RINGS), (4.0, 2 * FIRST_RINGS), (6.5, 4 * FIRST_RINGS)])
def test_the_first_attempt_is_on_a_margin_with_room_for_the_fold(radius, rings):
    """A region whose inverted area is over ROOM x its valid area is not tried: the margin
    doubles first. The mirrored disk of radius 2.5 has 0.32 at FIRST_RINGS rings (tried
    there), that of radius 4.0 0.46 there and 0.28 on twice the rings (its one attempt),
    that of radius 6.5 0.59 and 0.44 (its one attempt on four times the rings)."""
    p, fs, free = _mirrored_disk(radius)
    assert (_inverted_share(p, fs, free, FIRST_RINGS) > ROOM) == (rings > FIRST_RINGS)
    seen = []

    def run(points, faces, **_):
        seen.append(faces.n_faces)
        return SimpleNamespace(status="untangled", points=points)

    got = repair_folds(p, fs, free, EEGTParams(region="folds", target="keep"), None, run)
    assert got.rings == rings and len(seen) == 1
    assert seen[0] == int(grow_region(fs, len(p), folded_faces(p, fs, free), rings).sum())


def test_folds_only_on_a_valid_mesh_moves_nothing():
    p, faces = _grid(6)
    p[8] += [0.1, 0.05]
    res = untangle_and_smooth(p, faces, params=EEGTParams(region="folds"))
    assert res.status == "valid" and not res.moved.any()
    assert np.array_equal(res.points, p)
    assert res.message == "no folded face a move can change: nothing moved (region 'folds')"


def test_keep_targets_on_a_valid_jittered_mesh_keep_every_bit():
    """Every face is already its own target: quality 1 against it, nothing to gain."""
    p, faces = _grid(10)
    rng = np.random.default_rng(1)
    inner = (p[:, 0] > 0) & (p[:, 0] < 10) & (p[:, 1] > 0) & (p[:, 1] < 10)
    p[inner] += rng.normal(0.0, 0.15, (int(inner.sum()), 2))
    res = untangle_and_smooth(p, faces, params=EEGTParams(target="keep"))
    assert res.status == "valid"
    assert np.array_equal(res.points, p)
    assert res.before.q_min > 0.999999 and res.after.q_avg == res.before.q_avg


def test_keep_targets_of_folded_faces_and_their_ring_come_from_the_reference_or_a_neighbour():
    p, faces = _grid(8)
    fs = as_faceset(faces, len(p))
    q = p.copy()
    q[40] = [5.4, 4.6]  # the centre node (4, 4) pushed across its neighbours
    free = np.zeros(len(p), dtype=bool)
    free[[30, 31, 32, 39, 40, 41, 48, 49, 50]] = True
    folded = folded_faces(q, fs, free)
    assert folded.any()
    lost = grow_region(fs, len(p), folded, DRAGGED_RINGS)  # the folded faces and their ring
    assert lost.sum() > folded.sum()
    rows = np.repeat(lost, fs.counts)
    own = keep_targets(q, fs, free, folded)
    assert np.array_equal(own[~rows], q[fs.indices[~rows]])  # the rest: their own corners
    # a folded or dragged face takes a neighbour's shape (a unit square, turned half a turn)
    assert np.array_equal(quality(p, fs, own)[lost], np.ones(int(lost.sum())))
    ref = keep_targets(q, fs, free, folded, reference=p * 2.0)
    assert np.array_equal(ref[rows], 2.0 * p[fs.indices[rows]])
    assert np.array_equal(ref[~rows], q[fs.indices[~rows]])


def test_grow_region_adds_the_faces_sharing_a_node_per_ring():
    p, faces = _grid(5)
    fs = as_faceset(faces, len(p))
    seed = np.zeros(fs.n_faces, dtype=bool)
    seed[12] = True  # the centre face
    assert grow_region(fs, len(p), seed, 1).sum() == 9
    assert grow_region(fs, len(p), seed, 2).sum() == 25
    assert grow_region(fs, len(p), seed, 9).sum() == 25


@pytest.mark.parametrize("bad, why", [
    (dict(target="keep", targets=np.zeros((16, 2))), "give targets or target 'keep', not both"),
    (dict(target="keep", reference_points=np.zeros((3, 2))),
     "reference mesh has 3 vertices, the mesh has 9"),
    (dict(target="regular", reference_points=np.zeros((9, 2))),
     "reference_points given but target is 'regular'"),
])
def test_keep_target_refusals_are_one_line(bad, why):
    p, faces = _grid(2)
    kw = dict(bad)
    params = EEGTParams(target=kw.pop("target"), region="folds")
    with pytest.raises(ValueError, match=why):
        untangle_and_smooth(p, faces, params=params, **kw)


def test_folds_run_stored_as_float32_is_measured_against_the_runs_own_targets():
    """The float32 check of the 3D entry measures the stored result again: against the
    targets the folds run measured with (``EEGTResult.targets``: each face's own corners,
    the region's from its run), not against regular polygons, so before and after speak of
    the same targets."""
    from core.run import untangle_and_smooth_3d

    p, faces = _o_grid()
    bent = _turned_wall(p, 25.0)
    wall = np.hypot(p[:, 0], p[:, 1]) < 1.0 + 1e-12
    p3 = np.column_stack([bent, np.zeros(len(bent))])
    params = EEGTParams(target="keep", region="folds")
    r64 = untangle_and_smooth_3d(p3, faces, fixed=wall, params=params, stored=np.float64)
    r32 = untangle_and_smooth_3d(p3, faces, fixed=wall, params=params, stored=np.float32)
    assert r64.status == r32.status == "untangled"
    assert r32.before == r64.before and r32.after.n_inverted == 0
    assert abs(r32.after.q_avg - r64.after.q_avg) < 1e-6
    assert abs(r32.after.q_min - r64.after.q_min) < 1e-5
    assert r32.targets.shape == (sum(len(f) for f in faces), 2)


def test_corner_rows_list_the_faces_corners_face_after_face_in_the_order_asked():
    """Mixed arities, faces asked out of order: each face's corner rows of ``fs.indices``,
    face after face, as the offsets say (what ``face_subset`` and the folds run's targets
    index with)."""
    from core.mesh.faces import corner_rows

    fs = as_faceset([[0, 1, 2], [1, 3, 4, 2], [2, 4, 5], [3, 6, 7, 8, 4]], 9)
    assert corner_rows(fs, np.array([3, 0, 2])).tolist() == [10, 11, 12, 13, 14, 0, 1, 2, 7, 8, 9]
    assert corner_rows(fs, np.array([], dtype=np.int64)).tolist() == []


def test_region_rim_holds_exactly_the_region_nodes_shared_with_faces_outside():
    """A pinned handle dragged across a 12 x 12 grid: the region that opens the fold holds
    its rim (the nodes it shares with faces outside it) and the fixed nodes, and lets every
    other node of its faces move."""
    from core.run import repair

    p, faces = _grid(12)
    c = 6 * 13 + 6
    q = p.copy()
    q[c] += [1.3, 0.2]
    fs = as_faceset(faces, len(p))
    border = np.isin(np.arange(len(p)) % 13, (0, 12)) | np.isin(np.arange(len(p)) // 13, (0, 12))
    free = ~border
    free[c] = False
    done = repair.repair_folds(q, fs, free, EEGTParams(region="folds", target="keep"), None,
                               untangle_and_smooth)
    assert done.result.status == "untangled" and not done.region.all()
    outside = np.zeros(len(p), dtype=bool)
    outside[np.asarray(faces)[~done.region].ravel()] = True
    rim = outside[done.nodes]
    assert rim.any() and (~rim & free[done.nodes]).any()
    assert np.array_equal(done.held, ~free[done.nodes] | rim)
