"""The headless command refuses bad requests before any work, in a real Blender: -o naming
the input (refused unless --in-place, single file and batch), a bad reference for target
"reference" (exit 2, nothing at OUT), and a --dask address where nothing listens (exit 2 in
seconds)."""
import json
import os
import time

import meshcheck
from e2e_tests import (
    DATA,
    OUT,
    blender,
    check,
    copy,
    fresh_dir,
    hidden_files,
    make_uv_blend,
    run_cli,
    tail,
    test,
)


def eegt_lines(out):
    """The command's own lines (Blender prints its banner and importer lines too)."""
    return [ln.strip() for ln in out.splitlines() if ln.startswith("eegt")]


def read_bytes(path):
    with open(path, "rb") as fh:
        return fh.read()


@test
def t_cli_output_naming_the_input_needs_in_place():
    """-o naming the input (same path, a symbolic link) is exit 2 and leaves it byte for
    byte; --in-place replaces it with the untangled mesh; a batch follows the same rule."""
    base = fresh_dir(f"{OUT}/in_place")
    mesh = f"{base}/m.obj"
    copy("quad_hole", mesh)
    os.symlink(mesh, f"{base}/link.obj")
    original = read_bytes(mesh)
    for out in (mesh, f"{base}/link.obj"):
        rc, text = blender(["-b", "-c", "eegt", mesh, "-o", out], timeout=60,
                           log="cli_output_is_input")
        expected = (f"eegt: -o '{out}' is the input file itself: give --in-place to replace "
                    "it, or another output")
        check(rc == 2 and eegt_lines(text) == [expected], f"-o {out}: rc={rc}: {tail(text)}")
        check(read_bytes(mesh) == original and not hidden_files(base),
              f"-o {out}: the input changed or a temporary file stayed")
    rc, text = blender(["-b", "-c", "eegt", mesh, "--in-place", "--quiet"], timeout=120,
                       log="cli_in_place")
    check(rc == 0, f"--in-place: rc={rc}: {tail(text)}")
    c = meshcheck.compare(f"{DATA}/quad_hole.obj", mesh)
    check(c["same_topology"] and c["in"]["n_inverted"] == 23 and c["out"]["n_inverted"] == 0,
          f"--in-place: inverted {c['in']['n_inverted']} -> {c['out']['n_inverted']}")
    check(os.path.islink(f"{base}/link.obj") and not hidden_files(base),
          "--in-place: the link was replaced or a temporary file stayed")
    # a batch: -o the input folder is refused; --in-place writes each file over itself
    folder = fresh_dir(f"{OUT}/in_place_batch")
    for m in ("quad_hole", "tilted_plane"):
        copy(m, f"{folder}/{m}.obj")
    before = {m: read_bytes(f"{folder}/{m}.obj") for m in ("quad_hole", "tilted_plane")}
    rc, text = blender(["-b", "-c", "eegt", folder, "-o", folder], timeout=60,
                       log="batch_output_is_input")
    check(rc == 2 and len(eegt_lines(text)) == 1 and "would replace it: give --in-place" in
          eegt_lines(text)[0], f"batch -o its folder: rc={rc}: {tail(text)}")
    check(all(read_bytes(f"{folder}/{m}.obj") == b for m, b in before.items()),
          "batch -o its folder changed an input")
    rc, text = blender(["-b", "-c", "eegt", folder, "--in-place", "--jobs", "2", "--quiet"],
                       timeout=180, log="batch_in_place")
    check(rc == 0, f"batch --in-place: rc={rc}: {tail(text)}")
    for m in before:
        c = meshcheck.compare(f"{DATA}/{m}.obj", f"{folder}/{m}.obj")
        check(c["same_topology"] and c["in"]["n_inverted"] > 0 and c["out"]["n_inverted"] == 0,
              f"batch --in-place {m}: inverted {c['in']['n_inverted']} -> "
              f"{c['out']['n_inverted']}")
    check(not hidden_files(folder), f"temporary files left: {hidden_files(folder)}")
    return "-o input / link: exit 2, input kept; --in-place: 23 -> 0 inverted; batch the same"


def _nan_reference():
    """quad_hole.obj with its first vertex's x a NaN."""
    with open(f"{DATA}/quad_hole.obj") as fh:
        lines = fh.read().splitlines()
    first = next(i for i, ln in enumerate(lines) if ln.startswith("v "))
    lines[first] = "v nan " + " ".join(lines[first].split()[2:])
    path = f"{OUT}/nan_reference.obj"
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    return path


@test
def t_cli_bad_reference_exit2_nothing_written():
    """A reference of another topology, with a NaN, a missing key, target reference without
    a reference, and --uv with a reference: exit 2, one line in the command's words, no
    output file, and no object worked on."""
    quad, other, nan = f"{DATA}/quad_hole.obj", f"{DATA}/mixed_quad_tri.obj", _nan_reference()
    uv = ("eegt: --uv takes each UV face's target shape from its 3D face: --reference, "
          "--reference-key and --target reference are for vertex positions")
    cases = [
        ("ref_topology", quad, ["--reference", other],
         f"eegt: --reference '{other}' (2790 vertices, 2941 faces) does not fit object "
         "'quad_hole' (168 vertices, 140 faces): a reference has the same vertices and faces, "
         "in the same order"),
        ("ref_nan", quad, ["--reference", nan],
         f"eegt: reference '{nan}' has 1 vertex with a NaN or infinite coordinate"),
        ("ref_key", quad, ["--reference-key", "Nope"],
         "eegt: --reference-key Nope: object 'quad_hole' has no shape key 'Nope' (its shape "
         "keys: none)"),
        ("ref_none", quad, ["--target", "reference"],
         "eegt: --target reference needs --reference FILE or --reference-key NAME: object "
         "'quad_hole' has no Basis shape key under an active one to take by default"),
        ("ref_uv", make_uv_blend(), ["--uv", "--reference", quad], uv),
    ]
    for name, inp, extra, expected in cases:
        out_obj, rep, text, _ = run_cli(name, inp, extra, expect=2)
        check("Traceback" not in text and eegt_lines(text) == [expected],
              f"{name}: {eegt_lines(text)}")
        check(not os.path.exists(out_obj), f"{name}: {out_obj} was written")
        check("EEGT " not in text, f"{name}: an object was worked on: {tail(text)}")
        with open(rep) as fh:
            report = json.load(fh)
        check(report["exit_code"] == 2 and report["objects"] == [] and
              report["written"] is False and report["error"] == expected,
              f"{name}: report exit {report['exit_code']}, objects {report['objects']}")
    return f"{len(cases)} bad references: exit 2, one line, nothing written"


@test
def t_batch_dask_scheduler_not_listening_exit2_fast():
    """--dask tcp://127.0.0.1:1 (nothing listens there): one clear line, exit 2, in
    seconds, before the output folder is made."""
    outdir = f"{OUT}/dask_unreachable"
    t0 = time.time()
    rc, text = blender(["-b", "-c", "eegt", f"{DATA}/quad_hole.obj", f"{DATA}/tilted_plane.obj",
                        "-o", outdir, "--dask", "tcp://127.0.0.1:1"], timeout=60,
                       log="batch_dask_unreachable")
    secs = time.time() - t0
    expected = ("eegt: cannot connect to the Dask scheduler at tcp://127.0.0.1:1: connection "
                "refused (is `dask scheduler` running there?)")
    check(rc == 2 and eegt_lines(text) == [expected], f"rc={rc}: {tail(text)}")
    check(secs < 8, f"took {secs:.1f} s")
    check(not os.path.exists(outdir), "the output folder was made")
    return f"exit 2 in {secs:.1f} s (Blender's start included)"
