# SPDX-License-Identifier: GPL-3.0-or-later
"""``blender -b -c eegt INPUT ...``: the batch command for pipelines.

Exit codes: 0 every mesh valid at the end, 3 some mesh could not be untangled or was
refused (the others are still processed and written), 2 bad arguments, unreadable input,
input with no faces to work on, or output that could not be saved, 1 internal error.
``--report`` writes a JSON report either way.

Everything that can be checked before computing is (output type and folder, report
folder, input path). Mesh objects without faces are skipped with a line; an input where no
chosen object has a face is exit 2. Output is written to a temporary file in the target
folder, checked (size, disk not full, the format's own completeness: a .blend ends with its
ENDB block or, compressed, its zstd seek table; a binary STL's size matches its triangle
count; a PLY's body matches its header; an OBJ holds every face) and renamed onto the
target: a failed save leaves no file there (an existing one stays intact) and the report
says ``"written": false``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import struct
import sys
import traceback
from typing import Any

import bpy

from ..core import EEGTParams
from . import props, report, runner
from .ops_untangle import _printer

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_FAILED = 0, 1, 2, 3
MESH_EXTENSIONS = (".obj", ".ply", ".stl")
OUTPUT_EXTENSIONS = (".blend", *MESH_EXTENSIONS)
# A compressed .blend is zstd frames closed by a seek table (a skippable frame whose last
# four bytes are this magic), written last: a cut file lacks it.
ZSTD_MAGIC, ZSTD_SEEKABLE_END = b"\x28\xb5\x2f\xfd", b"\xb1\xea\x92\x8f"


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


def _check_paths(ns: argparse.Namespace) -> None:
    """Fail fast, before loading or computing: input readable, output type supported and
    its folder writable, report folder writable."""
    path = ns.input
    if os.path.isdir(path):
        raise UsageError(f"eegt: cannot read input '{path}': is a directory")
    if not os.path.exists(path):
        raise UsageError(f"eegt: cannot read input '{path}': no such file")
    if not os.access(path, os.R_OK):
        raise UsageError(f"eegt: cannot read input '{path}': permission denied")
    if ns.output:
        ext = os.path.splitext(ns.output)[1].lower()
        if ext not in OUTPUT_EXTENSIONS:
            raise UsageError(f"eegt: unsupported output type '{ext or ns.output}' (use .blend, "
                             ".obj, .ply or .stl)")
        _check_writable(ns.output, "output")
    if ns.report:
        _check_writable(ns.report, "report")


def _check_writable(path: str, what: str) -> None:
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise UsageError(f"eegt: cannot write {what} '{path}': is a directory")
    if not os.path.isdir(folder):
        raise UsageError(f"eegt: cannot write {what} '{path}': no folder {folder}")
    if not os.access(folder, os.W_OK | os.X_OK) or (
            os.path.exists(path) and not os.access(path, os.W_OK)):
        raise UsageError(f"eegt: cannot write {what} '{path}': permission denied")


def _load(path: str) -> None:
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
    """Write to a temporary file beside `path`, check it, rename it onto `path`; on any
    failure remove it and raise (UsageError, exit 2): `path` is then untouched."""
    ext = os.path.splitext(path)[1].lower()
    folder = os.path.dirname(os.path.abspath(path))
    tmp = os.path.join(folder, f".{os.path.basename(path)}.eegt-tmp-{os.getpid()}{ext}")
    try:
        _export(tmp, ext)
        problem = _incomplete(tmp, ext)
        if problem:
            raise UsageError(f"eegt: cannot write output '{path}': {problem}")
        os.replace(tmp, path)
    except RuntimeError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else "write error"
        first = first.removeprefix("Error: ")
        raise UsageError(f"eegt: cannot write output '{path}': {first}") from None
    except OSError as exc:
        raise UsageError(f"eegt: cannot write output '{path}': {exc.strerror or exc}") from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def _export(path: str, ext: str) -> None:
    if ext == ".blend":  # copy: the session keeps its file path; a new file has no backup
        bpy.ops.wm.save_as_mainfile(filepath=path, check_existing=False, copy=True)
    elif ext == ".obj":
        bpy.ops.wm.obj_export(filepath=path, forward_axis="Y", up_axis="Z",
                              export_materials=False)
    elif ext == ".ply":
        bpy.ops.wm.ply_export(filepath=path, forward_axis="Y", up_axis="Z")
    else:
        bpy.ops.wm.stl_export(filepath=path, forward_axis="Y", up_axis="Z")


def _incomplete(path: str, ext: str) -> str | None:
    """Why the freshly written file is not whole (Blender's exporters report success when
    the disk fills), or None."""
    if not os.path.isfile(path) or os.path.getsize(path) == 0:
        return "nothing was written"
    stat = os.statvfs(path)
    if stat.f_bavail == 0 and stat.f_blocks > 0:
        return "the disk is full"
    size = os.path.getsize(path)
    with open(path, "rb") as fh:
        head = fh.read(4096)
        fh.seek(max(0, size - 64))
        tail = fh.read()
    if ext == ".blend":
        if head.startswith(b"BLENDER") and b"ENDB" not in tail:
            return "the .blend file is truncated (no end block)"
        if head.startswith(ZSTD_MAGIC) and not tail.endswith(ZSTD_SEEKABLE_END):
            return "the compressed .blend file is truncated (no seek table)"
    elif ext == ".stl":
        if not head.startswith(b"solid") and len(head) >= 84:
            n = struct.unpack_from("<I", head, 80)[0]
            if size != 84 + 50 * n:
                return f"the STL file is truncated ({size} bytes for {n} triangles)"
        elif head.startswith(b"solid") and b"endsolid" not in tail:
            return "the STL file is truncated"
    elif ext == ".ply":
        return _ply_incomplete(path, head, size)
    elif ext == ".obj":
        return _obj_incomplete(path, tail)
    return None


def _ply_incomplete(path: str, head: bytes, size: int) -> str | None:
    """Binary little-endian PLY: walk the header's elements and compare with the size."""
    end = head.find(b"end_header\n")
    if end < 0:
        return "the PLY header is truncated"
    lines = head[:end].decode("ascii", "replace").splitlines()
    if "format binary_little_endian 1.0" not in lines:
        return None  # ASCII PLY (not what the exporter writes by default): no cheap check
    sizes = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2,
             "int16": 2, "uint16": 2, "int": 4, "uint": 4, "int32": 4, "uint32": 4,
             "float": 4, "float32": 4, "double": 8, "float64": 8}
    elements: list[list[Any]] = []  # [name, count, fixed bytes, list props (count, item)]
    for ln in lines:
        t = ln.split()
        if t[:1] == ["element"]:
            elements.append([t[1], int(t[2]), 0, []])
        elif t[:2] == ["property", "list"] and elements:
            elements[-1][3].append((sizes[t[2]], sizes[t[3]]))
        elif t[:1] == ["property"] and elements:
            elements[-1][2] += sizes[t[1]]
    pos = end + len(b"end_header\n")
    with open(path, "rb") as fh:
        for _name, count, fixed, lists in elements:
            if not lists:
                pos += count * fixed
                continue
            fh.seek(pos)
            body = fh.read()
            at = 0
            for _ in range(count):
                at += fixed
                for csize, isize in lists:
                    if at + csize > len(body):
                        return "the PLY file is truncated"
                    n = int.from_bytes(body[at:at + csize], "little")
                    at += csize + n * isize
            pos += at
    return None if pos == size else f"the PLY file is truncated ({size} of {pos} bytes)"


def _obj_incomplete(path: str, tail: bytes) -> str | None:
    """OBJ: ends with a whole line and holds a face line for every exported face."""
    if not tail.endswith(b"\n"):
        return "the OBJ file is truncated"
    expected = 0
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for obj in bpy.context.view_layer.objects:
        if obj.type == "MESH" and obj.visible_get():
            expected += len(obj.evaluated_get(depsgraph).data.polygons)
    faces = 0
    with open(path, "rb") as fh:
        for line in fh:
            faces += line.startswith(b"f ")
    if faces < expected:
        return f"the OBJ file is truncated ({faces} of {expected} faces)"
    return None


def _objects(names: list[str], path: str) -> list[bpy.types.Object]:
    """The mesh objects to process (one per mesh data); objects without faces are skipped
    with a line, and none with a face is a usage error (exit 2)."""
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
    meshes = [o for o in meshes if o not in faceless]
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
        _check_paths(ns)
        _load(ns.input)
        objs = _objects(ns.object, ns.input)
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
