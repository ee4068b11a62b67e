"""Solver meshes in a real Blender, with meshio from the installed extension's wheels: the
command's Gmsh round trip (`-c eegt channel.msh -o fixed.msh`), File > Import > Solver mesh,
the Untangle & Smooth operator and File > Export > Solver mesh in a user's script, and a
truncated file (exit 2, one line, nothing written). The .msh files are made by Gmsh on the
host (make_solver_meshes.py, run by run_e2e.sh into $E2E_WORK/solver)."""
import json
import os

from e2e_tests import HERE, OUT, WORK, blender, check, fresh_dir, hidden_files, tail, test

SOLVER = f"{WORK}/solver"
EXT_WHEELS = "/extensions/.local/lib/"  # where Blender installs an extension's wheels


def solver_check(src, out, moved_txt=None, log="solver_check"):
    """bl_solver_check.py's comparison of `src` and `out` (run in Blender)."""
    args = ["-b", "--python-exit-code", "1", "--python", f"{HERE}/bl_solver_check.py", "--",
            src, out, *([moved_txt] if moved_txt else [])]
    rc, text = blender(args, timeout=120, log=log)
    lines = [ln for ln in text.splitlines() if ln.startswith("SOLVER-CHECK ")]
    check(rc == 0 and len(lines) == 1, f"check: rc={rc}: {tail(text)}")
    res = json.loads(lines[0].removeprefix("SOLVER-CHECK "))
    check(EXT_WHEELS in res["meshio"], f"meshio came from {res['meshio']}, not the extension")
    return res


def kept_everything_else(res):
    """Every cell block, cell/point/field data array and group as in the input."""
    for key in ("blocks_same", "cell_data_same", "point_data_same", "field_data_same"):
        check(res[key], f"{key} is false: {res}")
    check(res["groups"] == ["cylinder", "fluid", "inlet", "outlet", "walls"],
          f"groups {res['groups']}")
    check(res["head"][0] == res["head"][1], f"format line changed: {res['head']}")
    check(res["boundary_moved"] == 0, f"{res['boundary_moved']} boundary nodes moved")


@test
def t_solver_cli_msh_round_trip():
    """blender -b -c eegt channel.msh -o fixed.msh: exit 0, 0 inverted by meshcheck's own
    count, every line and vertex block, data array and physical group unchanged."""
    base = fresh_dir(f"{OUT}/solver_cli")
    src, out, rep = f"{SOLVER}/channel.msh", f"{base}/fixed.msh", f"{base}/report.json"
    rc, text = blender(["-b", "-c", "eegt", src, "-o", out, "--report", rep, "--quiet"],
                       timeout=240, log="solver_cli")
    check(rc == 0, f"exit {rc}: {tail(text)}")
    res = solver_check(src, out)
    check(res["inverted"][0] > 0 and res["inverted"][1] == 0,
          f"inverted {res['inverted'][0]} -> {res['inverted'][1]}")
    check(0 < res["moved"] < res["n_points"], f"{res['moved']} of {res['n_points']} moved")
    check(any(t != "triangle" for t, _ in res["blocks"]), f"no non-2D blocks: {res['blocks']}")
    kept_everything_else(res)
    with open(rep) as fh:
        report = json.load(fh)
    check(report["solver_mesh"]["format"] == "msh" and report["written"] is True,
          f"report: {report.get('solver_mesh')}")
    return (f"inverted {res['inverted'][0]} -> 0, {res['moved']} of {res['n_points']} nodes "
            f"moved, blocks {res['blocks']} kept, {res['head'][1][1]}")


EVERY_FORMAT = ("vtk", "vtk_ascii", "vtu", "vtu_ascii", "inp", "mesh", "su2")


@test
def t_solver_cli_every_format_round_trip():
    """blender -b -c eegt channel.EXT -o fixed.EXT for every other format (the Gmsh channel
    converted by meshio on the host): exit 0, 0 inverted, every block, data array and the
    format line as in the input, no boundary node moved."""
    base = fresh_dir(f"{OUT}/solver_formats")
    done = []
    for name in EVERY_FORMAT:
        ext = name.split("_")[0]
        src, out = f"{SOLVER}/channel_{name}.{ext}", f"{base}/fixed_{name}.{ext}"
        rc, text = blender(["-b", "-c", "eegt", src, "-o", out, "--quiet"], timeout=240,
                           log=f"solver_{name}")
        check(rc == 0, f"{name}: exit {rc}: {tail(text)}")
        res = solver_check(src, out, log=f"solver_{name}_check")
        check(res["inverted"][0] > 0 and res["inverted"][1] == 0,
              f"{name}: inverted {res['inverted'][0]} -> {res['inverted'][1]}")
        check(0 < res["moved"] < res["n_points"], f"{name}: {res['moved']} moved")
        for key in ("blocks_same", "cell_data_same", "point_data_same", "field_data_same"):
            check(res[key], f"{name}: {key} is false")
        check(res["head"][0] == res["head"][1], f"{name}: format line {res['head']}")
        check(res["boundary_moved"] == 0, f"{name}: {res['boundary_moved']} boundary nodes moved")
        done.append(f"{name} {res['inverted'][0]}->0")
    return ", ".join(done)


@test
def t_solver_import_untangle_export():
    """Import > Solver mesh, Untangle & Smooth, Export > Solver mesh in a user's script: the
    file changes exactly at the vertices the operator moved; everything else is kept."""
    base = fresh_dir(f"{OUT}/solver_ops")
    src, out, moved = f"{SOLVER}/channel.msh", f"{base}/channel_eegt.msh", f"{base}/moved.txt"
    rc, text = blender(["-b", "--python-exit-code", "1", "--python",
                        f"{HERE}/bl_solver_ops.py", "--", src, out, moved],
                       timeout=240, log="solver_ops")
    lines = [ln for ln in text.splitlines() if ln.startswith("SOLVER-OPS ")]
    check(rc == 0 and len(lines) == 1, f"rc={rc}: {tail(text)}")
    ops = json.loads(lines[0].removeprefix("SOLVER-OPS "))
    check(ops["import"] == ops["untangle"] == ops["export"] == ["FINISHED"], f"{ops}")
    check({"walls", "inlet", "outlet", "cylinder"} <= set(ops["vertex_groups"]), f"{ops}")
    check(ops["inverted"][0] > 0 and ops["inverted"][1] == 0, f"{ops}")
    res = solver_check(src, out, moved, log="solver_ops_check")
    check(res["moved_as_in_blender"] and res["moved"] == ops["moved"] > 0,
          f"file changed at {res['moved']} nodes, the operator moved {ops['moved']}")
    check(res["inverted"] == ops["inverted"], f"file {res['inverted']}, Blender {ops}")
    kept_everything_else(res)
    return (f"inverted {ops['inverted'][0]} -> 0, exactly the {ops['moved']} moved nodes "
            "changed in the file, groups and blocks kept")


@test
def t_solver_truncated_file_exit2():
    """A truncated .msh: exit 2, one eegt line, no output and no temporary file."""
    base = fresh_dir(f"{OUT}/solver_bad")
    src, out = f"{SOLVER}/truncated.msh", f"{base}/fixed.msh"
    rc, text = blender(["-b", "-c", "eegt", src, "-o", out], timeout=60, log="solver_bad")
    lines = [ln.strip() for ln in text.splitlines() if ln.startswith("eegt")]
    check(rc == 2 and len(lines) == 1 and lines[0].startswith(f"eegt: cannot read '{src}'"),
          f"rc={rc}: {lines or tail(text)}")
    check(not os.path.exists(out) and not hidden_files(base), f"something was written: "
          f"{os.listdir(base)}")
    return lines[0]
