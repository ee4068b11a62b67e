"""The command with many inputs and --uv, in a real Blender: a folder of .blend files with
tangled UV maps is repaired file by file (the batch summary once raised KeyError 'q_avg' on
UV results), each output's UVs counted by meshcheck, the JSON + CSV summary holds both
files' objects with their UV stats."""
import json
import os

from e2e_tests import (
    HERE,
    OUT,
    REPO,
    batch_report,
    blender,
    check,
    fresh_dir,
    make_uv_blend,
    tail,
    test,
)


def make_seeded_uv_blend(path, seed):
    """A .blend like make_uv_blend's (object "Tangled"), its UVs jittered with ``seed``."""
    rc, out = blender(["-b", "--factory-startup", "--python-exit-code", "1", "--python",
                       f"{HERE}/bl_make_uv_blend.py", "--", REPO, path, str(seed)],
                      timeout=120, log=f"make_uv_blend_{seed}")
    check(rc == 0 and os.path.isfile(path), f"making {path}: rc={rc}: {tail(out)}")


def uv_counts(inp, out, name):
    """meshcheck's count of the UV map of "Tangled" in ``inp`` and ``out``."""
    res = f"{OUT}/batch_uv_check_{name}.json"
    rc, text = blender(["-b", "--python-exit-code", "1", "--python", f"{HERE}/bl_uv_check.py",
                        "--", inp, out, res], timeout=120, log=f"batch_uv_check_{name}")
    check(rc == 0, f"uv check of {name}: exit code {rc}: {tail(text)}")
    with open(res) as fh:
        return json.load(fh)


@test
def t_batch_uv_folder():
    """eegt DIR -o OUT --uv over two tangled .blend files: exit 0, both outputs with 0
    inverted and 0 flipped UV faces by meshcheck's own count (UV vertices, pinned UVs,
    border and 3D positions kept), the summary's files are UV runs with both objects."""
    src, dst = fresh_dir(f"{OUT}/batch_uv_in"), fresh_dir(f"{OUT}/batch_uv_out")
    names = ["sphere_a", "sphere_b"]
    with open(make_uv_blend(), "rb") as fh, open(f"{src}/{names[0]}.blend", "wb") as out:
        out.write(fh.read())
    make_seeded_uv_blend(f"{src}/{names[1]}.blend", seed=7)
    rc, text = blender(["-b", "-c", "eegt", src, "-o", dst, "--uv", "--jobs", "2"],
                       timeout=300, log="batch_uv_folder")
    check(rc == 0, f"exit code {rc}: {tail(text)}")
    check("KeyError" not in text and "Traceback" not in text, f"traceback: {tail(text, 12)}")
    details = []
    for name in names:
        inp, outp = f"{src}/{name}.blend", f"{dst}/{name}.blend"
        check(os.path.isfile(outp), f"no output {outp}")
        c = uv_counts(inp, outp, name)
        check(c["in"]["n_inverted"] > 0 and c["out"]["n_inverted"] == 0
              and c["out"]["n_flipped"] == 0,
              f"{name}: inverted UV faces {c['in']['n_inverted']} -> {c['out']['n_inverted']}, "
              f"flipped -> {c['out']['n_flipped']}")
        check(c["border_kept"] and c["pins_kept"] and c["positions_kept"]
              and c["out"]["n_uv_vertices"] == c["in"]["n_uv_vertices"],
              f"{name}: border kept {c['border_kept']}, pins kept {c['pins_kept']}, "
              f"positions kept {c['positions_kept']}, UV vertices "
              f"{c['in']['n_uv_vertices']} -> {c['out']['n_uv_vertices']}")
        details.append((name, c))
    rep, rows = batch_report(f"{dst}/eegt_report.json")
    check(rep["exit_code"] == 0 and rep["counts"]["ok"] == 2 and rep["kinds"] == {"uv": 2},
          f"summary: exit {rep['exit_code']}, counts {rep['counts']}, kinds {rep.get('kinds')}")
    files = {os.path.basename(f["input"]): f for f in rep["files"]}
    check(sorted(files) == [f"{n}.blend" for n in names], f"summary files: {sorted(files)}")
    for name, c in details:
        f = files[f"{name}.blend"]
        objs = [(o["object"], o["kind"], o["uv_map"]) for o in f["objects"]]
        check(f["kind"] == "uv" and [o[:2] for o in objs] == [("Tangled", "uv")] and objs[0][2],
              f"{name}: kind {f['kind']}, objects {objs}")
        check(f["before"]["flipped"] == c["in"]["n_flipped"] and f["after"]["flipped"] == 0
              and f["after"]["inverted"] == 0,
              f"{name}: summary flipped {f['before']['flipped']} -> {f['after']['flipped']} "
              f"(meshcheck {c['in']['n_flipped']}), inverted -> {f['after']['inverted']}")
    by_name = {os.path.basename(r["input"]): r for r in rows}
    for name, c in details:
        r = by_name[f"{name}.blend"]
        check(r["kind"] == "uv" and r["objects"] == "1" and r["uv_inverted_after"] == "0"
              and int(r["uv_flipped_before"]) == c["in"]["n_flipped"]
              and r["inverted_before"] == "" and r["q_avg_after"] == "",
              f"{name}: CSV row {r}")
    return ", ".join(f"{n}: flipped {c['in']['n_flipped']} -> 0, inverted "
                     f"{c['in']['n_inverted']} -> 0" for n, c in details) + "; summary has both"
