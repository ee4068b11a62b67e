"""The e2e test list, run by run_e2e.sh with the Debian 13 root's python3 (inside the chroot).

Every Blender run goes through `timeout` with a sandboxed HOME / BLENDER_USER_RESOURCES under
$E2E_WORK/home. The repository is mounted at /work. Each test asserts real numbers (exit
codes, inverted counts computed by meshcheck.py, exact vertex equality); the last line printed
is "N passed, M failed". E2E_ONLY=name1,name2 runs a subset (after the packaging tests).
"""
import glob
import json
import os
import subprocess
import sys
import time
import traceback
import zipfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import meshcheck  # noqa: E402

REPO = "/work"
WORK = os.environ.get("E2E_WORK", "/tmp/eegt-e2e")
HOME = f"{WORK}/home"
SRC, DIST, OUT = f"{WORK}/src", f"{WORK}/dist", f"{WORK}/out"
ART = f"{REPO}/tests/e2e/artifacts"
DATA = f"{REPO}/tests/data"
E2E_DATA = f"{HERE}/data"
DISPLAY = os.environ.get("E2E_DISPLAY", "")
ONLY = [s for s in os.environ.get("E2E_ONLY", "").split(",") if s]
EXT_DIR = f"{HOME}/blender/extensions/user_default/eegt_blender"

# Tangled inputs for the headless command; the impossible one is ours (see its header).
CLI_MESHES = ["quad_hole", "tilted_plane", "polygon_voronoi", "mixed_quad_tri"]
IMPOSSIBLE = f"{E2E_DATA}/u_star_impossible.obj"

results = []  # (name, ok, seconds, detail)


class Fail(Exception):
    pass


def check(cond, msg):
    if not cond:
        raise Fail(msg)


def blender(args, timeout=180, env=None, log=None):
    """Run the real Blender with the sandboxed user dirs; return (exit code, combined output)."""
    e = dict(os.environ, HOME=HOME, BLENDER_USER_RESOURCES=f"{HOME}/blender")
    e.update(env or {})
    cmd = ["timeout", "-k", "10", str(timeout), "blender", *args]
    p = subprocess.run(cmd, env=e, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                       errors="replace")
    if log:
        with open(f"{ART}/{log}.log", "w") as fh:
            fh.write("$ " + " ".join(cmd) + "\n" + p.stdout)
    check(p.returncode not in (124, 137), f"timed out after {timeout} s: {' '.join(args[:6])}")
    return p.returncode, p.stdout


def tail(text, n=6):
    return " | ".join(text.strip().splitlines()[-n:])


def report_entries(path):
    """Per-object entries of a CLI JSON report: every dict that has 'status' and 'after'."""
    with open(path) as fh:
        data = json.load(fh)
    found = []

    def walk(x):
        if isinstance(x, dict):
            if "status" in x and "after" in x:
                found.append(x)
            for v in x.values():
                walk(v)
        elif isinstance(x, list):
            for v in x:
                walk(v)
    walk(data)
    return data, found


def test(fn):
    """Register and run later; a test returns a short detail string or raises."""
    fn.test_name = fn.__name__.removeprefix("t_")
    TESTS.append(fn)
    return fn


TESTS = []

# ---------------------------------------------------------------- packaging --------------


@test
def t_blender_version():
    rc, out = blender(["--version"], timeout=60)
    check(rc == 0 and "Blender 4." in out, f"rc={rc}: {tail(out)}")
    return out.splitlines()[0]


@test
def t_extension_build():
    os.makedirs(DIST, exist_ok=True)
    rc, out = blender(["--command", "extension", "build", "--source-dir", SRC,
                       "--output-dir", DIST], log="extension_build")
    zips = glob.glob(f"{DIST}/eegt_blender-*.zip")
    check(rc == 0 and len(zips) == 1, f"rc={rc}, zips={zips}: {tail(out)}")
    names = zipfile.ZipFile(zips[0]).namelist()
    check("blender_manifest.toml" in names and "__init__.py" in names,
          "manifest or __init__.py missing from the zip")
    check(any(n.startswith("core/") for n in names), "core/ missing from the zip")
    leaked = [n for n in names if n.split("/")[0] in ("tests", ".git", ".venv", "bench")]
    check(not leaked, f"zip contains {leaked[:5]}")
    return f"{os.path.basename(zips[0])}, {len(names)} files"


@test
def t_extension_validate():
    (z,) = glob.glob(f"{DIST}/eegt_blender-*.zip")
    rc, out = blender(["--command", "extension", "validate", z], log="extension_validate")
    check(rc == 0, f"rc={rc}: {tail(out)}")
    return tail(out, 1)


@test
def t_extension_install():
    (z,) = glob.glob(f"{DIST}/eegt_blender-*.zip")
    rc, out = blender(["--command", "extension", "install-file", "-r", "user_default", "-e", z],
                      log="extension_install")
    check(rc == 0, f"rc={rc}: {tail(out)}")
    check(os.path.isfile(f"{EXT_DIR}/blender_manifest.toml"), f"not installed in {EXT_DIR}")
    # A normal (non-factory) start must load it: operator, CLI command; turn the splash off.
    rc, out = blender(["-b", "--python-exit-code", "1", "--python", f"{HERE}/bl_prefs.py"],
                      log="extension_enabled")
    check(rc == 0 and "E2E-PREFS-OK" in out, f"rc={rc}: {tail(out)}")
    return "installed and enabled in the sandboxed user_default repository"


# ---------------------------------------------------------------- headless command -------


def run_cli(name, inp, extra=(), expect=0):
    out_obj, rep = f"{OUT}/{name}_out.obj", f"{OUT}/{name}_report.json"
    for p in (out_obj, rep):
        if os.path.exists(p):
            os.remove(p)
    t0 = time.time()
    rc, out = blender(["-b", "-c", "eegt", inp, "-o", out_obj, "--report", rep, *extra],
                      timeout=240, log=f"cli_{name}")
    check(rc == expect, f"exit code {rc}, expected {expect}: {tail(out)}")
    return out_obj, rep, out, time.time() - t0


def make_cli_test(mesh):
    def t():
        inp = f"{DATA}/{mesh}.obj"
        out_obj, rep, _, secs = run_cli(mesh, inp)
        check(os.path.isfile(out_obj), "no output mesh written")
        c = meshcheck.compare(inp, out_obj)
        check(c["same_topology"], "topology changed (or vertex/face order)")
        check(c["in"]["n_inverted"] > 0, "input was not tangled")
        a = c["out"]
        check(a["finite"] and a["n_inverted"] == 0,
              f"output has {a['n_inverted']} inverted faces")
        check(a["q_min"] > 0 and a["q_avg"] > c["in"]["q_avg"],
              f"quality not improved: q_avg {c['in']['q_avg']:.3f} -> {a['q_avg']:.3f}")
        check(c["boundary_max_move"] <= 1e-5, f"boundary moved by {c['boundary_max_move']:.2e}")
        check(c["max_move"] > 1e-3, "nothing moved")
        check(a["off_plane_rel"] < 1e-5, f"left the plane: {a['off_plane_rel']:.2e}")
        _, entries = report_entries(rep)
        check(len(entries) == 1, f"report has {len(entries)} object entries")
        e = entries[0]
        check(e["status"] == "untangled" and e["after"]["n_inverted"] == 0,
              f"report says {e['status']}, after={e['after']}")
        check(e["before"]["n_inverted"] == c["in"]["n_inverted"],
              f"report before.n_inverted {e['before']['n_inverted']} != "
              f"meshcheck {c['in']['n_inverted']}")
        return (f"inverted {c['in']['n_inverted']} -> 0, q_min {a['q_min']:.3f}, "
                f"q_avg {c['in']['q_avg']:.3f} -> {a['q_avg']:.3f}, {secs:.1f} s")
    t.__name__ = f"t_cli_{mesh}"
    return t


for _m in CLI_MESHES:
    test(make_cli_test(_m))


@test
def t_cli_impossible_exit3():
    # The input really cannot be untangled: try every centre position on a fine grid.
    v, f = meshcheck.read_obj(IMPOSSIBLE)
    best = min(meshcheck.stats(_with(v, x, y), f)["n_inverted"]
               for x in _grid() for y in _grid())
    check(best >= 1, "the 'impossible' mesh can be untangled after all")
    out_obj, rep, _, _ = run_cli("impossible", IMPOSSIBLE, expect=3)
    check(os.path.isfile(out_obj), "best result not written (default is to write)")
    c = meshcheck.compare(IMPOSSIBLE, out_obj)
    s = c["out"]
    check(c["same_topology"] and s["finite"], f"output broken: {c}")
    check(1 <= s["n_inverted"] <= c["in"]["n_inverted"],
          f"best iterate has {s['n_inverted']} inverted, input {c['in']['n_inverted']}")
    _, entries = report_entries(rep)
    check(len(entries) == 1 and entries[0]["status"] == "failed", f"report entries {entries}")
    # "written" = the best iterate was written; when the best iterate is the input itself
    # there is nothing to write: it must then say False and the file must hold the input.
    check(entries[0]["written"] == (c["max_move"] > 0.0),
          f"report written={entries[0]['written']} but the mesh moved by {c['max_move']}")
    check(entries[0]["after"]["n_inverted"] == s["n_inverted"],
          f"report after {entries[0]['after']} != file {s['n_inverted']} inverted")
    # --no-write-on-fail: same exit code; the failed mesh is left as it was (the output file
    # is still saved, with the input geometry) and the report says it was not written.
    out_obj2, rep2, _, _ = run_cli("impossible_nowrite", IMPOSSIBLE, ["--no-write-on-fail"],
                                   expect=3)
    _, entries2 = report_entries(rep2)
    check(len(entries2) == 1 and entries2[0]["written"] is False,
          f"--no-write-on-fail: report entries {entries2}")
    if os.path.exists(out_obj2):
        c2 = meshcheck.compare(IMPOSSIBLE, out_obj2)
        check(c2["same_topology"] and c2["max_move"] == 0.0,
              f"--no-write-on-fail changed the mesh (max move {c2.get('max_move')})")
    return (f"exit 3, best iterate {c['in']['n_inverted']} -> {s['n_inverted']} inverted "
            f"(grid minimum {best}); --no-write-on-fail leaves it unchanged")


@test
def t_cli_boundary_slide():
    """--boundary slide in the real Blender: every boundary vertex stays on the input boundary
    (meshcheck's own polyline test), the corners stay, order is kept, quality beats fixed."""
    inp = f"{DATA}/quad_hole.obj"
    out_fixed, _, _, _ = run_cli("boundary_fixed", inp)
    out_obj, rep, _, secs = run_cli("boundary_slide", inp, ["--boundary", "slide"])
    c = meshcheck.compare(inp, out_obj)
    check(c["same_topology"] and c["out"]["n_inverted"] == 0, f"result: {c['out']}")
    s = meshcheck.slide_check(inp, out_obj)
    check(s["dist_rel"] <= 1e-6, f"a boundary vertex left the boundary: {s['dist_rel']:.2e}")
    check(s["corners"] == 4 and s["corner_move_rel"] <= 1e-6, f"corners: {s}")
    check(s["order_kept"], "boundary order changed")
    check(s["moved"] >= 20, f"only {s['moved']} boundary vertices slid")
    f = meshcheck.compare(inp, out_fixed)["out"]
    check(c["out"]["q_avg"] > f["q_avg"] + 0.01,
          f"slide q_avg {c['out']['q_avg']:.3f} not above fixed {f['q_avg']:.3f}")
    _, entries = report_entries(rep)
    check(entries[0]["status"] == "untangled", f"report {entries[0]['status']}")
    return (f"{s['moved']} boundary vertices slid (max off-curve {s['dist_rel']:.1e}), "
            f"q_avg {f['q_avg']:.3f} (fixed) -> {c['out']['q_avg']:.3f}, {secs:.1f} s")


def _grid():  # centre positions over [-1, 4]^2 (the U spans [0, 3]^2), step 0.1
    return [i * 0.1 - 1.0 for i in range(51)]


def _with(v, x, y):
    v = v.copy()
    v[8, :2] = x, y
    return v


def _exit2(name, args, needle):
    rc, out = blender(["-b", "-c", "eegt", *args], timeout=60, log=f"cli_{name}")
    check(rc == 2, f"exit code {rc}, expected 2: {tail(out)}")
    check("Traceback" not in out, "a traceback was printed")
    lines = [ln for ln in out.splitlines() if needle in ln]
    check(lines, f"no line naming {needle!r}: {tail(out)}")
    return lines[-1].strip()[:120]


@test
def t_cli_missing_file_exit2():
    return _exit2("missing", [f"{OUT}/no_such_mesh.obj", "-o", f"{OUT}/x.obj"], "no_such_mesh")


@test
def t_cli_unreadable_file_exit2():
    bad = f"{OUT}/garbage.blend"
    with open(bad, "wb") as fh:
        fh.write(b"this is not a blend file\x00\x01\x02" * 50)
    return _exit2("unreadable", [bad, "-o", f"{OUT}/y.obj"], "garbage.blend")


@test
def t_cli_bad_argument_exit2():
    rc, out = blender(["-b", "-c", "eegt", f"{DATA}/quad_hole.obj", "--no-such-flag"],
                      timeout=60, log="cli_bad_argument")
    check(rc == 2, f"exit code {rc}, expected 2: {tail(out)}")
    check("Traceback" not in out, "a traceback was printed")
    return "exit 2"


@test
def t_batch_python_script():
    """blender -b --python-exit-code 1 --python bl_batch.py over several files."""
    outdir = f"{OUT}/batch"
    os.makedirs(outdir, exist_ok=True)
    inputs = [f"{DATA}/{m}.obj" for m in ("quad_hole", "polygon_voronoi", "tilted_plane")]
    rc, out = blender(["-b", "--python-exit-code", "1", "--python", f"{HERE}/bl_batch.py",
                       "--", outdir, *inputs], timeout=300, log="batch")
    check(rc == 0, f"exit code {rc}: {tail(out)}")
    for inp in inputs:
        o = f"{outdir}/{os.path.basename(inp)}"
        check(os.path.isfile(o), f"{o} not written")
        s = meshcheck.stats(*meshcheck.read_obj(o))
        check(s["n_inverted"] == 0, f"{o}: {s['n_inverted']} inverted")
    # The same script must fail (exit 1) when a mesh stays tangled: the check can fail.
    rc, out = blender(["-b", "--python-exit-code", "1", "--python", f"{HERE}/bl_batch.py",
                       "--", outdir, IMPOSSIBLE], timeout=120, log="batch_impossible")
    check(rc == 1, f"impossible input: exit code {rc}, expected 1: {tail(out)}")
    return f"{len(inputs)} files valid; a tangled result makes the script exit 1"


BLEND = f"{OUT}/tangled_quad_hole.blend"


def make_blend():
    """A .blend holding the tangled quad_hole mesh, selected and active (made once)."""
    if not os.path.isfile(BLEND):
        rc, out = blender(["-b", "--factory-startup", "--python-exit-code", "1", "--python",
                           f"{HERE}/bl_make_blend.py", "--", f"{DATA}/quad_hole.obj", BLEND],
                          timeout=120, log="make_blend")
        check(rc == 0 and os.path.isfile(BLEND), f"making the .blend: rc={rc}: {tail(out)}")
    return BLEND


@test
def t_python_expr_on_blend():
    """blender -b file.blend --python-expr "bpy.ops.mesh.eegt_untangle_smooth()": no UI context."""
    out_obj = f"{OUT}/python_expr_out.obj"
    expr = ("import bpy; r = bpy.ops.mesh.eegt_untangle_smooth(); print('E2E-EXPR', r); "
            f"bpy.ops.wm.obj_export(filepath={out_obj!r}, export_selected_objects=True, "
            "export_normals=False, export_uv=False, export_materials=False)")
    rc, out = blender(["-b", make_blend(), "--python-exit-code", "1", "--python-expr", expr],
                      timeout=120, log="python_expr")
    check(rc == 0 and "E2E-EXPR {'FINISHED'}" in out, f"rc={rc}: {tail(out)}")
    c = meshcheck.compare(f"{DATA}/quad_hole.obj", out_obj)
    check(c["same_topology"] and c["out"]["n_inverted"] == 0 and c["in"]["n_inverted"] > 0,
          f"result: {c['out']}")
    return f"FINISHED, inverted {c['in']['n_inverted']} -> 0"


# ---------------------------------------------------------------- OpenCL -----------------


@test
def t_opencl_parity():
    """pyopencl + pocl inside the real Blender: OpenCL result vs NumPy (or the fallback)."""
    rc, out = blender(["-b", "--python-exit-code", "1", "--python", f"{HERE}/bl_opencl.py",
                       "--", f"{DATA}/mixed_quad_tri.obj", f"{OUT}/opencl.json", "device"],
                      timeout=300, log="opencl")
    check(rc == 0, f"exit code {rc}: {tail(out)}")
    with open(f"{OUT}/opencl.json") as fh:
        return json.load(fh)["summary"]


@test
def t_opencl_no_device_fallback():
    """No OpenCL device (empty ICD list): OPENCL asked for, NumPy used, and the run says so."""
    empty = f"{WORK}/no_icds"
    os.makedirs(empty, exist_ok=True)
    rc, out = blender(["-b", "--python-exit-code", "1", "--python", f"{HERE}/bl_opencl.py",
                       "--", f"{DATA}/quad_hole.obj", f"{OUT}/opencl_nodevice.json",
                       "nodevice"], timeout=300, env={"OCL_ICD_VENDORS": empty},
                      log="opencl_nodevice")
    check(rc == 0, f"exit code {rc}: {tail(out)}")
    with open(f"{OUT}/opencl_nodevice.json") as fh:
        return json.load(fh)["summary"]


# ---------------------------------------------------------------- GUI --------------------


@test
def t_gui_click_undo_redo_panel():
    check(DISPLAY, "no X display (Xvfb did not start)")
    blend = make_blend()
    rc, out = blender(["--window-geometry", "0", "0", "1600", "900",
                       blend, "--python", f"{HERE}/bl_gui.py", "--", ART],
                      timeout=300, env={"DISPLAY": DISPLAY}, log="gui")
    lines = [ln for ln in out.splitlines() if ln.startswith("E2E-GUI")]
    check(rc == 0 and lines and lines[-1].startswith("E2E-GUI-OK"),
          f"exit code {rc}: {' | '.join(lines[-4:]) or tail(out)}")
    return lines[-1].removeprefix("E2E-GUI-OK").strip()


# ---------------------------------------------------------------- main -------------------


def main():
    os.makedirs(OUT, exist_ok=True)
    os.makedirs(ART, exist_ok=True)
    t_all = time.time()
    for fn in TESTS:
        name = fn.test_name
        packaging = name.startswith(("blender_version", "extension_"))
        if ONLY and not packaging and name not in ONLY:
            continue
        t0 = time.time()
        try:
            detail, ok = fn(), True
        except Fail as e:
            detail, ok = str(e), False
        except Exception:
            detail, ok = traceback.format_exc(limit=3).strip().replace("\n", " | "), False
        dt = time.time() - t0
        results.append((name, ok, dt, detail))
        print(f"{'PASS' if ok else 'FAIL'}  {name:<32} {dt:6.1f} s  {detail}", flush=True)
        if not ok and packaging:
            print("packaging failed: the remaining tests need the installed extension")
            break
    n_fail = sum(not ok for _, ok, _, _ in results)
    print(f"--- e2e summary ({time.time() - t_all:.0f} s) ---")
    for name, ok, dt, _ in results:
        print(f"  {'ok  ' if ok else 'FAIL'} {name} ({dt:.1f} s)")
    print(f"{len(results) - n_fail} passed, {n_fail} failed")
    return 1 if n_fail else 0


if __name__ == "__main__":
    sys.exit(main())
