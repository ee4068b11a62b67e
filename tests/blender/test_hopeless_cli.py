"""The U-shaped star (tests/e2e/data/u_star_impossible.obj: no position of its one free
node makes its faces valid) through the command line: recognised before the run, so it
exits 3 at once, names the faces and why, and writes nothing it did not change."""

from __future__ import annotations

import json
from pathlib import Path

U_STAR = Path(__file__).resolve().parents[1] / "e2e" / "data" / "u_star_impossible.obj"


def test_cli_u_star_exits_3_at_once_naming_the_faces(ext, bpy, tmp_path):
    out, rep = tmp_path / "out.obj", tmp_path / "r.json"
    code = ext.operators.command.entry.execute([str(U_STAR), "-o", str(out), "--report",
                                                str(rep), "--quiet"])
    assert code == 3
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["status"] == "failed"
    assert o["before"]["n_inverted"] == 2 and o["after"]["n_inverted"] == 2
    assert "2 faces stay inverted (faces 3, 5)" in o["message"], o
    assert "node 8 is held" in o["message"] and "cannot all be valid at once" in o["message"]
    assert o["written"] is False  # the best iterate is the input: nothing moved
    assert out.is_file()  # the output is still saved (the input's geometry)
    xy = [ln.split()[1:3] for ln in out.read_text().splitlines() if ln.startswith("v ")]
    assert [[float(t) for t in row] for row in xy] == [
        [float(t) for t in ln.split()[1:3]] for ln in U_STAR.read_text().splitlines()
        if ln.startswith("v ")]


def test_cli_u_star_no_write_on_fail_exits_3(ext, bpy, tmp_path):
    out, rep = tmp_path / "out.obj", tmp_path / "r.json"
    code = ext.operators.command.entry.execute([str(U_STAR), "-o", str(out), "--report",
                                                str(rep), "--quiet", "--no-write-on-fail"])
    assert code == 3
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["status"] == "failed" and o["written"] is False
