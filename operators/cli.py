# SPDX-License-Identifier: GPL-3.0-or-later
"""``blender -b -c eegt INPUT ...``: the batch command for pipelines.

Exit codes: 0 every mesh valid at the end, 3 some mesh could not be untangled or was
refused (the others are still processed and written), 2 bad arguments or unreadable input /
unwritable output, 1 internal error. ``--report`` writes a JSON report either way.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import traceback
from typing import Any

import bpy

from ..core import EEGTParams
from . import props, report, runner
from .ops_untangle import _printer

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_FAILED = 0, 1, 2, 3
MESH_EXTENSIONS = (".obj", ".ply", ".stl")


class UsageError(Exception):
    """A command-line or input problem: one line, exit code 2 (0 for --help)."""

    def __init__(self, message: str, code: int = EXIT_USAGE) -> None:
        super().__init__(message)
        self.code = code


class _Parser(argparse.ArgumentParser):
    """argparse that raises instead of calling sys.exit (Blender must keep running)."""

    def exit(self, status: int = 0, message: str | None = None) -> None:  # type: ignore[override]
        raise UsageError((message or "").strip(), EXIT_USAGE if status else EXIT_OK)

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(f"{self.prog}: error: {message}")


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser; one flag per EEGTParams field."""
    p = _Parser(prog="blender -b -c eegt",
                description="Untangle and smooth planar meshes (EEGT) in a .blend, OBJ, PLY "
                            "or STL file. Exit codes: 0 all valid, 3 some mesh failed, "
                            "2 bad arguments or input, 1 internal error.")
    p.add_argument("input", help="input .blend (all mesh objects) or .obj/.ply/.stl file")
    p.add_argument("-o", "--output", help="output .blend/.obj/.ply/.stl (nothing is written "
                                          "without it)")
    p.add_argument("--object", action="append", default=[], metavar="NAME",
                   help="only this mesh object (repeatable)")
    p.add_argument("--backend", choices=("numpy", "opencl", "auto"), default=None,
                   help="compute backend (default: the add-on preference, else numpy)")
    p.add_argument("--device", metavar="SPEC", default=None,
                   help="OpenCL device: 'platform:device' indices or part of its name "
                        "(default: the add-on preference, else automatic)")
    p.add_argument("--paper", action="store_true",
                   help="start from the paper's parameters instead of the defaults")
    group = p.add_argument_group("EEGT parameters")
    defaults = EEGTParams()
    for f in props.param_fields():
        default = getattr(defaults, f.name)
        kw: dict[str, Any] = {"dest": f.name, "default": None,
                              "help": f"{props.field_help(f)} (default {default})"}
        if isinstance(default, bool):
            kw["action"] = argparse.BooleanOptionalAction
        elif isinstance(default, int):
            kw["type"] = int
        elif isinstance(default, float):
            kw["type"] = float
        if f.name in props.STRING_CHOICES:
            kw["choices"] = [c[0] for c in props.STRING_CHOICES[f.name]]
        group.add_argument(_flag(f.name), **kw)
    p.add_argument("--no-pinned", action="store_true",
                   help="ignore the eegt_pinned attribute / vertex group")
    p.add_argument("--project", action="store_true",
                   help="project slightly non-planar meshes onto their plane")
    p.add_argument("--report", metavar="JSON", help="write a JSON report here")
    p.add_argument("--no-write-on-fail", action="store_true",
                   help="leave a mesh unchanged when it could not be untangled")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    return p


def _params(ns: argparse.Namespace) -> EEGTParams:
    base = EEGTParams.paper() if ns.paper else EEGTParams()
    changes = {f.name: getattr(ns, f.name) for f in dataclasses.fields(EEGTParams)
               if getattr(ns, f.name) is not None}
    try:
        return dataclasses.replace(base, **changes)
    except ValueError as exc:
        raise UsageError(f"eegt: {exc}") from None


def _load(path: str) -> None:
    if not os.path.isfile(path):
        raise UsageError(f"eegt: cannot read input '{path}': no such file")
    ext = os.path.splitext(path)[1].lower()
    try:
        if ext == ".blend":
            bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
            return
        if ext not in MESH_EXTENSIONS:
            raise UsageError(f"eegt: unsupported input type '{ext}' (use .blend, .obj, .ply "
                             "or .stl)")
        bpy.ops.wm.read_homefile(use_empty=True)
        if ext == ".obj":
            bpy.ops.wm.obj_import(filepath=path, forward_axis="Y", up_axis="Z")
        elif ext == ".ply":
            bpy.ops.wm.ply_import(filepath=path, forward_axis="Y", up_axis="Z")
        else:
            bpy.ops.wm.stl_import(filepath=path, forward_axis="Y", up_axis="Z")
    except RuntimeError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else "read error"
        first = first.removeprefix("Error: ")
        raise UsageError(f"eegt: cannot read input '{path}': {first}") from None


def _save(path: str) -> None:
    ext = os.path.splitext(path)[1].lower()
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise UsageError(f"eegt: cannot write output '{path}': no folder {folder}")
    try:
        if ext == ".blend":
            bpy.ops.wm.save_as_mainfile(filepath=path, check_existing=False)
        elif ext == ".obj":
            bpy.ops.wm.obj_export(filepath=path, forward_axis="Y", up_axis="Z",
                                  export_materials=False)
        elif ext == ".ply":
            bpy.ops.wm.ply_export(filepath=path, forward_axis="Y", up_axis="Z")
        elif ext == ".stl":
            bpy.ops.wm.stl_export(filepath=path, forward_axis="Y", up_axis="Z")
        else:
            raise UsageError(f"eegt: unsupported output type '{ext}'")
    except RuntimeError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else "write error"
        first = first.removeprefix("Error: ")
        raise UsageError(f"eegt: cannot write output '{path}': {first}") from None


def _objects(names: list[str]) -> list[bpy.types.Object]:
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
        raise UsageError("eegt: the input has no mesh objects")
    seen: set[int] = set()
    unique = []
    for obj in meshes:
        if obj.data.as_pointer() not in seen:
            seen.add(obj.data.as_pointer())
            unique.append(obj)
    return unique


def _backend(choice: str | None, device: str | None) -> tuple[str, str | None]:
    from .prefs import resolve_backend
    name, pref_device = resolve_backend(choice.upper() if choice else "PREFS")
    return name, device or pref_device


def run(argv: list[str]) -> tuple[int, dict[str, Any]]:
    """Parse, load, process, save; returns (exit code, report dict). Never raises."""
    rep = report.new_report(argv)
    ns = None
    try:
        ns = build_parser().parse_args(argv)
        rep["input"], rep["output"] = ns.input, ns.output
        params = _params(ns)
        rep["params"] = params.as_dict() if hasattr(params, "as_dict") else \
            dataclasses.asdict(params)
        backend, device = _backend(ns.backend, ns.device)
        rep["backend_requested"] = backend
        _load(ns.input)
        objs = _objects(ns.object)
        if bpy.context.mode != "OBJECT" and bpy.ops.object.mode_set.poll():
            bpy.ops.object.mode_set(mode="OBJECT")
        results = []
        for obj in objs:
            progress = None if ns.quiet else _printer(obj.name)
            job = runner.prepare(obj, use_pinned=not ns.no_pinned, project=ns.project)
            runner.compute(job, params, backend, progress, device)
            ok = job.error is None and job.result is not None and \
                job.result.status in ("valid", "untangled")
            res = runner.apply(obj, job, write=ok or not ns.no_write_on_fail)
            runner.store_last_run(obj, res)
            results.append(res)
            print("EEGT " + res.line(), flush=True)
        rep["objects"] = [r.as_dict() for r in results]
        if ns.output:
            _save(ns.output)
            rep["written"] = True
        else:
            print("EEGT: no --output given, nothing written", flush=True)
        code = EXIT_OK if all(r.ok for r in results) else EXIT_FAILED
    except UsageError as exc:
        code = exc.code
        if str(exc):
            print(str(exc), file=sys.stdout if code == EXIT_OK else sys.stderr, flush=True)
        rep["error"] = None if code == EXIT_OK else str(exc)
    except Exception as exc:
        traceback.print_exc()
        print(f"eegt: internal error: {exc!r}", file=sys.stderr, flush=True)
        rep["error"] = f"internal error: {exc!r}"
        code = EXIT_INTERNAL
    rep["exit_code"] = code
    if ns is not None and ns.report:
        try:
            with open(ns.report, "w", encoding="utf-8") as fh:
                json.dump(rep, fh, indent=2)
        except OSError as exc:
            print(f"eegt: cannot write report '{ns.report}': {exc.strerror}", file=sys.stderr)
            if code == EXIT_OK:
                code = EXIT_USAGE
    return code, rep


def execute(argv: list[str]) -> int:
    """The registered command handler: the process exit code."""
    return run(list(argv))[0]


_handle: Any = None


def register() -> None:
    """Register ``-c eegt`` (Blender 4.2+)."""
    global _handle
    fn = getattr(bpy.utils, "register_cli_command", None)
    if fn is not None and _handle is None:
        _handle = fn("eegt", execute)


def unregister() -> None:
    """Remove ``-c eegt``."""
    global _handle
    if _handle is not None:
        bpy.utils.unregister_cli_command(_handle)
        _handle = None
