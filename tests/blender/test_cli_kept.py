"""The command on a knife-cut mesh (issue 40 item 1): a pentagon with a vertex on its
straight boundary edge is kept as given, so the run exits 0."""

from __future__ import annotations

import json

import pytest

pytestmark = pytest.mark.blender


def knife_cut_obj() -> str:
    """4 x 4 unit quads with the inner nodes moved a little; face 0 a pentagon with a vertex
    at (0.5, 0) on its boundary edge."""
    n, lines, faces = 4, [], []
    for j in range(n + 1):
        for i in range(n + 1):
            inner = 0 < i < n and 0 < j < n
            lines.append(f"v {i + (0.2 * (-1) ** j if inner else 0.0)} "
                         f"{j + (0.15 * (-1) ** i if inner else 0.0)} 0.0")
    lines.append("v 0.5 0.0 0.0")
    for j in range(n):
        for i in range(n):
            f = [j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1,
                 (j + 1) * (n + 1) + i]
            if i == j == 0:
                f.insert(1, (n + 1) ** 2)
            faces.append("f " + " ".join(str(k + 1) for k in f))
    return "o knife\n" + "\n".join(lines + faces) + "\n"


def test_knife_cut_pentagon_grid_exits_0(bpy, ext, tmp_path):
    inp, out, rep = tmp_path / "knife.obj", tmp_path / "out.obj", tmp_path / "r.json"
    inp.write_text(knife_cut_obj())
    code = ext.operators.command.entry.execute([str(inp), "-o", str(out), "--report",
                                                str(rep), "--quiet"])
    assert code == 0
    (o,) = json.loads(rep.read_text())["objects"]
    assert o["status"] == "valid" and o["after"]["n_inverted"] == 0
    assert o["after"]["q_avg"] > o["before"]["q_avg"]
    assert "kept as given" in o["message"]
