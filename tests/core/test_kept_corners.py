"""Corners kept as given (core.metrics.kept, issue 40 item 1): a straight or concave corner of
fixed vertices only in a simple counterclockwise face is valid, not a failure."""

from __future__ import annotations

import numpy as np

from core import EEGTParams, mesh_stats, untangle_and_smooth
from core.metrics.kept import kept_corners

N = 4


def _idx(i: int, j: int) -> int:
    return j * (N + 1) + i


def pentagon_grid(jitter: float = 0.0, tangle: bool = False) -> tuple[np.ndarray, list]:
    """4 x 4 unit quads; face 0 a pentagon with a vertex at (0.5, 0) on its boundary edge
    (a knife cut): the centre jittered or dragged across its neighbours on request."""
    pts = [(float(i), float(j)) for j in range(N + 1) for i in range(N + 1)] + [(0.5, 0.0)]
    faces = []
    for j in range(N):
        for i in range(N):
            f = [_idx(i, j), _idx(i + 1, j), _idx(i + 1, j + 1), _idx(i, j + 1)]
            if i == j == 0:
                f.insert(1, len(pts) - 1)
            faces.append(f)
    p = np.array(pts)
    if jitter:
        inner = [_idx(i, j) for j in range(1, N) for i in range(1, N)]
        p[inner] += np.random.default_rng(1).uniform(-jitter, jitter, (len(inner), 2))
    if tangle:
        p[_idx(2, 2)] = (3.6, 3.4)
    return p, faces


def l_domain() -> tuple[np.ndarray, list]:
    """An L-shaped domain whose hexagon at the reentrant corner (2, 2) is concave there."""
    pts = [(0, 0), (1, 0), (3, 0), (4, 0), (0, 1), (1, 1), (3, 1), (4, 1), (2, 2), (3, 2),
           (4, 2), (0, 3), (1, 3), (2, 3), (0, 4), (1, 4), (2, 4)]
    k = {v: i for i, v in enumerate(pts)}
    faces = [[(0, 0), (1, 0), (1, 1), (0, 1)], [(1, 0), (3, 0), (3, 1), (1, 1)],
             [(3, 0), (4, 0), (4, 1), (3, 1)], [(3, 1), (4, 1), (4, 2), (3, 2)],
             [(0, 1), (1, 1), (1, 3), (0, 3)], [(1, 1), (3, 1), (3, 2), (2, 2), (2, 3), (1, 3)],
             [(0, 3), (1, 3), (1, 4), (0, 4)], [(1, 3), (2, 3), (2, 4), (1, 4)]]
    return np.array(pts, dtype=float), [[k[v] for v in f] for f in faces]


def test_untouched_pentagon_grid_is_valid():
    p, faces = pentagon_grid()
    r = untangle_and_smooth(p, faces)
    assert r.status == "valid" and r.before.n_inverted == 0 and r.after.n_inverted == 0
    assert r.n_frozen == 0 and r.n_kept == 1 and r.as_dict()["kept_faces"] == 1
    assert "1 face kept as given" in r.message and "failed" not in r.message
    # measured without its straight vertex: the unit square it looks like
    assert r.before.q_min == 1.0 and r.after.q_min == 1.0


def test_jittered_pentagon_grid_smooths():
    p, faces = pentagon_grid(jitter=0.3)
    r = untangle_and_smooth(p, faces)
    assert r.status in ("valid", "untangled") and r.after.n_inverted == 0
    assert r.after.q_avg > r.before.q_avg and r.after.q_min > r.before.q_min
    assert "1 face kept as given" in r.message


def test_tangled_centre_is_untangled():
    p, faces = pentagon_grid(tangle=True)
    r = untangle_and_smooth(p, faces)
    assert r.before.n_inverted > 0
    assert r.status == "untangled" and r.after.n_inverted == 0 and r.n_frozen == 0


def test_l_shaped_hexagon_is_not_failed():
    p, faces = l_domain()
    r = untangle_and_smooth(p, faces)
    assert r.status == "valid" and r.after.n_inverted == 0 and r.n_kept == 1
    assert "1 concave corner" in r.message
    assert r.after.q_avg >= r.before.q_avg


def test_inverted_fixed_face_still_fails():
    p, faces = pentagon_grid()
    p[_idx(1, 1)] = (-0.2, -0.2)  # pinned: face 0 has only fixed corners and a negative area
    fixed = np.zeros(len(p), dtype=bool)
    fixed[_idx(1, 1)] = True
    r = untangle_and_smooth(p, faces, fixed=fixed)
    assert r.status == "failed" and r.n_frozen == 1 and r.after.n_inverted == 1
    assert "face 0 stays inverted" in r.message


def test_paper_mode_keeps_its_definition():
    p, faces = pentagon_grid()
    r = untangle_and_smooth(p, faces, params=EEGTParams.paper())
    assert r.status == "failed" and r.n_kept == 0 and r.n_frozen == 1


def test_measured_without_kept_vertices():
    p, faces = pentagon_grid()
    free = np.ones(len(p), dtype=bool)
    free[[_idx(i, j) for j in range(N + 1) for i in range(N + 1)
          if i in (0, N) or j in (0, N)] + [len(p) - 1]] = False
    kept = kept_corners(p, faces, free)
    assert kept is not None and kept.ids.tolist() == [0]
    assert (kept.n_straight, kept.n_concave) == (1, 0)
    assert kept.measured.to_lists()[0] == faces[0][:1] + faces[0][2:]
    assert mesh_stats(p, faces).n_inverted == 1  # every corner counts without `kept`
    assert mesh_stats(p, faces, kept=kept).n_inverted == 0
    # a free corner folded across the face is inverted whatever is kept
    q = p.copy()
    q[_idx(1, 1)] = (-0.2, 0.5)
    assert mesh_stats(q, faces, kept=kept).n_inverted >= 1
