"""The benchmark corpus (bench.corpus) and the peer wrapper's file handling."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench import corpus, libm
from bench.peer_invertible_maps import (
    ENV,
    PeerMissing,
    peer_binary,
    read_points,
    triangles_of,
    write_input,
)
from core import faces_from_csr, mesh_stats
from core.mesh.topology import boundary_nodes

pytest.importorskip("triangle", reason="the bench dependency group (triangle) is not installed")
pytest.importorskip("gmsh", reason="the bench dependency group (gmsh) is not installed")

ROOT = Path(__file__).resolve().parents[2]


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


MAKE_CASES = r"""
import hashlib, json, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from bench import corpus
out = {}
for spec in (corpus.CaseSpec("motion", "annulus", "tri30", 3000, 3, {"angle": 180.0}),
             corpus.CaseSpec("motion", "naca", "gmshgraded", 3000, 2, {"angle": -20.0, "dy": 0.1}),
             corpus.CaseSpec("motion+jitter", "naca", "tri30", 3000, 1,
                             {"angle": -10.0, "dy": 0.05, "share": 2})):
    made = corpus._make(spec)
    out[spec.name] = [hashlib.sha256(np.ascontiguousarray(made[k]).tobytes()).hexdigest()
                      for k in ("points", "reference")]
print(json.dumps(out))
"""


def _made_with(env_extra: dict[str, str]) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "NPY_DISABLE_CPU_FEATURES"}
    env.update(env_extra)
    done = subprocess.run([sys.executable, "-c", MAKE_CASES, str(ROOT)], env=env,
                          capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_moved_boundary_cases_are_the_same_bits_with_and_without_avx512():
    """NumPy's power has its own AVX-512 code (last-bit differences from the C library's
    pow): the motion's blend weights and the airfoil's outline go through bench.libm, so a
    case is the same mesh on every machine, and so is a long run from it."""
    from numpy.core import _multiarray_umath as mu

    have = [f for f in mu.__cpu_dispatch__ if mu.__cpu_features__.get(f)]
    if not have:
        pytest.skip("this NumPy dispatches no SIMD extension on this CPU: nothing to restrict")
    mine = _made_with({})
    assert len(mine) == 3
    for off in ([f for f in have if f.startswith("AVX512")], have):
        if off:
            assert _made_with({"NPY_DISABLE_CPU_FEATURES": " ".join(off)}) == mine, off


def test_libm_power_is_the_c_librarys_pow_element_by_element():
    x = np.array([0.0, 0.3, 1.7, 2.5e-3, 9.0])
    assert np.array_equal(libm.power(x[1:], 3), [math.pow(v, 3) for v in x[1:]])
    neg = libm.power(x, -2.0)
    assert neg[0] == np.inf and np.array_equal(neg[1:], [math.pow(v, -2.0) for v in x[1:]])
    assert libm.power(x.reshape(5, 1), 4).shape == (5, 1)
