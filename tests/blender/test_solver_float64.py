"""The command on solver meshes computes on the file's own float64 numbers (no Blender mesh
between): far offsets and extreme scales keep honest counts, every output is decided before
the run, and no write (command or File > Export > Solver mesh) destroys an existing file."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from solver_meshes import channel_msh

meshio = pytest.importorskip("meshio", reason="meshio is not installed")


@pytest.fixture
def cli(ext):
    return ext.operators.command.cli


def _own_count(ext, path) -> int:
    """Inverted faces of a (2D, counterclockwise) solver mesh file, measured on its own
    float64 numbers, centred and scaled by a power of two."""
    sm = ext.fileio.solver_mesh.read(str(path))
    fs = ext.core.faces_from_csr(sm.offsets[:-1], sm.counts(), sm.corners, sm.n_points)
    p = sm.points3d()[:, :2]
    lo, hi = p.min(axis=0), p.max(axis=0)
    half = float(np.max(0.5 * hi - 0.5 * lo))
    work = (p - (0.5 * lo + 0.5 * hi)) / 2.0 ** np.frexp(half)[1]
    return ext.core.mesh_stats(work, fs).n_inverted


def _transformed(src, path, scale: float = 1.0, offset=(0.0, 0.0)):
    """`src` with its points scaled and moved, written as binary VTU (float64 exact)."""
    m = meshio.read(src)
    m.points = m.points[:, :2] * scale + np.asarray(offset)
    m.points = np.column_stack([m.points, np.zeros(len(m.points))])
    meshio.write(path, m, file_format="vtu")
    return path


def _run(cli, *args):
    code, rep = cli.run([str(a) for a in args] + ["--quiet"])
    return code, rep


@pytest.fixture
def broken_inp(monkeypatch):
    """meshio's Abaqus writer made to report success on a file that does not read back (as a
    writer that cannot hold the mesh does)."""
    def write(path, mesh, **kwargs):
        with open(path, "w") as fh:
            fh.write("*Heading\n*Node\n1, 0.0\n")

    monkeypatch.setattr(meshio.abaqus, "write", write)


@pytest.fixture
def channel(tmp_path):
    return channel_msh(tmp_path / "c.msh", shift=0.15)


def test_utm_offset_counts_are_the_files_own_and_untangled(bpy, ext, cli, channel, tmp_path):
    base = _transformed(channel, tmp_path / "base.vtu", 5.0)
    utm = _transformed(channel, tmp_path / "utm.vtu", 5.0, (3e5, 4.2e6))
    want = _own_count(ext, base)
    assert want > 0 and _own_count(ext, utm) == want
    out = tmp_path / "utm_out.vtu"
    code, rep = _run(cli, utm, "-o", out)
    entry = rep["objects"][0]
    assert entry["before"]["n_inverted"] == want, entry
    assert code == 0 and entry["after"]["n_inverted"] == 0 == _own_count(ext, out), entry
    assert meshio.read(out).points[:, 0].min() > 2.9e5


@pytest.mark.parametrize("scale", [1e300, 1e-300, 1e8])
def test_extreme_scales_work(bpy, ext, cli, channel, tmp_path, scale):
    base = _transformed(channel, tmp_path / "base.vtu")
    src = _transformed(channel, tmp_path / "s.vtu", scale,
                       (1e8, 1e8) if scale == 1e8 else (0.0, 0.0))
    if scale == 1e8:  # an offset of 1e8 at unit size
        src = _transformed(channel, tmp_path / "s.vtu", 1.0, (1e8, 1e8))
    out = tmp_path / "out.vtu"
    code, rep = _run(cli, src, "-o", out)
    entry = rep["objects"][0]
    assert code == 0, rep["error"]
    assert entry["before"]["n_inverted"] == _own_count(ext, base) > 0
    assert entry["after"]["n_inverted"] == 0 == _own_count(ext, out)
    assert np.isfinite(meshio.read(out).points).all()


def test_impossible_conversion_exits_2_before_the_run(bpy, cli, channel, tmp_path, capfd,
                                                       broken_inp):
    out = tmp_path / "out.inp"
    out.write_bytes(b"an earlier result\n")
    capfd.readouterr()
    code, rep = _run(cli, channel, "-o", out)
    cap = capfd.readouterr()
    err = cap.err.strip().splitlines()
    assert code == 2, rep
    assert len(err) == 1 and f"cannot write output '{out}'" in err[0], err
    assert ".eegt-tmp" not in err[0]
    assert "EEGT " not in cap.out and not rep.get("objects")  # refused before the run
    assert out.read_bytes() == b"an earlier result\n"
    assert sorted(os.listdir(tmp_path)) == ["c.msh", out.name]


def test_export_over_existing_file_it_cannot_write_leaves_it(bpy, ext, channel, tmp_path,
                                                             broken_inp):
    assert bpy.ops.eegt.import_solver_mesh(filepath=str(channel)) == {"FINISHED"}
    out = tmp_path / "o.inp"
    out.write_bytes(b"x" * 41216)
    with pytest.raises(RuntimeError, match="cannot write"):
        bpy.ops.eegt.export_solver_mesh(filepath=str(out))
    assert out.read_bytes() == b"x" * 41216
    assert sorted(os.listdir(tmp_path)) == ["c.msh", "o.inp"]


@pytest.mark.parametrize("flags", [["--fixed-groups", ","], ["--pin-field", ""],
                                   ["--slide-groups", " , "]])
def test_empty_solver_flags_are_refused(bpy, cli, channel, tmp_path, capfd, flags):
    out = tmp_path / "o.msh"
    capfd.readouterr()
    code, _ = _run(cli, channel, "-o", out, *flags)
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "names nothing" in err[0], err
    assert not out.exists()


def test_reference_may_be_a_solver_mesh(bpy, cli, channel, tmp_path, capfd):
    ref = _transformed(channel_msh(tmp_path / "r.msh", shift=0.0), tmp_path / "r.vtu")
    out = tmp_path / "o.msh"
    code, rep = _run(cli, channel, "-o", out, "--reference", ref)
    assert code == 0, rep["error"]
    assert rep["params"]["target"] == "reference" and out.exists()
    other = channel_msh(tmp_path / "other.msh", size=0.2)
    out.unlink()
    capfd.readouterr()
    code, _ = _run(cli, channel, "-o", out, "--reference", other)
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "does not fit" in err[0], err
    assert not out.exists()


@pytest.mark.parametrize("case", ["all_pinned", "not_planar"])
def test_refused_mesh_exits_2_nothing_written(bpy, cli, channel, tmp_path, capfd, case):
    src, flags = channel, ["--fixed-groups", "fluid"]
    if case == "not_planar":
        m = meshio.read(channel)
        m.points[:, 2] = m.points[:, 0] ** 2
        src = tmp_path / "bent.vtu"
        meshio.write(src, m, file_format="vtu")
        flags = []
    out = tmp_path / ("o" + src.suffix)
    capfd.readouterr()
    code, _ = _run(cli, src, "-o", out, *flags)
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert not out.exists()


def test_report_is_json_with_group_metrics(bpy, cli, channel, tmp_path):
    rep_path = tmp_path / "r.json"
    code, _ = _run(cli, channel, "-o", tmp_path / "o.msh", "--report", rep_path,
                   "--metrics", "min_angle")
    rep = json.loads(rep_path.read_text())
    assert code == 0 and rep["written"]
    assert rep["objects"][0]["metrics"]["min_angle"]["after"]["min"] > 0
    assert "fluid" in rep["solver_mesh"]["metrics"]


def test_export_of_a_mesh_far_from_the_origin_keeps_its_own_steps(bpy, ext, channel,
                                                                   tmp_path):
    """Import keeps the vertices relative to the file's centre (float64, on the mesh), so a
    vertex moved 1.3 cm at UTM-like coordinates is written 1.3 cm away (plain float32 there
    has 0.5 m steps); every node not moved keeps the file's float64 bits."""
    src = _transformed(channel, tmp_path / "utm.vtu", 50.0, (3e5 + 0.123456789, 4.2e6))
    assert bpy.ops.eegt.import_solver_mesh(filepath=str(src)) == {"FINISHED"}
    obj = bpy.context.active_object
    file_pts = meshio.read(src).points
    k = int(np.argmin(np.abs(file_pts[:, 0] - np.median(file_pts[:, 0]))))
    co = np.empty(len(obj.data.vertices) * 3, dtype=np.float32)
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    co[k, :2] += np.float32(0.013)
    obj.data.vertices.foreach_set("co", co.ravel())
    out = tmp_path / "o.vtu"
    assert bpy.ops.eegt.export_solver_mesh(filepath=str(out)) == {"FINISHED"}
    got = meshio.read(out).points
    assert np.abs(got[k, :2] - (file_pts[k, :2] + 0.013)).max() < 1e-4
    others = np.arange(len(got)) != k
    assert np.array_equal(got[others], file_pts[others])
