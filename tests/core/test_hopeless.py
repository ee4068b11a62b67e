"""Free nodes that no position can fix are recognised before the run (core/run/hopeless.py):
held, their faces reported with the certificate, the rest of the mesh untangled as usual."""

from pathlib import Path

import numpy as np
import pytest

from core import mesh_stats, untangle_and_smooth
from core.mesh import read_obj
from core.mesh.faces import as_faceset
from core.run.hopeless import hopeless_nodes
from core.run.hopeless_groups import hopeless_groups

U_STAR = Path(__file__).resolve().parents[1] / "e2e" / "data" / "u_star_impossible.obj"


def _u_star() -> tuple[np.ndarray, list[list[int]]]:
    p, fs = read_obj(U_STAR)
    faces = [list(map(int, row)) for g in fs.groups for row in g.nodes.T]
    return p[:, :2].copy(), faces


def _tangled_grid(n: int = 4) -> tuple[np.ndarray, list[list[int]]]:
    """n x n unit quads with interior node (2, 2) pushed across its neighbours."""
    m = n + 1
    xs, ys = np.meshgrid(np.arange(m, dtype=float), np.arange(m, dtype=float))
    p = np.column_stack([xs.ravel(), ys.ravel()])
    p[2 * m + 2] = [3.4, 2.6]
    return p, [[m * j + i, m * j + i + 1, m * j + i + m + 1, m * j + i + m]
               for j in range(n) for i in range(n)]


def _star(k: int, centre: tuple[float, float]) -> tuple[np.ndarray, list[list[int]]]:
    """A regular k-gon fan: ring nodes 0..k-1 (boundary, fixed), centre node k (free)."""
    t = 2 * np.pi * np.arange(k) / k
    p = np.vstack([np.column_stack([np.cos(t), np.sin(t)]), centre])
    return p, [[k, i, (i + 1) % k] for i in range(k)]


def test_u_star_fails_at_once_naming_the_faces_and_the_certificate():
    """The U-shaped star (tests/e2e/data/u_star_impossible.obj): its centre needs x > 2 for
    face 3 and x < 1 for face 5. It is held before the run: no optimizer iteration is spent,
    the status is 'failed' and the message names the faces and why."""
    p, f = _u_star()
    res = untangle_and_smooth(p, f)
    assert res.status == "failed"
    assert res.global_iterations == 0 and res.untangle_iterations == 0
    assert res.n_frozen == 2 and res.after.n_inverted == 2
    assert "2 faces stay inverted (faces 3, 5)" in res.message, res.message
    assert ("node 8 is held: with the other vertices of its faces that touch it fixed, no "
            "position of it makes them valid (faces 3, 5 cannot all be valid at once)"
            ) in res.message, res.message
    assert np.array_equal(res.points, p)
    assert not res.moved.any()


def test_u_star_beside_a_tangled_grid_the_grid_is_untangled_and_the_star_reported():
    grid, gf = _tangled_grid()
    star, sf = _u_star()
    shift = len(grid)
    p = np.vstack([grid, star + np.array([10.0, 0.0])])
    f = gf + [[v + shift for v in face] for face in sf]
    assert mesh_stats(grid, gf).n_inverted > 0
    res = untangle_and_smooth(p, f)
    assert res.status == "failed" and res.n_frozen == 2
    assert mesh_stats(res.points[:shift], gf).n_inverted == 0  # the grid: untangled
    assert res.after.n_inverted == 2
    ids = [len(gf) + 3, len(gf) + 5]
    assert f"faces {ids[0]}, {ids[1]}" in res.message, res.message
    assert f"node {shift + 8} is held" in res.message, res.message
    assert np.array_equal(res.points[shift:], p[shift:])


def test_a_tangled_star_that_can_be_untangled_is_not_held():
    """The centre of a regular octagon fan dragged outside it: every neighbour is fixed, yet
    its region (the octagon) is not empty: not held, untangled."""
    p, f = _star(8, (1.3, 0.2))
    assert mesh_stats(p, f).n_inverted > 0
    fs = as_faceset(f, len(p))
    free = np.zeros(len(p), dtype=bool)
    free[8] = True
    assert hopeless_nodes(p, fs, free).nodes.size == 0
    res = untangle_and_smooth(p, f)
    assert res.status == "untangled", res.message
    assert res.after.n_inverted == 0 and "held" not in res.message


def _feasible_somewhere(p: np.ndarray, f: list[list[int]], node: int) -> bool:
    """Brute force: some point of a fine grid makes every corner of `node`'s faces that
    touches it positive (the others do not depend on it)."""
    lo, hi = p.min(axis=0) - 0.5, p.max(axis=0) + 0.5
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 241), np.linspace(lo[1], hi[1], 241))
    ok = np.ones(gx.shape, dtype=bool)
    for face in f:
        if node not in face:
            continue
        for k in range(len(face)):
            v, nx, pv = face[k], face[(k + 1) % len(face)], face[k - 1]
            if node not in (v, nx, pv):
                continue
            pts = [(gx, gy) if i == node else (p[i, 0], p[i, 1]) for i in (v, nx, pv)]
            (vx, vy), (ax, ay), (bx, by) = pts
            ok &= (ax - vx) * (by - vy) - (ay - vy) * (bx - vx) > 0
    return bool(ok.any())


@pytest.mark.parametrize("arity", [3, 4])
def test_certificate_never_holds_a_node_that_some_position_fixes(arity):
    """Random stars (triangle fans, and quads around a node with a fixed outer ring): a node
    certified hopeless has no valid position on a fine grid, and a node with one is never
    certified. Both kinds occur."""
    rng = np.random.default_rng(7 + arity)
    held = kept = 0
    for _ in range(60):
        if arity == 3:
            k = int(rng.integers(4, 9))
            t = np.sort(rng.uniform(0, 2 * np.pi, k))
            r = rng.uniform(0.3, 1.0, k)
            p = np.vstack([np.column_stack([r * np.cos(t), r * np.sin(t)]),
                           rng.uniform(-0.3, 0.3, 2)])
            f = [[k, i, (i + 1) % k] for i in range(k)]
            node = k
        else:  # 3 x 3 nodes, four quads around node 4, the ring jittered
            xs, ys = np.meshgrid(np.arange(3.0), np.arange(3.0))
            p = np.column_stack([xs.ravel(), ys.ravel()]) + rng.normal(0, 0.5, (9, 2))
            f = [[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7]]
            node = 4
        free = np.zeros(len(p), dtype=bool)
        free[node] = True
        certified = hopeless_nodes(p, as_faceset(f, len(p)), free).nodes.size == 1
        if certified:
            held += 1
            assert not _feasible_somewhere(p, f, node)
        elif not _feasible_somewhere(p, f, node):
            continue  # hopeless without a margin (a region shrunk to a point) or too thin
        else:
            kept += 1
    assert held > 0 and kept > 0, (held, kept)


def test_a_free_neighbour_is_not_examined_but_the_faces_without_it_are():
    """The U-star's boundary node 4 made free: node 8's faces without node 4 (0-2, 5-7) have
    a common region, so nothing is held; the faces with node 4 are not rows of node 8."""
    p, f = _u_star()
    fs = as_faceset(f, len(p))
    free = np.zeros(len(p), dtype=bool)
    free[[4, 8]] = True
    assert hopeless_nodes(p, fs, free).nodes.size == 0


def _u_star_split() -> tuple[np.ndarray, list[list[int]]]:
    """The U-star with its face 0 (8, 0, 1) split at a new free node 9 (its centroid)."""
    p, f = _u_star()
    p = np.vstack([p, p[[8, 0, 1]].mean(axis=0)])
    return p, [[9, 0, 1], [9, 1, 8], [9, 8, 0], *f[1:]]


def test_u_star_with_a_second_free_node_is_held_at_once():
    """Node 8 has a free neighbour (node 9), yet its faces 5 and 7 (the old 3 and 5: no free
    node but 8) cannot both be valid: node 8 is held before the run, no optimizer iteration
    is spent on the fold (node 9 is smoothed, its faces stay valid)."""
    p, f = _u_star_split()
    fs = as_faceset(f, len(p))
    free = np.zeros(len(p), dtype=bool)
    free[[8, 9]] = True
    h = hopeless_nodes(p, fs, free)
    assert h.nodes.tolist() == [8] and h.witness == ((5, 7),)
    res = untangle_and_smooth(p, f)
    assert res.status == "failed"
    assert res.untangle_iterations == 0
    assert mesh_stats(res.points, f[:3]).n_inverted == 0
    assert "2 faces stay inverted (faces 5, 7)" in res.message, res.message
    assert "node 8 is held" in res.message and "faces 5, 7 cannot all be valid" in res.message
    assert res.after.n_inverted == 2
    assert np.array_equal(res.points[8], p[8])


def _rim_pair(clockwise: bool) -> tuple[np.ndarray, list[list[int]]]:
    """Two free nodes (4, 5) inside a rim of four fixed nodes, six triangles. Clockwise: the
    rim's nodes mirrored (a rim turned inside out, signed area -1); else the unit square
    with the two free nodes swapped (tangled, solvable)."""
    rim = [(0, 0), (0, 1), (1, 1), (1, 0)] if clockwise else [(0, 0), (1, 0), (1, 1), (0, 1)]
    inner = [(0.3, 0.5), (0.7, 0.5)] if clockwise else [(0.7, 0.5), (0.3, 0.5)]
    p = np.array(rim + inner, dtype=float)
    return p, [[4, 0, 1], [4, 1, 5], [5, 1, 2], [5, 2, 3], [5, 3, 4], [4, 3, 0]]


def test_group_whose_rim_encloses_negative_area_is_held_beside_an_untangled_grid():
    """Nodes 4 and 5 of the inside-out rim: each alone has a region (two half-planes), but
    the six faces' areas add up to -1 wherever they go. Held before the run with the reason;
    the tangled grid beside it is untangled."""
    grid, gf = _tangled_grid()
    pair, pf = _rim_pair(clockwise=True)
    shift = len(grid)
    p = np.vstack([grid, pair + np.array([10.0, 0.0])])
    f = gf + [[v + shift for v in face] for face in pf]
    fs = as_faceset(f, len(p))
    free = np.ones(len(p), dtype=bool)
    free[np.flatnonzero(np.isin(np.arange(len(p)), [0, 1, 2, 3, 4, 5, 9, 10, 14, 15, 19, 20,
                                                   21, 22, 23, 24]))] = False
    free[shift:shift + 4] = False
    assert hopeless_nodes(p, fs, free).nodes.size == 0  # no single node is hopeless
    g = hopeless_groups(p, fs, free)
    assert g.nodes.tolist() == [shift + 4, shift + 5]
    (nodes, faces, total), = g.groups
    assert nodes == (shift + 4, shift + 5)
    assert faces == tuple(range(len(gf), len(gf) + 6)) and total == -1.0
    res = untangle_and_smooth(p, f)
    assert res.status == "failed"
    assert mesh_stats(res.points[:shift], gf).n_inverted == 0
    assert (f"nodes {shift + 4}, {shift + 5} are held: their 6 faces cannot all be valid at "
            "once (their signed areas add up to -1 wherever these nodes go") in res.message
    assert np.array_equal(res.points[shift:], p[shift:])


def test_group_whose_rim_encloses_positive_area_is_not_held_and_is_untangled():
    p, f = _rim_pair(clockwise=False)
    fs = as_faceset(f, len(p))
    free = np.array([False] * 4 + [True] * 2)
    assert mesh_stats(p, f).n_inverted > 0
    assert hopeless_groups(p, fs, free).nodes.size == 0
    res = untangle_and_smooth(p, f)
    assert res.status == "untangled" and res.after.n_inverted == 0, res.message


def test_group_with_a_free_node_outside_the_grown_rings_is_not_examined():
    """The inside-out rim joined to a long strip of free nodes (a chain wider than the rings
    grown from the tangled faces): the group is not closed, nothing is held."""
    pair, pf = _rim_pair(clockwise=True)
    fs = as_faceset(pf, len(pair))
    free = np.array([False] * 4 + [True] * 2)
    assert hopeless_groups(pair, fs, free).nodes.size == 2
    free[0] = True  # a rim node that moves: the sum is no longer a constant
    assert hopeless_groups(pair, fs, free).nodes.size == 0
