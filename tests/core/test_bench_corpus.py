"""The benchmark corpus (bench.corpus) and the peer wrapper's file handling."""

from __future__ import annotations

import numpy as np
import pytest

from bench import corpus
from bench.peer_invertible_maps import (
    ENV,
    PeerMissing,
    peer_binary,
    read_points,
    triangles_of,
    write_input,
)
from core import faces_from_csr, mesh_stats
from core.topology import boundary_nodes

pytest.importorskip("triangle", reason="the bench dependency group (triangle) is not installed")
pytest.importorskip("gmsh", reason="the bench dependency group (gmsh) is not installed")


@pytest.fixture(autouse=True)
def tmp_cache(tmp_path, monkeypatch):
    monkeypatch.setattr(corpus, "CACHE", tmp_path)


def test_jitter_case_inverts_five_percent_and_keeps_boundary_and_reloads_same_bits():
    spec = corpus.CaseSpec("jitter", "holes3", "tri30", 3000, 2, {"share": 5})
    case = corpus.load(spec)
    assert spec.path.exists()
    st = mesh_stats(case.points, case.faces)
    assert 0.05 * case.n_faces <= st.n_inverted < 0.06 * case.n_faces
    assert mesh_stats(case.reference, case.faces).n_inverted == 0
    assert np.array_equal(case.fixed, boundary_nodes(case.points.shape[0], case.faces))
    assert np.array_equal(case.points[case.fixed], case.reference[case.fixed])
    assert np.all(np.any(case.points[~case.fixed] != case.reference[~case.fixed], axis=1))
    again = corpus.load(spec)  # from the cache
    assert np.array_equal(again.points, case.points)
    assert 2500 < case.n_faces < 3500


def test_triangle_min_angle_holds_on_the_base_mesh():
    pts, fs = corpus.base_mesh("holes3", "tri30", 2000)
    tri = pts[fs.groups[0].nodes.T]  # (T, 3, 2)
    e = np.roll(tri, -1, axis=1) - tri
    cos = -np.sum(e * np.roll(e, 1, axis=1), axis=2) / (
        np.linalg.norm(e, axis=2) * np.linalg.norm(np.roll(e, 1, axis=1), axis=2))
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).min() > 29.9


def test_annulus_motion_turns_the_inner_ring_rigidly_and_keeps_the_outer_ring():
    spec = corpus.CaseSpec("motion", "annulus", "gmshquad", 2000, 3, {"angle": 180.0})
    case = corpus.load(spec)
    r_ref = np.hypot(*case.reference.T)
    inner = case.fixed & (r_ref < 0.5)
    outer = case.fixed & (r_ref > 0.9)
    assert inner.sum() > 20 and outer.sum() > 40
    assert np.allclose(case.points[inner], -case.reference[inner], atol=1e-12)
    assert np.array_equal(case.points[outer], case.reference[outer])
    assert {g.n for g in case.faces.groups} == {4}
    assert mesh_stats(case.points, case.faces).n_inverted > 0.1 * case.n_faces


def test_mixed_gmsh_mesh_has_triangles_and_quads_all_counterclockwise():
    pts, fs = corpus.base_mesh("naca", "gmshmixed", 3000)
    assert {g.n for g in fs.groups} == {3, 4}
    assert mesh_stats(pts, fs).n_inverted == 0


def test_peer_input_round_trip_and_quads_cut_in_two(tmp_path):
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [2.0, 0.5]])
    fs = faces_from_csr([0, 4], [4, 3], [0, 1, 2, 3, 1, 4, 2])
    tris = triangles_of(fs)
    assert sorted(map(tuple, tris.tolist())) == [(0, 1, 2), (0, 2, 3), (1, 4, 2)]
    path = tmp_path / "in.obj"
    write_input(path, pts, pts + 0.25, tris)
    text = path.read_text().splitlines()
    assert text[0] == "v 0 0 0" and text[5] == "vt 0.25 0.25"
    assert read_points(path, 5).tolist() == pts.tolist()


def test_peer_missing_says_which_variable(monkeypatch):
    monkeypatch.delenv(ENV, raising=False)
    with pytest.raises(PeerMissing, match=ENV):
        peer_binary()
    monkeypatch.setenv(ENV, "/nonexistent/untangle2d")
    with pytest.raises(PeerMissing, match="not an executable"):
        peer_binary()
