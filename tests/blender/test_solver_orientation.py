"""Solver meshes whose cells run clockwise, all or some (FEM files often do), through the
command: the run orients them in memory (core.mesh.orient_faces), says how many were read
clockwise, and writes the file's own cells back unchanged with only positions moved, the
same positions as the consistently oriented file gives, bit for bit. A Moebius strip is
refused with one line; a Blender-side mesh of mixed faces keeps today's refusal."""

from __future__ import annotations

import json

import numpy as np
import pytest
from solver_meshes import CHANNEL_TRIANGLES, channel_msh

meshio = pytest.importorskip("meshio", reason="meshio is not installed")


@pytest.fixture
def cli(ext):
    return ext.operators.command.cli


def _with_order(src, dst, flip: np.ndarray, fmt: str):
    """The Gmsh-made mesh `src` written as `dst` with the triangles `flip` reversed (each
    keeps its first node: a b c -> a c b)."""
    m = meshio.read(src)
    cells = []
    for b in m.cells:
        data = np.asarray(b.data).copy()
        if b.type == "triangle":
            data[flip] = data[flip][:, [0, 2, 1]]
        cells.append((b.type, data))
    phys = m.cell_data["gmsh:physical"]
    if fmt == "msh":
        out = meshio.Mesh(m.points, cells, cell_data={
            "gmsh:physical": phys, "gmsh:geometrical": m.cell_data["gmsh:geometrical"]},
            field_data=m.field_data)
        meshio.gmsh.write(str(dst), out, fmt_version="2.2", binary=False)
    else:
        meshio.Mesh(m.points, cells, cell_data={"gmsh:physical": phys}).write(str(dst))
    return dst


def _run(cli, src, out, tmp_path, *extra):
    rep = tmp_path / f"{out.stem}.json"
    code = cli.run([str(src), "-o", str(out), "--report", str(rep), "--quiet", *extra])[0]
    return code, json.loads(rep.read_text())


def _triangles(path) -> np.ndarray:
    return np.concatenate([np.asarray(b.data) for b in meshio.read(path).cells
                           if b.type == "triangle"])


@pytest.mark.parametrize("fmt", ["vtu", "msh"])
def test_mixed_orientation_runs_like_the_oriented_file(bpy, cli, tmp_path, fmt):
    gmsh_file = channel_msh(tmp_path / "channel.msh", shift=0.15)  # tangled round the cylinder
    rng = np.random.default_rng(5)
    mixed = rng.random(CHANNEL_TRIANGLES) < 0.4
    ccw = _with_order(gmsh_file, tmp_path / f"ccw.{fmt}", np.zeros_like(mixed), fmt)
    src = _with_order(gmsh_file, tmp_path / f"mixed.{fmt}", mixed, fmt)

    code0, rep0 = _run(cli, ccw, tmp_path / f"out_ccw.{fmt}", tmp_path, "--metrics", "min_angle")
    code, rep = _run(cli, src, tmp_path / f"out_mixed.{fmt}", tmp_path, "--metrics", "min_angle")
    assert code0 == 0 and code == 0, (rep0["objects"], rep["objects"])
    assert rep0["solver_mesh"]["clockwise_faces"] == 0
    assert not any("clockwise" in n for n in rep0["solver_mesh"]["notes"])
    # every reversed triangle counted, and only those: the folded ones are not "clockwise"
    assert rep["solver_mesh"]["clockwise_faces"] == int(mixed.sum())
    note = [n for n in rep["solver_mesh"]["notes"] if "read clockwise" in n]
    assert note == [f"{int(mixed.sum())} of {CHANNEL_TRIANGLES} faces were read clockwise: the "
                    "run takes them counterclockwise; the file keeps its own node order"]
    before, before0 = rep["objects"][0]["before"], rep0["objects"][0]["before"]
    assert before == before0 and before["n_inverted"] > 0  # the folds, not the reversed faces
    assert rep["objects"][0]["after"] == rep0["objects"][0]["after"]
    assert rep["objects"][0]["after"]["n_inverted"] == 0
    groups = rep["solver_mesh"]["metrics"]  # per group, measured on the oriented faces
    assert [g["faces"] for g in groups.values()] == [CHANNEL_TRIANGLES]
    assert groups == rep0["solver_mesh"]["metrics"]
    assert rep["objects"][0]["metrics"] == rep0["objects"][0]["metrics"]

    a, b = meshio.read(src), meshio.read(tmp_path / f"out_mixed.{fmt}")
    assert np.array_equal(_triangles(tmp_path / f"out_mixed.{fmt}"), _triangles(src))
    for x, y in zip(a.cells, b.cells):  # the file's own cells, node order and all
        assert x.type == y.type and np.array_equal(x.data, y.data)
    moved = (a.points != b.points).any(axis=1)
    lines = np.concatenate([c.data.ravel() for c in a.cells if c.type == "line"])
    assert moved.any() and not moved[lines].any()
    # the same run as on the consistently oriented file: the same positions, bit for bit
    assert np.array_equal(b.points, meshio.read(tmp_path / f"out_ccw.{fmt}").points)


def test_clockwise_only_file_says_all_and_keeps_its_order(bpy, cli, tmp_path):
    gmsh_file = channel_msh(tmp_path / "channel.msh", shift=0.15)
    every = np.ones(CHANNEL_TRIANGLES, dtype=bool)
    ccw = _with_order(gmsh_file, tmp_path / "ccw.vtu", ~every, "vtu")
    cw = _with_order(gmsh_file, tmp_path / "cw.vtu", every, "vtu")
    code0, _ = _run(cli, ccw, tmp_path / "out_ccw.vtu", tmp_path)
    code, rep = _run(cli, cw, tmp_path / "out_cw.vtu", tmp_path)
    assert code0 == 0 and code == 0
    assert rep["solver_mesh"]["clockwise_faces"] == CHANNEL_TRIANGLES
    assert any(n.startswith(f"all {CHANNEL_TRIANGLES} faces were read clockwise")
               for n in rep["solver_mesh"]["notes"])
    assert np.array_equal(_triangles(tmp_path / "out_cw.vtu"), _triangles(cw))
    assert np.array_equal(meshio.read(tmp_path / "out_cw.vtu").points,
                          meshio.read(tmp_path / "out_ccw.vtu").points)


def _moebius_vtu(path, n: int = 12):
    """A ring of quads closed with a half twist (a Moebius strip), flat in z = 0, with a
    ring of triangles inside so some node could move."""
    t = 2 * np.pi * np.arange(n) / n
    ring = np.column_stack([np.cos(t), np.sin(t), np.zeros(n)])
    pts = np.vstack([ring, 2 * ring, [[0.0, 0.0, 0.0]]])
    quads = [[k, n + k, n + k + 1, k + 1] for k in range(n - 1)] + [[n - 1, 2 * n - 1, 0, n]]
    tris = [[2 * n, k, (k + 1) % n] for k in range(n)]
    meshio.Mesh(pts, [("triangle", np.array(tris)), ("quad", np.array(quads))]).write(str(path))
    return path


def test_moebius_strip_is_refused_with_one_line(bpy, cli, tmp_path, capfd):
    src = _moebius_vtu(tmp_path / "strip.vtu")
    out = tmp_path / "out.vtu"
    capfd.readouterr()
    code, _ = cli.run([str(src), "-o", str(out), "--quiet"])
    err = [ln for ln in capfd.readouterr().err.splitlines() if ln.strip()]
    assert code == 2 and len(err) == 1, err
    assert "cannot be oriented consistently" in err[0] and "Moebius" in err[0], err
    assert f"'{src}'" in err[0], err
    assert not out.exists()


def test_blender_side_mixed_faces_keep_the_refusal(bpy, cli, tmp_path):
    # a 3 x 3 grid of quads with the centre one reversed, as an .obj: Blender users flip
    # normals themselves (the object's error says so; exit 3, nothing run)
    lines = [f"v {x} {y} 0" for y in range(4) for x in range(4)]
    for j in range(3):
        for i in range(3):
            a = j * 4 + i + 1
            face = [a, a + 1, a + 5, a + 4]
            lines.append("f " + " ".join(map(str, face[::-1] if (i, j) == (1, 1) else face)))
    src = tmp_path / "grid.obj"
    src.write_text("\n".join(lines) + "\n")
    rep = tmp_path / "r.json"
    code, _ = cli.run([str(src), "-o", str(tmp_path / "out.obj"), "--report", str(rep),
                       "--quiet"])
    entry = json.loads(rep.read_text())["objects"][0]
    assert code == 3 and entry["status"] == "error" and not entry["written"], entry
    assert "faces are not consistently oriented" in entry["message"]
    assert "recalculate normals" in entry["message"]
