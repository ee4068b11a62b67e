"""The paper's Tables 1-3 side by side with our modes, Blender and quoted peers.

Run: `python -m bench.paper_tables [--quick] [--out out/bench] [--readme]`.

For each mesh (the paper's Table 1 mesh, third-party and read in place: docs/testing.md; and
the tests/data OBJs) prints one markdown table with rows: the paper's published values (Tables
1-3), our paper-faithful mode (`EEGTParams.paper()`), our defaults (`EEGTParams()`), Blender's
Smooth Vertices (factor 0.5, repeat 100, boundary vertices not selected, i.e. fixed) measured
in the same run through the PyPI bpy module, and quoted peer values (measured earlier on the
same machine class, not rerun here). Quality is the mean ratio (docs/method.md 3,
`core.mesh_stats`) on the 2D coordinates; seconds are medians of repeated runs (3, or 1 with
--quick; paper mode on naca_deform and two_holes_twist runs once).
Then the robustness table (`bench.robustness`), and before/after PNGs in --out.
`--readme` also rewrites the block between `<!-- results:begin -->` and
`<!-- results:end -->` in README.md and writes docs/results.md.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import io
import os
import platform
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
TABLE1_VTK = ROOT.parent / "shared" / "meshes" / "mesquite" / "hole_in_square_tanglap.vtk"
BEGIN, END = "<!-- results:begin -->", "<!-- results:end -->"
SECTION = "### Versus the paper and peers"

# (method, inverted, q_min, q_avg, seconds) as published in the paper (q_min 0 where inverted).
PAPER = {
    "table1": ("Table 1", [
        ("initial mesh", 23, 0.0, 0.6347, None),
        ("Mesquite Untangle-Beta", 0, 0.0207, 0.6003, 0.09),
        ("Mesquite Size", 4, 0.0, 0.5073, 0.41),
        ("Mesquite Shape-Size", 0, 0.0953, 0.5634, 0.239),
        ("Mesquite Untangle-Beta + Shape Improve", 0, 0.2297, 0.6312, 0.525),
        ("EEGT", 0, 0.2502, 0.5844, 0.006),
    ]),
    "naca_deform": ("Table 2", [
        ("initial mesh", 459, 0.0, 0.3243, None),
        ("Mesquite Untangle-Beta", 5533, 0.0, 0.1766, 5.402),
        ("Mesquite Size", 1637, 0.0, 0.1355, 900.233),
        ("Mesquite Shape-Size", 3833, 0.0, 0.2829, 54.494),
        ("EEGT", 0, 0.4157, 0.8102, 29.849),
        ("EEGT + Mesquite Shape Improve", 0, 0.2963, 0.9006, 108.089),
    ]),
    "tri_two_holes": ("Table 3", [
        ("initial mesh", 4914, 0.0, 0.2566, None),
        ("Mesquite Size", 1825, 0.0, 0.2043, 4.927),
        ("Mesquite Shape-Size", 2636, 0.0, 0.1729, 32.472),
        ("EEGT", 0, 0.6461, 0.9130, 37.488),
    ]),
}

# Peers measured earlier on the same machine class (not rerun here), quoted:
# (method, inverted, q_min, q_avg, seconds, note); None = not given.
PEERS = {
    "table1": [
        ("foldover-free untangler (Garanzha et al. 2021)", 0, 0.231, 0.631, 0.21, ""),
        ("Mesquite Untangle-Beta", 0, 0.021, 0.600, None, "the paper's row, reproduced"),
        ("Mesquite Untangle-Beta + Shape Improve", 0, 0.048, 0.601, None, ""),
    ],
    "quad_hole": [
        ("foldover-free untangler (Garanzha et al. 2021)", 0, 0.758, 0.892, 0.009, ""),
        ("Mesquite Untangle-Beta + Shape Improve", 0, 0.760, 0.892, 0.055, ""),
    ],
    "naca_deform": [
        ("foldover-free untangler (Garanzha et al. 2021)", 0, 0.097, 0.752, 94, ""),
        ("Mesquite Untangle-Beta + Shape Improve", "821-4153", None, None, None, "fails"),
    ],
    "tri_two_holes": [
        ("foldover-free untangler (Garanzha et al. 2021)", 0, 0.732, 0.986, 0.68, ""),
        ("Mesquite Untangle-Beta + Shape Improve", 0, 0.697, 0.986, 12.9, ""),
    ],
    "mixed_quad_tri": [
        ("foldover-free untangler (Garanzha et al. 2021)", 0, 0.752, 0.963, 0.90, ""),
        ("Mesquite Untangle-Beta + Shape Improve", 0, 0.546, 0.949, 0.77, ""),
    ],
    "polygon_voronoi": [
        ("foldover-free untangler (Garanzha et al. 2021)", 0, 0.879, 0.989, 0.43, ""),
        ("Mesquite Untangle-Beta + Shape Improve", None, None, None, None,
         "cannot (no polygons)"),
    ],
    "two_holes_twist": [
        ("foldover-free untangler (Garanzha et al. 2021)", 0, 0.047, 0.736, 15.8, ""),
        ("Mesquite Untangle-Beta + Shape Improve", "23-1743", None, None, None, "fails"),
    ],
}

MESHES = [
    ("table1", "Table 1 mesh: Mesquite's `hole_in_square_tanglap` (third-party, not bundled: docs/testing.md)"),
    ("quad_hole", "quad_hole (our remake of Sec. 4.1)"),
    ("naca_deform", "naca_deform (Sec. 4.2, Table 2)"),
    ("tri_two_holes", "tri_two_holes (Sec. 4.3, Table 3)"),
    ("mixed_quad_tri", "mixed_quad_tri"),
    ("polygon_voronoi", "polygon_voronoi"),
    ("two_holes_twist", "two_holes_twist (a hole spun 120 degrees)"),
]
# Paper mode is slow here (thousands of iterations on ~10k faces): one run, said in the table.
PAPER_ONE_RUN = {"naca_deform", "two_holes_twist"}
BLENDER_FACTOR, BLENDER_REPEAT = 0.5, 100
SMALL_REPEATS = 15  # timed rounds when the first round took under 0.2 s (noisy at 3)


def load_table1() -> tuple[np.ndarray, np.ndarray]:
    """The Table 1 mesh from the legacy VTK file, read in place; its clockwise quads reversed."""
    from core.mesh.obj_io import read_legacy_vtk

    pts, cells = read_legacy_vtk(TABLE1_VTK)
    if set(np.diff(cells.offsets).tolist()) != {4}:
        raise ValueError(f"{TABLE1_VTK}: only quads expected")
    return pts, cells.reversed().indices.reshape(-1, 4)


def fmt_sec(x: float | None) -> str:
    if x is None:
        return ""
    return f"{x:.3f}" if x < 1 else f"{x:.2f}" if x < 10 else f"{x:.1f}"


@dataclass
class Row:
    method: str
    source: str  # "paper" | "measured" | "quoted"
    inverted: object
    q_min: float | None
    q_avg: float | None
    seconds: float | None
    note: str = ""

    def md(self) -> str:
        def f(x, d=4):
            return "" if x is None else f"{x:.{d}f}" if isinstance(x, float) else str(x)

        sec = fmt_sec(self.seconds)
        return (f"| {self.method} | {self.source} | {f(self.inverted)} | {f(self.q_min)} | "
                f"{f(self.q_avg)} | {sec} | {self.note} |")


@contextlib.contextmanager
def quiet_stdout():
    """Silence file descriptor 1 (C-level prints of Blender) for the duration."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


class Blender:
    """Blender's Smooth Vertices through the PyPI bpy module, boundary vertices unselected."""

    def __init__(self) -> None:
        sandbox = tempfile.mkdtemp(prefix="eegt_bench_user_")
        os.environ["HOME"] = sandbox  # before bpy is imported: user prefs go here
        os.environ["BLENDER_USER_RESOURCES"] = sandbox
        with contextlib.redirect_stdout(io.StringIO()):
            import bpy
        self.bpy = bpy
        self.version = bpy.app.version_string

    def _object(self, name: str, points: np.ndarray, faces):
        bpy = self.bpy
        bpy.ops.wm.read_homefile(use_empty=True)
        if name == "table1":
            mesh = bpy.data.meshes.new(name)
            mesh.from_pydata(points.tolist(), [], [list(map(int, f)) for f in faces])
            mesh.update()
            obj = bpy.data.objects.new(name, mesh)
            bpy.context.scene.collection.objects.link(obj)
        else:
            with quiet_stdout():  # the importer prints its timing from C
                bpy.ops.wm.obj_import(filepath=str(DATA / f"{name}.obj"), forward_axis="Y",
                                      up_axis="Z")
            obj = bpy.context.selected_objects[0]
        bpy.context.view_layer.objects.active = obj
        obj.select_set(True)
        return obj

    def smooth(self, name: str, points: np.ndarray, faces, repeats: int):
        """Before and after (N, 3), Blender's faces, median operator seconds, selection."""
        import bmesh

        from core import faces_from_csr, free_nodes

        bpy = self.bpy
        obj = self._object(name, points, faces)
        mesh = obj.data
        n = len(mesh.vertices)

        def positions() -> np.ndarray:
            buf = np.empty(n * 3, dtype=np.float32)
            mesh.attributes["position"].data.foreach_get("vector", buf)
            return buf.reshape(-1, 3).astype(np.float64)

        def ints(coll, attr, k):
            buf = np.empty(k, dtype=np.int32)
            coll.foreach_get(attr, buf)
            return buf

        bfaces = faces_from_csr(
            ints(mesh.polygons, "loop_start", len(mesh.polygons)),
            ints(mesh.polygons, "loop_total", len(mesh.polygons)),
            ints(mesh.loops, "vertex_index", len(mesh.loops)), n)
        select = free_nodes(n, bfaces)  # interior vertices; the boundary stays unselected
        start = np.empty(n * 3, dtype=np.float32)
        mesh.attributes["position"].data.foreach_get("vector", start)
        bpy.context.tool_settings.mesh_select_mode = (True, False, False)
        times, after = [], None
        for _ in range(repeats):
            mesh.attributes["position"].data.foreach_set("vector", start)
            mesh.update()
            bpy.ops.object.mode_set(mode="EDIT")
            bpy.ops.mesh.select_all(action="DESELECT")
            bm = bmesh.from_edit_mesh(mesh)
            bm.verts.ensure_lookup_table()
            for i in np.flatnonzero(select):
                bm.verts[int(i)].select = True
            bm.select_flush(True)
            bmesh.update_edit_mesh(mesh)
            t = time.perf_counter()
            r = bpy.ops.mesh.vertices_smooth(factor=BLENDER_FACTOR, repeat=BLENDER_REPEAT)
            times.append(time.perf_counter() - t)
            bpy.ops.object.mode_set(mode="OBJECT")
            if r != {"FINISHED"}:
                raise RuntimeError(f"vertices_smooth returned {r}")
            after = positions()
        before = start.reshape(-1, 3).astype(np.float64)
        moved = np.any(after != before, axis=1)
        if (moved & ~select).any():
            raise RuntimeError("Blender moved a boundary vertex")
        return before, after, bfaces, statistics.median(times), select


def run_ours(points: np.ndarray, faces, params, repeats: int, backends=("numpy",),
             warm: bool = False):
    """({backend: (last result, median seconds)}, repeats). Backends are timed alternately
    (the machine's speed drifts; alternating keeps them comparable). warm: one untimed run
    each first (kernel builds), and SMALL_REPEATS when the first timed round took < 0.2 s."""
    from core import untangle_and_smooth

    if warm:
        for backend in backends:
            untangle_and_smooth(points, faces, params=params, backend=backend)
    times: dict[str, list[float]] = {b: [] for b in backends}
    res = {}
    done = 0
    while done < repeats:
        for backend in backends:
            t = time.perf_counter()
            res[backend] = untangle_and_smooth(points, faces, params=params, backend=backend)
            times[backend].append(time.perf_counter() - t)
        done += 1
        if warm and done == 1 and sum(v[0] for v in times.values()) < 0.2:
            repeats = max(repeats, SMALL_REPEATS)
    return {b: (res[b], statistics.median(times[b])) for b in backends}, repeats


def auto_row(res, sec: float, numpy_res, repeats: int) -> Row:
    """The defaults with backend="auto": same points as NumPy?"""
    same = np.array_equal(res.points, numpy_res.points)
    note = f"backend used: {res.backend}; " + (
        "points bit-identical to the NumPy run" if same else "points differ from the NumPy run"
    ) + f"; median of {repeats}, alternating with the NumPy runs"
    a = res.after
    return Row("ours, auto backend, `EEGTParams()`", "measured", a.n_inverted, a.q_min, a.q_avg,
               sec, note)


def its(res) -> str:
    s = f"{res.untangle_iterations} untangle"
    if res.global_iterations:
        s += f" + {res.global_iterations} global"
    return f"{res.status}: {s} + {res.smooth_iterations} smooth iterations"


def code_version() -> str:
    """The commit measured, and whether core/ differs from it."""
    import subprocess

    def git(*a: str) -> str:
        return subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True).stdout.strip()

    head = git("rev-parse", "--short", "HEAD") or "unknown"
    dirty = git("status", "--porcelain", "--", "core")
    return f"code at commit {head}" + (" with uncommitted changes in core/" if dirty else "")


def machine_line(blender_version: str) -> str:
    cpu = platform.processor() or platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    ncpu = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    when = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    return (f"Measured {when} on {cpu} ({simd_level()}), {ncpu} cores (shared), {platform.system()} "
            f"{platform.release()}, Python {platform.python_version()}, NumPy {np.__version__} "
            f"(NumPy backend, one thread; auto backend: {opencl_device()}), "
            f"Blender {blender_version} (PyPI bpy); {code_version()}.")


def simd_level() -> str:
    """The best SIMD extension NumPy dispatches to on this CPU (results do not depend on it:
    tests/core/test_reproducibility.py), so that readers can tell the machine class."""
    try:
        from numpy._core import _multiarray_umath as mu
    except ImportError:
        from numpy.core import _multiarray_umath as mu
    found = [f for f in mu.__cpu_dispatch__ if mu.__cpu_features__.get(f)]
    return f"SIMD up to {found[-1]}" if found else "baseline SIMD"


def opencl_device() -> str:
    """The OpenCL device "auto" uses here, or why there is none."""
    try:
        from core.eegt import engine_opencl
        from core.opencl.runtime import runtime

        cls, why = engine_opencl.available()
        return runtime().name if cls is not None else f"none ({why.split(' (')[0]})"
    except Exception as exc:  # no pyopencl at all
        return f"none ({exc})"


def mesh_table(
    key: str, label: str, blender: Blender, repeats: int, out: Path
) -> tuple[list[str], str]:
    from bench.plot import before_after_png
    from core import EEGTParams, as_faceset, mesh_stats
    from core.mesh.obj_io import read_obj

    if key == "table1":
        pts3, quads = load_table1()
        faces = as_faceset(quads, len(pts3))
    else:
        pts3, faces = read_obj(DATA / f"{key}.obj")
    p = pts3[:, :2].copy()
    rows: list[Row] = []
    table, paper_rows = PAPER.get(key, (None, []))
    for m, inv, qmin, qavg, sec in paper_rows:
        rows.append(Row(m, f"paper ({table})", inv, qmin, qavg, sec))
    s0 = mesh_stats(p, faces)
    rows.append(Row("input" if key == "table1" else "input (our copy)", "measured", s0.n_inverted, s0.q_min, s0.q_avg, None,
                    f"{faces.n_faces} faces, {len(p)} nodes"))
    for mode, params in (("paper", EEGTParams.paper()), ("defaults", EEGTParams())):
        n = 1 if mode == "paper" and key in PAPER_ONE_RUN else repeats
        if mode == "defaults":
            runs, n = run_ours(p, faces, params, repeats, ("numpy", "auto"), warm=True)
            res, sec = runs["numpy"]
            rows.append(auto_row(*runs["auto"], res, n))
        else:
            runs, _ = run_ours(p, faces, params, n)
            res, sec = runs["numpy"]
        a = res.after
        note = its(res) + ("" if n == repeats else f"; {n} run (slow)" if n == 1 else
                           f"; median of {n}")
        if res.status == "failed" and np.array_equal(res.points, p):
            note += "; no iterate beat the input, so the input is returned"
        rows.append(Row(f"ours, {'`EEGTParams.paper()`' if mode == 'paper' else '`EEGTParams()` (defaults)'}",
                        "measured", a.n_inverted, a.q_min, a.q_avg, sec, note))
        before_after_png(out / f"{key}_{mode}.png", p, res.points, faces, f"{key}, {mode}")
    b0, b1, bfaces, bsec, bsel = blender.smooth(key, pts3, faces.to_lists(), repeats)
    sb = mesh_stats(b1[:, :2], bfaces)
    note = f"{int(bsel.sum())} vertices selected; operator time only"
    if np.abs(b1 - b0).max() < 1e-5 * np.ptp(b0, axis=0).max():
        note += "; no change: every free vertex already sits at its neighbours' mean"
    rows.append(Row(f"Blender Smooth Vertices (factor {BLENDER_FACTOR}, repeat {BLENDER_REPEAT}, "
                    "boundary fixed)", "measured", sb.n_inverted, sb.q_min, sb.q_avg, bsec, note))
    for m, inv, qmin, qavg, sec, note in PEERS.get(key, []):
        rows.append(Row(m, "quoted", inv, qmin, qavg, sec, note))
    short = label.split(" (")[0].split(":")[0]
    summary = [short, cell(rows, "EEGT", "paper"), cell(rows, "ours, `EEGTParams.paper()`"),
               cell(rows, "ours, `EEGTParams()`"), cell(rows, "ours, auto"), cell(rows, "Blender"),
               cell(rows, "foldover-free"), cell(rows, "Mesquite")]
    lines = [f"#### {label}", "",
             "| method | source | inverted | q_min | q_avg | seconds | notes |",
             "|---|---|---|---|---|---|---|"]
    lines += [r.md() for r in rows]
    return [*lines, ""], "| " + " | ".join(summary) + " |"


def score(r: Row) -> tuple:
    """Fewer inverted, then higher q_min, then q_avg; unknown or ranges of inverted last."""
    if not isinstance(r.inverted, int):
        return (-1e9, 0.0, 0.0)
    return (-r.inverted, r.q_min or 0.0, r.q_avg or 0.0)


def cell(rows: list[Row], prefix: str, source: str | None = None) -> str:
    """The best row whose method starts with PREFIX (and whose source starts with SOURCE)."""
    cand = [r for r in rows if r.method.startswith(prefix)
            and (source is None or r.source.startswith(source))]
    if not cand:
        return ""
    r = max(cand, key=score)
    tag = "" if source or r.source == "measured" else f" ({r.source.split(' (')[0]})"
    sec = "" if r.seconds is None else f", {fmt_sec(r.seconds)} s"
    if r.inverted is None:
        return r.note + tag
    if r.inverted != 0:
        return f"{r.inverted} inverted{sec}{tag}"
    return f"{r.q_min:.3f} / {r.q_avg:.3f}{sec}{tag}"


def robustness_table(runs: int) -> list[str]:
    from bench.robustness import robustness
    from core import EEGTParams

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        for name in ("naca_deform", "two_holes_twist"):
            robustness(name, EEGTParams(), runs, "defaults")
    return ["#### Robustness: untangling over runs with 1e-9 random perturbations of the free nodes",
            "",
            "| mesh | parameters | untangled | q_min range | q_avg range | seconds median / max |",
            "|---|---|---|---|---|---|",
            *[line for line in buf.getvalue().splitlines() if line.startswith("|")], ""]


CORPUS = ("\n#### Meshes from mesh generators\n\nTriangle and gmsh meshes tangled by node "
          "noise and by moved inner boundaries, ours against the foldover-free untangler "
          "per family (medians) and per seed: [corpus.md](corpus.md).\n")
README_DROPS = (2, 3)  # the README's summary leaves out ours in paper mode and on NumPy


def drop_columns(lines: list[str], drop: tuple[int, ...]) -> list[str]:
    """The markdown table rows of ``lines`` without the columns ``drop`` (0 = the first);
    other lines as they are."""
    out = []
    for line in lines:
        if not line.startswith("|"):
            out.append(line)
            continue
        cells = line.strip().strip("|").split("|")
        out.append("|" + "|".join(c for i, c in enumerate(cells) if i not in drop) + "|")
    return out


def update_readme(block: list[str], readme: Path) -> None:
    text = readme.read_text()
    body = "\n".join([BEGIN, *block, END])
    if BEGIN in text and END in text:
        a = text.index(BEGIN)
        b = text.index(END) + len(END)
        text = text[:a] + body + text[b:]
    else:
        start = text.index("## Results and speed")
        nxt = text.find("\n## ", start + 1)
        nxt = len(text) if nxt < 0 else nxt + 1
        head = text[:nxt].rstrip("\n")
        text = head + "\n\n" + body + "\n\n" + text[nxt:]
    readme.write_text(text)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 repeat, 5 robustness runs")
    ap.add_argument("--out", default="out/bench", help="folder for the PNGs")
    ap.add_argument("--readme", action="store_true",
                    help="rewrite README.md's results block and docs/results.md")
    args = ap.parse_args()
    if not TABLE1_VTK.exists():
        print(f"the paper's Table 1 mesh is not at {TABLE1_VTK}", file=sys.stderr)
        return 1
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    repeats, runs = (1, 5) if args.quick else (3, 20)
    blender = Blender()
    t0 = time.perf_counter()
    tables: list[str] = []
    summary = ["#### Summary: q_min / q_avg (or inverted left), seconds", "",
               "| mesh | paper's EEGT | ours, paper mode | ours, defaults (NumPy) "
               "| ours, defaults (auto) | Blender Smooth Vertices | foldover-free untangler "
               "| best Mesquite |",
               "|---|---|---|---|---|---|---|---|"]
    for key, label in MESHES:
        lines, row = mesh_table(key, label, blender, repeats, out)
        print("\n".join(lines), flush=True)
        tables += lines
        summary.append(row)
    summary.append("")
    print("\n".join(summary), flush=True)
    robust = robustness_table(runs)
    print("\n".join(robust), flush=True)
    tables = summary + tables + robust
    machine = machine_line(blender.version)
    intro = [
        f"Generated by `python -m bench.paper_tables{' --quick' if args.quick else ''} --readme`. "
        + machine,
        "",
        "Paper rows are the published values (their machine, Mesquite and EEGT timings); "
        "*measured* rows ran in this run; *quoted* rows are peers measured earlier on the same "
        "machine class, not rerun here. Quality is the mean ratio on the 2D coordinates (0 for "
        f"inverted elements); seconds are medians of {repeats} run{'s' if repeats > 1 else ''} "
        "(wall time of `core.untangle_and_smooth`; the operator call for Blender).",
        "",
    ]
    print(f"\n{machine}\nwrote PNGs to {out} ({time.perf_counter() - t0:.0f} s)")
    if args.readme:
        more = ["Ours in the paper's mode and on NumPy, robustness runs, per-mesh tables with "
                "every row of the paper's Tables 1-3 and the peers: "
                "[docs/results.md](docs/results.md).", ""]
        update_readme([SECTION, "", *intro[:1], "", *drop_columns(summary, README_DROPS), *more],
                      ROOT / "README.md")
        (ROOT / "docs" / "results.md").write_text(
            "\n".join(["# Results versus the paper and peers", "", *intro, *tables, CORPUS]))
        print("updated README.md and docs/results.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
