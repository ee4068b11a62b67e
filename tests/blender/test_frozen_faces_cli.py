"""A face with a straight corner made of fixed (boundary) vertices only: kept as given by
default (the face is simple and counterclockwise: valid, exit 0); under the paper's rule
(--untangle eegt) it stays inverted, so the run is a failure: the command line exits 3,
still writes the untangled and smoothed mesh (the default --write-on-fail) and names the
face and why."""

from __future__ import annotations

import json

import numpy as np


def _obj_with_straight_boundary_corner(path, tangle: bool) -> None:
    """3x3 quads; the bottom middle quad is a pentagon whose extra vertex sits on the straight
    boundary (a 180 degree corner of three boundary vertices)."""
    pts = [(i, j, 0.0) for j in range(4) for i in range(4)] + [(1.5, 0.0, 0.0)]
    if tangle:
        pts[5] = (2.6, 2.4, 0.0)  # interior vertex (1, 1) pushed across its neighbours
    faces = []
    for j in range(3):
        for i in range(3):
            quad = [4 * j + i, 4 * j + i + 1, 4 * (j + 1) + i + 1, 4 * (j + 1) + i]
            if (i, j) == (1, 0):
                quad = [1, 16, 2, 6, 5]
            faces.append(quad)
    lines = [f"v {x} {y} {z}" for x, y, z in pts]
    lines += ["f " + " ".join(str(k + 1) for k in f) for f in faces]
    path.write_text("\n".join(lines) + "\n")


def test_cli_straight_corner_kept_as_given_exits_0(ext, bpy, tmp_path):
    src, out, rep = tmp_path / "kept.obj", tmp_path / "out.obj", tmp_path / "r.json"
    _obj_with_straight_boundary_corner(src, tangle=True)
    code = ext.operators.command.entry.execute([str(src), "-o", str(out), "--report", str(rep),
                                                "--quiet"])
    assert code == 0
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["status"] == "untangled" and o["written"] is True
    assert o["before"]["n_inverted"] > 1 and o["after"]["n_inverted"] == 0
    assert "1 face kept as given" in o["message"]


def test_cli_frozen_straight_corner_exits_3_and_names_the_face(ext, bpy, tmp_path):
    src, out, rep = tmp_path / "frozen.obj", tmp_path / "out.obj", tmp_path / "r.json"
    _obj_with_straight_boundary_corner(src, tangle=True)
    code = ext.operators.command.entry.execute([str(src), "-o", str(out), "--report", str(rep),
                                                "--untangle", "eegt", "--quiet"])
    assert code == 3
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["status"] == "failed" and o["written"] is True
    assert o["before"]["n_inverted"] > 1 and o["after"]["n_inverted"] == 1
    assert "stays inverted: a corner made of fixed vertices only" in o["message"]
    # the message names the frozen face: a failed run does not repeat it as a note
    assert not any("corner made of fixed vertices only" in n for n in o["notes"])
    xy = np.array([[float(t) for t in ln.split()[1:3]] for ln in out.read_text().splitlines()
                   if ln.startswith("v ")])
    assert len(xy) == 17 and np.all(np.isfinite(xy))
