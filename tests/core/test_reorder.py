"""Z-order renumbering of large meshes (core.mesh.reorder): the same faces, memory locality, and
a pipeline run that is exactly the run of the renumbered mesh, mapped back."""

import threading

import numpy as np
import pytest
from meshdata import load2d

import core.host.side_by_side
import core.run.pipeline as pipeline
from core import EEGTParams, mesh_stats, untangle_and_smooth
from core.mesh.faces import FaceSet
from core.mesh.reorder import scattered, z_order


def _shuffled(p: np.ndarray, fs: FaceSet, seed: int = 0) -> tuple[np.ndarray, FaceSet]:
    """The same mesh with nodes and faces numbered at random (as some meshers leave them)."""
    rng = np.random.default_rng(seed)
    nodes, faces = rng.permutation(p.shape[0]), rng.permutation(fs.n_faces)
    new = np.empty_like(nodes)
    new[nodes] = np.arange(nodes.size)
    lists = [new[fs.indices[fs.offsets[f]:fs.offsets[f + 1]]] for f in faces]
    offsets = np.concatenate([[0], np.cumsum([len(f) for f in lists])])
    return p[nodes], FaceSet(offsets, np.concatenate(lists))


@pytest.mark.parametrize("name", ["mixed_quad_tri", "polygon_voronoi", "tri_two_holes"])
def test_z_order_renumbers_the_same_faces_with_their_corner_order(name):
    p, fs = load2d(name)
    order, out = z_order(p, fs)
    assert np.array_equal(np.sort(order.nodes), np.arange(p.shape[0]))
    assert np.array_equal(np.sort(order.faces), np.arange(fs.n_faces))
    for j in range(0, out.n_faces, 97):
        f = order.faces[j]
        mine = out.indices[out.offsets[j]:out.offsets[j + 1]]
        assert np.array_equal(order.nodes[mine], fs.indices[fs.offsets[f]:fs.offsets[f + 1]])
    back = order.back(p[order.nodes])
    assert back.tobytes() == p.tobytes()


def test_z_order_of_a_z_ordered_mesh_is_the_identity():
    p, fs = _shuffled(*load2d("tri_two_holes"))
    order, out = z_order(p, fs)
    again, same = z_order(p[order.nodes], out)
    assert np.array_equal(again.nodes, np.arange(p.shape[0]))
    assert np.array_equal(again.faces, np.arange(fs.n_faces))
    assert np.array_equal(same.indices, out.indices)


def test_z_order_brings_the_nodes_of_a_face_close_in_memory():
    p, fs = _shuffled(*load2d("tri_two_holes"))
    _, out = z_order(p, fs)

    def spread(f: FaceSet) -> np.ndarray:  # distance in memory between a face's nodes
        t = f.indices.reshape(-1, 3)
        return t.max(axis=1) - t.min(axis=1)

    n = p.shape[0]  # 5 383 nodes: at random a face spans half of them
    assert np.mean(spread(fs)) > 0.45 * n and np.median(spread(fs)) > 0.45 * n
    assert np.mean(spread(out)) < 0.12 * n and np.median(spread(out)) < 0.04 * n


@pytest.mark.parametrize("backend,side_by_side", [("numpy", False), ("auto", False),
                                                  ("numpy", True)])
def test_large_mesh_runs_as_its_z_ordered_renumbering_bit_for_bit(monkeypatch, backend,
                                                                  side_by_side):
    """Above the size limit the run works on the renumbered mesh: its points are that run's,
    mapped back, bit for bit, and its statistics are measured in the caller's numbering;
    also with the renumbering made beside the edge analysis and the input's and result's
    statistics side by side (as a large run does)."""
    p, fs = _shuffled(*load2d("tri_two_holes"), seed=1)
    params = EEGTParams(untangle="eegt+local")
    monkeypatch.setattr(pipeline, "REORDER_MIN_FACES", 1_000)
    if side_by_side:
        monkeypatch.setattr(core.host.side_by_side, "SIDE_BY_SIDE_FROM", 1_000)
    threads = []
    monkeypatch.setattr(pipeline, "z_order", lambda *a: threads.append(
        threading.current_thread().name) or z_order(*a))
    res = untangle_and_smooth(p, fs, params=params, backend=backend)
    assert threads == ["eegt-side-by-side" if side_by_side else "MainThread"]
    order, out = z_order(p, fs)  # the renumbered mesh is its own Z order: it is not renumbered
    ref = untangle_and_smooth(p[order.nodes], out, params=params, backend=backend)
    assert res.status == ref.status == "untangled" and res.after.n_inverted == 0
    assert res.points.tobytes() == order.back(ref.points).tobytes()
    assert (res.untangle_iterations, res.global_iterations, res.smooth_iterations) == \
        (ref.untangle_iterations, ref.global_iterations, ref.smooth_iterations)
    assert res.after == mesh_stats(res.points, fs)
    assert res.before == mesh_stats(p, fs)
    fixed = ~res.moved
    assert fixed.sum() > 300 and res.points[fixed].tobytes() == p[fixed].tobytes()
    assert res.after.q_min > 0.5 and res.after.q_avg > 0.95


def _grid(m: int) -> tuple[np.ndarray, FaceSet]:
    """An m x m quad grid numbered row by row (as a grid primitive is)."""
    ys, xs = np.mgrid[0 : m + 1, 0 : m + 1]
    p = np.column_stack([xs.ravel(), ys.ravel()]).astype(np.float64)
    i, j = np.mgrid[0:m, 0:m]
    a = (i * (m + 1) + j).ravel()
    quads = np.column_stack([a, a + 1, a + m + 2, a + m + 1])
    return p, FaceSet(np.arange(quads.shape[0] + 1) * 4, quads.ravel())


def test_only_scattered_numberings_are_renumbered():
    """A grid numbered row by row loses time in Z order (its rows already stream through
    the caches); a shuffled one and qhull-like face orders gain."""
    p, fs = _grid(120)
    assert not scattered(fs, p.shape[0])
    sp, sfs = _shuffled(p, fs)
    assert scattered(sfs, sp.shape[0])
    _, out = z_order(sp, sfs)
    assert not scattered(out, p.shape[0])


def test_meshes_below_the_limit_well_numbered_or_sliding_keep_their_numbering(monkeypatch):
    p, fs = load2d("quad_hole")
    calls = []
    monkeypatch.setattr(pipeline, "z_order", lambda *a: calls.append(1) or z_order(*a))
    sp, sfs = _shuffled(p, fs)
    untangle_and_smooth(sp, sfs)  # under the size limit
    monkeypatch.setattr(pipeline, "REORDER_MIN_FACES", 10)
    untangle_and_smooth(sp, sfs, params=EEGTParams(boundary="slide"))
    gp, gfs = _grid(12)
    gp[(gp[:, 0] % 12 > 0) & (gp[:, 1] % 12 > 0)] += 0.3  # interior moved: some folds
    untangle_and_smooth(gp, gfs)  # numbered row by row
    assert calls == []
    untangle_and_smooth(sp, sfs)
    assert calls == [1]
