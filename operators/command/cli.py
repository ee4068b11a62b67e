# SPDX-License-Identifier: GPL-3.0-or-later
"""``blender -b -c eegt INPUT ...``: the batch command for pipelines.

This module is the single-file command; many files in one command (folders, glob patterns,
an output folder, worker processes, Dask) are ``batch.py``, which runs this command once per
file. Its argument parser is ``parser.py``, the output file's staging and checks
``output_files.py``, the exit codes and file types ``usage.py``, the solver mesh input
(docs/engineers.md) ``solver_run.py``.

Exit codes: 0 every mesh valid at the end, 3 some mesh could not be untangled or was
refused (the others are still processed and written), 2 bad arguments, unreadable input,
input with no faces to work on, or output that could not be saved, 1 internal error.
``--report`` writes a JSON report either way.

Everything that can be checked before computing is: the input path (a directory says so),
the output type, that the output is not the input itself (unless ``--in-place``), that the
output and the report can be created (``-o x.fbx`` fails at once, and a long run never ends
in a result it cannot save), and the reference of target "reference" (readable, finite, of
each chosen object's topology; not with ``--uv``). Each is exit 2 with one line, nothing
written.

Faceless input, per object: a mesh object without faces (edges or points only) is skipped
with a line and listed in the report's ``"skipped"``, and the others are processed as usual
(exit 0 if they all end valid); when no chosen mesh object has a face (an empty file, an
OBJ of lines or of garbage the importer skips) it is exit 2 and nothing is written.

Output is never lost or silently corrupt: it is exported to a hidden temporary file in the
target folder (``.NAME.eegt-tmp-PID.EXT``, so relative paths and the file system are the
target's), checked for the format's own end (Blender's writers report success on a full
disk: a .blend ends with its ENDB block or, compressed, a zstd seek table whose frames add
up to the size; a binary STL is 84 + 50 bytes per triangle; a binary PLY's body matches its
header; an OBJ ends a line and holds every face), then the report is written to a temporary
file and both are renamed into place. Any failure exits 2 with one line on stderr, removes
the temporary files and leaves no file at the target (an existing one stays byte-identical);
``"written"`` is true only once the output is in place. A .blend is saved as a copy to a new
name, so Blender makes no ``.blend1`` backup.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import threading
import traceback
from typing import Any

import bpy

from ...batch.inputs import replaces_input
from ...core import EEGTParams
from ...core.eegt import warm_up
from ..mesh import reference_mesh, runner
from ..mesh.reference_mesh import ReferenceSource, from_file
from ..shared.progress import printer
from ..shared.result import store_last_run
from ..ui.prefs import resolve_backend
from ..uv import uv_runner
from . import metrics, output_files, report, solver_run
from .parser import build_parser
from .usage import (
    EXIT_FAILED,
    EXIT_INTERNAL,
    EXIT_OK,
    EXIT_USAGE,
    INPUT_EXTENSIONS,
    OUTPUT_EXTENSIONS,
    UsageError,
    check_writable,
    unsupported,
    why,
)


def _reference(ns: argparse.Namespace, params: EEGTParams) -> ReferenceSource | None:
    """The reference choice of target 'reference' (None for 'regular'); UsageError for a
    contradiction or an unreadable file."""
    if params.target != "reference":
        return None
    if ns.reference and ns.reference_key:
        raise UsageError("eegt: give --reference or --reference-key, not both")
    if ns.reference:
        if solver_run.is_solver(ns.input):  # read and matched by solver_run.plan
            return ReferenceSource(file=ns.reference)
        try:
            return from_file(ns.reference)
        except ValueError as exc:
            raise UsageError(f"eegt: {exc}") from None
    return ReferenceSource(key=ns.reference_key or "")


def _params(ns: argparse.Namespace) -> EEGTParams:
    """The run's parameters from the flags; UsageError for a contradiction or a bad value."""
    if ns.uv is not None and (ns.reference or ns.reference_key or ns.target == "reference"):
        raise UsageError("eegt: --uv takes each UV face's target shape from its 3D face: "
                         "--reference, --reference-key and --target reference are for vertex "
                         "positions")
    if (ns.reference or ns.reference_key) and ns.target is None:
        ns.target = "reference"
    elif (ns.reference or ns.reference_key) and ns.target != "reference":
        raise UsageError(f"eegt: --reference / --reference-key need --target reference, "
                         f"not {ns.target}")
    base = EEGTParams.paper() if ns.paper else EEGTParams()
    changes = {f.name: getattr(ns, f.name) for f in dataclasses.fields(EEGTParams)
               if getattr(ns, f.name) is not None}
    if ns.uv is None and not ns.paper and solver_run.is_solver(ns.input):
        changes = {**solver_run.REPAIR, **changes}  # a solver mesh is repaired unless asked
    try:
        return dataclasses.replace(base, **changes)
    except ValueError as exc:
        raise UsageError(f"eegt: {exc}") from None


def _check_paths(ns: argparse.Namespace) -> None:
    """Fail fast, before loading or computing: input readable, output type supported, the
    output not the input unless --in-place (which alone makes the input the output), output
    and report creatable (so a long run never ends in an unsavable result)."""
    path = ns.input
    if os.path.isdir(path):
        raise UsageError(f"eegt: cannot read input '{path}': is a directory")
    if not os.path.exists(path):
        raise UsageError(f"eegt: cannot read input '{path}': no such file")
    if not os.access(path, os.R_OK):
        raise UsageError(f"eegt: cannot read input '{path}': permission denied")
    _check_input_type(path)
    if ns.in_place and not ns.output:
        ns.output = path
    if ns.output:
        ext = os.path.splitext(ns.output)[1].lower()
        if ext not in OUTPUT_EXTENSIONS:
            raise unsupported("output", ext or ns.output)
        why = replaces_input(path, ns.output, ns.in_place)
        if why:
            raise UsageError(why)
    solver_run.check_paths(ns)
    if ns.output:
        check_writable(ns.output, "output")
    if ns.report:
        check_writable(ns.report, "report")


def _check_input_type(path: str) -> None:
    """The input is of a type the command reads (UsageError otherwise)."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in INPUT_EXTENSIONS:
        raise unsupported("input", ext)


def _load(path: str) -> None:
    ext = os.path.splitext(path)[1].lower()
    try:
        if ext == ".blend":
            bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
            return
        _check_input_type(path)
        bpy.ops.wm.read_homefile(use_empty=True)
        if ext == ".obj":
            bpy.ops.wm.obj_import(filepath=path, forward_axis="Y", up_axis="Z")
        elif ext == ".ply":
            bpy.ops.wm.ply_import(filepath=path, forward_axis="Y", up_axis="Z")
        else:
            bpy.ops.wm.stl_import(filepath=path, forward_axis="Y", up_axis="Z")
    except RuntimeError as exc:
        line = output_files.first_line(exc, "read error")
        raise UsageError(f"eegt: cannot read input '{path}': {line}") from None


def _objects(names: list[str], path: str) -> tuple[list[bpy.types.Object], list[str]]:
    """The mesh objects to process (one per mesh data) and the names of those skipped for
    having no faces (each with a line); none with a face is a usage error (exit 2)."""
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    if names:
        chosen = []
        for name in names:
            obj = bpy.data.objects.get(name)
            if obj is None or obj.type != "MESH":
                have = ", ".join(sorted(o.name for o in meshes)[:10]) or "none"
                raise UsageError(f"eegt: no mesh object named '{name}' (mesh objects: {have})")
            chosen.append(obj)
        meshes = chosen
    if not meshes:
        raise UsageError(f"eegt: input '{path}' has no mesh objects (nothing to work on)")
    faceless = [o for o in meshes if len(o.data.polygons) == 0]
    if len(faceless) == len(meshes):
        raise UsageError(f"eegt: input '{path}' has no faces to work on "
                         f"({len(meshes)} mesh object{'s' if len(meshes) > 1 else ''}, "
                         "edges or points only)")
    for obj in faceless:
        print(f"EEGT {obj.name}: skipped: no faces", flush=True)
    seen: set[int] = set()
    unique = []
    for obj in meshes:
        if obj not in faceless and obj.data.as_pointer() not in seen:
            seen.add(obj.data.as_pointer())
            unique.append(obj)
    return unique, [o.name for o in faceless]


def _uv_objects(objs: list[bpy.types.Object], name: str,
                rep: dict[str, Any]) -> list[bpy.types.Object]:
    """--uv: the objects with the UV map; the others skipped with a line (none: exit 2)."""
    try:
        kept, skipped = uv_runner.objects_with_uv_map(objs, name or None)
    except ValueError as exc:
        raise UsageError(f"eegt: {exc}") from None
    for entry in skipped:
        print(f"EEGT {entry['object']}: skipped: {entry['reason']}", flush=True)
    rep["skipped"] += skipped
    return kept


def _check_reference(objs: list[bpy.types.Object], ref: ReferenceSource) -> None:
    """Target "reference": every chosen object has the reference the command line names,
    of its topology and with finite coordinates, before any work (UsageError: exit 2, one
    line, nothing written). The runner checks each object again."""
    for obj in objs:
        me = obj.data
        edited = reference_mesh.edited_key(obj)
        if ref.file:
            n, f = ref.file_points.shape[0], ref.file_faces.n_faces
            if not reference_mesh.same_topology(me, n, ref.file_faces):
                raise UsageError(
                    f"eegt: --reference '{ref.file}' ({n} vertices, {f} faces) does not fit "
                    f"object '{obj.name}' ({len(me.vertices)} vertices, {len(me.polygons)} "
                    "faces): a reference has the same vertices and faces, in the same order")
        elif not ref.key and reference_mesh.default_key(me, edited) is None:
            raise UsageError(
                "eegt: --target reference needs --reference FILE or --reference-key NAME: "
                f"object '{obj.name}' has no Basis shape key under an active one to take by "
                "default")
        elif ref.key:
            keys = me.shape_keys
            names = [kb.name for kb in keys.key_blocks] if keys is not None else []
            if ref.key not in names:
                have = ", ".join(names[:10]) or "none"
                raise UsageError(f"eegt: --reference-key {ref.key}: object '{obj.name}' has no "
                                 f"shape key '{ref.key}' (its shape keys: {have})")
            if ref.key == edited:
                raise UsageError(f"eegt: --reference-key {ref.key}: it is the active shape key "
                                 f"of object '{obj.name}', the one the run changes: choose "
                                 "another")
        try:
            reference_mesh.reference_positions(obj, ref, edited)
        except ValueError as exc:
            raise UsageError(f"eegt: object '{obj.name}': {exc}") from None


def _backend(choice: str | None, device: str | None) -> tuple[str, str | None]:
    name, pref_device = resolve_backend(choice.upper() if choice else "PREFS")
    return name, device or pref_device


def _warm_device(backend: str, device: str | None) -> threading.Thread | None:
    """With an OpenCL backend, start getting the device ready (context, kernels) in a
    thread while the input is read: a fresh Blender process otherwise pays for it inside
    the first run."""
    if backend not in ("opencl", "auto"):
        return None
    runner.select_opencl_device(device)
    thread = threading.Thread(target=warm_up, args=(backend,), name="eegt-warm-up")
    thread.start()
    return thread


def run(argv: list[str]) -> tuple[int, dict[str, Any]]:
    """Parse, check, load, process, stage the output, then commit; returns (exit code,
    report dict). Never raises."""
    rep = report.new_report(argv)
    ns = None
    staged: str | None = None
    warming: threading.Thread | None = None
    try:
        ns = build_parser().parse_args(argv)
        rep["input"], rep["output"] = ns.input, ns.output
        _check_paths(ns)
        rep["output"] = ns.output  # --in-place alone: the input
        params = _params(ns)
        reference = _reference(ns, params)
        rep["params"] = params.as_dict()
        if reference is not None:
            rep["reference"] = reference.describe()
        backend, device = _backend(ns.backend, ns.device)
        rep["backend_requested"] = backend
        warming = _warm_device(backend, device)
        if solver_run.is_solver(ns.input):
            params, rep["solver_mesh"], plan = solver_run.plan(ns, params)
            rep["params"] = params.as_dict()
            rep["skipped"] = []
            outcome = _run_solver(plan, ns, params, backend, device, rep)
            staged, results = outcome.staged, [outcome.result]
        else:
            results = _run_blender(ns, params, backend, device, reference, rep)
            if ns.output:
                staged = output_files.stage(ns.output)
        if not ns.output:
            print("EEGT: no --output given, nothing written", flush=True)
        code = EXIT_OK if all(r.ok for r in results) else EXIT_FAILED
    except UsageError as exc:
        code = exc.code
        if str(exc):
            print(str(exc), file=sys.stdout if code == EXIT_OK else sys.stderr, flush=True)
        rep["error"] = None if code == EXIT_OK else str(exc)
        if ns is not None and exc.unwritable is not None and exc.unwritable == ns.report:
            ns.report = None  # said once: the report is not tried again
    except Exception as exc:
        traceback.print_exc()
        print(f"eegt: internal error: {exc!r}", file=sys.stderr, flush=True)
        rep["error"] = f"internal error: {exc!r}"
        code = EXIT_INTERNAL
    if warming is not None:
        warming.join()
    return _commit(ns, rep, code, staged), rep


def _run_blender(ns: argparse.Namespace, params: EEGTParams, backend: str,
                 device: str | None, reference: ReferenceSource | None,
                 rep: dict[str, Any]) -> list:
    """Load a Blender-readable input and run its chosen mesh objects (not written yet)."""
    _load(ns.input)
    objs, skipped = _objects(ns.object, ns.input)
    rep["skipped"] = [{"object": name, "reason": "no faces"} for name in skipped]
    if bpy.context.mode != "OBJECT" and bpy.ops.object.mode_set.poll():
        bpy.ops.object.mode_set(mode="OBJECT")
    if ns.uv is not None:
        objs = _uv_objects(objs, ns.uv, rep)
    if reference is not None:
        _check_reference(objs, reference)
    return _run_objects(objs, ns, params, backend, device, reference, rep)


def _run_solver(plan: solver_run.SolverPlan, ns: argparse.Namespace, params: EEGTParams,
                backend: str, device: str | None,
                rep: dict[str, Any]) -> solver_run.SolverOutcome:
    """Run a solver mesh on its own numbers (solver_run.py): its report line and entry, the
    staged output; no Blender mesh in between."""
    progress = None if ns.quiet else printer(plan.name)
    outcome = solver_run.run(plan, ns, params, backend, device, progress)
    res = outcome.result
    print("EEGT " + res.line(), flush=True)
    rep["objects"] = [res.as_dict()]
    if ns.metrics:
        rep["objects"][0]["metrics"] = solver_run.object_metrics(plan, outcome.after2d,
                                                                 ns.metrics)
        rep["solver_mesh"]["metrics"] = solver_run.group_metrics(plan, outcome.after2d,
                                                                 ns.metrics)
    return outcome


def _run_objects(objs, ns, params, backend: str, device, reference,
                 rep: dict[str, Any]) -> list:
    """Run every object in turn (one report line each), keep each one's last run and fill
    the report's objects (with their metrics when asked)."""
    results, measured = [], []
    for obj in objs:
        progress = None if ns.quiet else printer(obj.name)
        if ns.uv is not None:
            res = uv_runner.run_object(obj, params, ns.uv or None, backend=backend,
                                       device=device, use_pins=not ns.no_pinned,
                                       targets=ns.uv_target, scope=ns.uv_scope,
                                       progress=progress,
                                       write_on_fail=not ns.no_write_on_fail)
            m = None  # --metrics measure positions, which --uv leaves alone
        else:
            res, m = _run_mesh_object(obj, ns, params, backend, device, reference, progress,
                                      rep)
        store_last_run(obj, res)
        results.append(res)
        measured.append(m)
        print("EEGT " + res.line(), flush=True)
    rep["objects"] = [r.as_dict() for r in results]
    if ns.metrics:
        for entry, m in zip(rep["objects"], measured):
            entry["metrics"] = m
    return results


def _run_mesh_object(obj, ns, params, backend: str, device, reference, progress,
                     rep: dict[str, Any]):
    """(result, metrics or None) of one object's vertex-position run."""
    job = runner.prepare(obj, use_pinned=not ns.no_pinned, project=ns.project,
                         reference=reference)
    runner.compute(job, params, backend, progress, device)
    ok = job.error is None and job.result is not None and \
        job.result.status in ("valid", "untangled")
    res = runner.apply(obj, job, write=ok or not ns.no_write_on_fail)
    m = metrics.run_metrics(job, res, ns.metrics) if ns.metrics else None
    return res, m


def _fail(rep: dict[str, Any], message: str) -> int:
    """Print one line on stderr and mark the report: nothing written, exit 2."""
    print(message, file=sys.stderr, flush=True)
    rep.update(written=False, error=message, exit_code=EXIT_USAGE)
    return EXIT_USAGE


def _commit(ns: argparse.Namespace | None, rep: dict[str, Any], code: int,
            staged: str | None) -> int:
    """Put the staged output and the report in place; the exit code. The report is
    written to a temporary file first: when it cannot be, the output is dropped too (exit 2
    means nothing written), and "written" is true only once the output has been renamed."""
    out = ns.output if ns is not None else None
    path = ns.report if ns is not None else None
    rep["written"], rep["exit_code"] = staged is not None, code
    # /dev/null, /dev/stdout and the like are written as they are, never replaced
    special = bool(path) and os.path.exists(path) and not os.path.isfile(path)
    tmp = output_files.tmp_path(path) if path and not special else None
    try:
        if path:
            with open(tmp or path, "w", encoding="utf-8") as fh:
                json.dump(rep, fh, indent=2)
    except OSError as exc:
        output_files.discard(tmp)
        output_files.discard(staged)
        failed = _fail(rep, f"eegt: cannot write report '{path}': {why(exc)}")
        return code if code == EXIT_INTERNAL else failed
    try:
        if staged:
            os.replace(staged, os.path.realpath(out))
    except OSError as exc:
        output_files.discard(staged)
        output_files.discard(tmp)
        code = _fail(rep, f"eegt: cannot write output '{out}': {why(exc)}")
        return _commit(ns, rep, code, None)
    try:
        if tmp:
            os.replace(tmp, os.path.realpath(path))
    except OSError as exc:
        output_files.discard(tmp)
        return _fail(rep, f"eegt: cannot write report '{path}': {why(exc)}")
    return code
