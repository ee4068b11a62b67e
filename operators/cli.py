# SPDX-License-Identifier: GPL-3.0-or-later
"""``blender -b -c eegt INPUT ...``: the batch command for pipelines.

This module is the single-file command; many files in one command (folders, glob patterns,
an output folder, worker processes, Dask) are ``operators/batch.py``, which runs this
command once per file.

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
import struct
import sys
import threading
import traceback
from typing import Any

import bpy

from ..batch.inputs import replaces_input
from ..batch.solver_formats import SOLVER_EXTENSIONS
from ..core import EEGTParams
from ..core.backends import warm_up
from . import metrics, props, reference_input, report, runner, uv_runner
from .ops_untangle import _printer
from .reference_input import ReferenceSource, from_file
from .result import store_last_run
from .solver_io import command as solver_command

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_FAILED = 0, 1, 2, 3
MESH_EXTENSIONS = (".obj", ".ply", ".stl", *SOLVER_EXTENSIONS)
OUTPUT_EXTENSIONS = (".blend", *MESH_EXTENSIONS)
# A compressed .blend is zstd frames closed by a seek table (a skippable frame whose last
# four bytes are this magic), written last: a cut file lacks it.
ZSTD_MAGIC, ZSTD_SEEKABLE_END = b"\x28\xb5\x2f\xfd", b"\xb1\xea\x92\x8f"


class UsageError(Exception):
    """A command-line or input problem: one line, exit code 2 (0 for --help). `unwritable`:
    the path this error says cannot be written (the report is then not tried again)."""

    def __init__(self, message: str, code: int = EXIT_USAGE,
                 unwritable: str | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.unwritable = unwritable


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
                                          "without it); the input file itself only with "
                                          "--in-place")
    p.add_argument("--in-place", action="store_true",
                   help="write the result over the input file (without -o, or with -o naming "
                        "it): it is replaced whole once the result is saved and checked")
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
                   help="ignore the eegt_pinned attribute / vertex group (with --uv: the "
                        "UV pins)")
    p.add_argument("--uv", nargs="?", const="", default=None, metavar="MAP",
                   help="untangle and smooth the UV map MAP (default: the active one) of "
                        "every chosen object instead of its vertex positions; objects "
                        "without it are skipped")
    p.add_argument("--uv-scope", choices=("tangles", "selection"), default="tangles",
                   help="with --uv: move only tangled faces and the faces around them "
                        "(tangles, default) or every face (selection)")
    p.add_argument("--project", action="store_true",
                   help="project slightly non-planar meshes onto their plane")
    p.add_argument("--reference", metavar="OBJ", default=None,
                   help="target 'reference': an OBJ file of the same topology (same vertex "
                        "order and faces) whose face shapes are the targets (implies --target "
                        "reference)")
    p.add_argument("--reference-key", metavar="NAME", default=None,
                   help="target 'reference': the shape key whose face shapes are the targets "
                        "(implies --target reference; default with --target reference: the "
                        "Basis key when another key is active)")
    p.add_argument("--report", metavar="JSON", help="write a JSON report here")
    p.add_argument("--metrics", type=metrics.parse_names, metavar="LIST", default=(),
                   help="add the before/after min/mean/max and count beyond the threshold of "
                        "these quality measures to each object's report entry: all, or a "
                        "comma list of " + ", ".join(metrics.MEASURE_NAMES))
    p.add_argument("--no-write-on-fail", action="store_true",
                   help="leave a mesh unchanged when it could not be untangled")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    solver_command.add_arguments(p)
    return p


def _reference(ns: argparse.Namespace, params: EEGTParams) -> ReferenceSource | None:
    """The reference choice of target 'reference' (None for 'regular'); UsageError for a
    contradiction or an unreadable file."""
    if params.target != "reference":
        return None
    if ns.reference and ns.reference_key:
        raise UsageError("eegt: give --reference or --reference-key, not both")
    if ns.reference:
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
            raise UsageError(f"eegt: unsupported output type '{ext or ns.output}' (use .blend, "
                             ".obj, .ply or .stl)")
        why = replaces_input(path, ns.output, ns.in_place)
        if why:
            raise UsageError(why)
    try:
        solver_command.check_paths(ns)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if ns.output:
        _check_writable(ns.output, "output")
    if ns.report:
        _check_writable(ns.report, "report")


def _check_input_type(path: str) -> None:
    """The input is of a type the command reads (UsageError otherwise)."""
    ext = os.path.splitext(path)[1].lower()
    if ext != ".blend" and ext not in MESH_EXTENSIONS:
        raise UsageError(f"eegt: unsupported input type '{ext}' (use .blend, .obj, .ply or "
                         ".stl)")


def _check_writable(path: str, what: str) -> None:
    """`path` can be created or overwritten: open it for appending (which changes nothing
    in an existing file) and remove it again if it is new."""
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise UsageError(f"eegt: cannot write {what} '{path}': is a directory",
                         unwritable=path)
    if not os.path.isdir(folder):
        raise UsageError(f"eegt: cannot write {what} '{path}': no folder {folder}",
                         unwritable=path)
    existed = os.path.exists(path)
    try:  # non-blocking: a FIFO without a reader fails here instead of hanging
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NONBLOCK, 0o666))
        if not existed:
            os.remove(path)
    except OSError as exc:
        raise UsageError(f"eegt: cannot write {what} '{path}': {_why(exc)}",
                         unwritable=path) from None


def _why(exc: OSError) -> str:
    """An OSError as a short lower-case reason ("permission denied")."""
    return (exc.strerror or str(exc)).lower()


def _first_line(exc: RuntimeError, default: str) -> str:
    """A Blender operator's error as one line, without its "Error: " prefix."""
    text = str(exc).strip()
    return text.splitlines()[0].removeprefix("Error: ") if text else default


def _tmp_path(path: str) -> str:
    """A hidden temporary name beside `path` (beside its target if it is a symbolic link,
    which then keeps pointing at the new file), same extension (exporters insist on it)."""
    real = os.path.realpath(path)
    name = os.path.basename(real)
    return os.path.join(os.path.dirname(real),
                        f".{name}.eegt-tmp-{os.getpid()}{os.path.splitext(name)[1]}")


def _discard(path: str | None) -> None:
    """Remove a temporary file if it is there."""
    if path and os.path.lexists(path):
        os.remove(path)


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
        raise UsageError(f"eegt: cannot read input '{path}': {_first_line(exc, 'read error')}"
                         ) from None


def _load_solver(ns: argparse.Namespace, params: EEGTParams) -> tuple[EEGTParams, dict]:
    """A solver mesh input as an object with its pins; the run's parameters."""
    try:
        return solver_command.load(ns, params)
    except ValueError as exc:
        raise UsageError(f"eegt: {exc}".replace("eegt: eegt: ", "eegt: ")) from None


def _stage(path: str) -> str:
    """Export to a temporary file beside `path` and check it is whole; its name. On any
    failure it is removed and UsageError (exit 2) raised: `path` is never touched here."""
    ext = os.path.splitext(path)[1].lower()
    tmp = _tmp_path(path)
    try:
        if solver_command.is_solver(path):
            solver_command.export(tmp)
            problem = solver_command.incomplete(tmp)
        else:
            _export(tmp, ext)
            problem = _incomplete(tmp, ext)
    except (RuntimeError, ValueError) as exc:
        problem = _first_line(exc, "write error")
    except OSError as exc:
        problem = _why(exc)
    except BaseException:
        _discard(tmp)
        raise
    if problem:
        _discard(tmp)
        raise UsageError(f"eegt: cannot write output '{path}': {problem}")
    return tmp


def _export(path: str, ext: str) -> None:
    if ext == ".blend":  # copy: the session keeps its file path; a new file has no backup
        bpy.ops.wm.save_as_mainfile(filepath=path, check_existing=False, copy=True)
    elif ext == ".obj":
        bpy.ops.wm.obj_export(filepath=path, forward_axis="Y", up_axis="Z",
                              export_materials=False)
    elif ext == ".ply":  # binary: its size can be checked against the header
        bpy.ops.wm.ply_export(filepath=path, forward_axis="Y", up_axis="Z", ascii_format=False)
    else:  # binary: its size is 84 + 50 * triangles
        bpy.ops.wm.stl_export(filepath=path, forward_axis="Y", up_axis="Z", ascii_format=False)


def _incomplete(path: str, ext: str) -> str | None:
    """Why the freshly written file is not whole, or None. Blender's writers report success
    when the disk fills, so each format is checked for its own end."""
    if not os.path.isfile(path) or os.path.getsize(path) == 0:
        return "nothing was written"
    size = os.path.getsize(path)
    with open(path, "rb") as fh:
        head = fh.read(65536)
        fh.seek(max(0, size - 64))
        tail = fh.read()
    if ext == ".blend":
        return _blend_incomplete(path, head, tail, size)
    if ext == ".stl":
        n = struct.unpack_from("<I", head, 80)[0] if size >= 84 else -1
        return None if size == 84 + 50 * n else \
            f"the STL file is truncated ({size} bytes for {max(n, 0)} triangles)"
    if ext == ".ply":
        return _ply_incomplete(path, head, size)
    return _obj_incomplete(path, tail)


def _blend_incomplete(path: str, head: bytes, tail: bytes, size: int) -> str | None:
    """A .blend ends with its ENDB block header (the code, then zeros: 32 bytes in the
    "BLENDER17-01" format of 5.0, else 24 or 20 for 8- or 4-byte pointers); a compressed one
    is zstd frames closed by a seek table whose frame sizes add up to the file size."""
    if head.startswith(b"BLENDER"):
        bhead = 32 if head[7:9] == b"17" else 24 if head[7:8] == b"-" else 20
        if tail.endswith(b"ENDB" + bytes(bhead - 4)):
            return None
        return "the .blend file is truncated (no end block)"
    if not head.startswith(ZSTD_MAGIC):
        return "not a .blend file"
    if len(tail) < 17 or not tail.endswith(ZSTD_SEEKABLE_END):
        return "the compressed .blend file is truncated (no seek table)"
    frames, flags = struct.unpack_from("<IB", tail, len(tail) - 9)
    entry = 12 if flags & 0x80 else 8
    table = 8 + frames * entry + 9  # skippable frame header + entries + footer
    if table > size:
        return "the compressed .blend file is truncated (bad seek table)"
    with open(path, "rb") as fh:
        fh.seek(size - table)
        raw = fh.read(table)
    magic, length = struct.unpack_from("<II", raw)
    total = sum(struct.unpack_from("<I", raw, 8 + i * entry)[0] for i in range(frames))
    if magic != 0x184D2A5E or length != table - 8 or total != size - table:
        return "the compressed .blend file is truncated (its frames do not add up)"
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
        edited = reference_input.edited_key(obj)
        if ref.file:
            n, f = ref.file_points.shape[0], ref.file_faces.n_faces
            if not reference_input.same_topology(me, n, ref.file_faces):
                raise UsageError(
                    f"eegt: --reference '{ref.file}' ({n} vertices, {f} faces) does not fit "
                    f"object '{obj.name}' ({len(me.vertices)} vertices, {len(me.polygons)} "
                    "faces): a reference has the same vertices and faces, in the same order")
        elif not ref.key and reference_input.default_key(me, edited) is None:
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
            reference_input.reference_positions(obj, ref, edited)
        except ValueError as exc:
            raise UsageError(f"eegt: object '{obj.name}': {exc}") from None


def _backend(choice: str | None, device: str | None) -> tuple[str, str | None]:
    from .prefs import resolve_backend
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
        rep["params"] = params.as_dict() if hasattr(params, "as_dict") else \
            dataclasses.asdict(params)
        if reference is not None:
            rep["reference"] = reference.describe()
        backend, device = _backend(ns.backend, ns.device)
        rep["backend_requested"] = backend
        warming = _warm_device(backend, device)
        if solver_command.is_solver(ns.input):
            params, rep["solver_mesh"] = _load_solver(ns, params)
            rep["params"] = dataclasses.asdict(params)
        else:
            _load(ns.input)
        objs, skipped = _objects(ns.object, ns.input)
        rep["skipped"] = [{"object": name, "reason": "no faces"} for name in skipped]
        if bpy.context.mode != "OBJECT" and bpy.ops.object.mode_set.poll():
            bpy.ops.object.mode_set(mode="OBJECT")
        if ns.uv is not None:
            objs = _uv_objects(objs, ns.uv, rep)
        if reference is not None:
            _check_reference(objs, reference)
        results, measured = [], []
        for obj in objs:
            progress = None if ns.quiet else _printer(obj.name)
            if ns.uv is not None:
                res = uv_runner.run_object(obj, params, ns.uv or None, backend=backend,
                                           device=device, use_pins=not ns.no_pinned,
                                           scope=ns.uv_scope, progress=progress,
                                           write_on_fail=not ns.no_write_on_fail)
                store_last_run(obj, res)
                results.append(res)
                measured.append(None)  # --metrics measure positions, which --uv leaves alone
                print("EEGT " + res.line(), flush=True)
                continue
            job = runner.prepare(obj, use_pinned=not ns.no_pinned, project=ns.project,
                                 reference=reference)
            runner.compute(job, params, backend, progress, device)
            ok = job.error is None and job.result is not None and \
                job.result.status in ("valid", "untangled")
            res = runner.apply(obj, job, write=ok or not ns.no_write_on_fail)
            store_last_run(obj, res)
            results.append(res)
            measured.append(metrics.run_metrics(job, res, ns.metrics) if ns.metrics else None)
            if ns.metrics and "solver_mesh" in rep:
                rep["solver_mesh"]["metrics"] = solver_command.group_metrics(job, res,
                                                                             ns.metrics)
            print("EEGT " + res.line(), flush=True)
        rep["objects"] = [r.as_dict() for r in results]
        if ns.metrics:
            for entry, m in zip(rep["objects"], measured):
                entry["metrics"] = m
        if ns.output:
            staged = _stage(ns.output)
        else:
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
    tmp = _tmp_path(path) if path and not special else None
    try:
        if path:
            with open(tmp or path, "w", encoding="utf-8") as fh:
                json.dump(rep, fh, indent=2)
    except OSError as exc:
        _discard(tmp)
        _discard(staged)
        failed = _fail(rep, f"eegt: cannot write report '{path}': {_why(exc)}")
        return code if code == EXIT_INTERNAL else failed
    try:
        if staged:
            os.replace(staged, os.path.realpath(out))
    except OSError as exc:
        _discard(staged)
        _discard(tmp)
        code = _fail(rep, f"eegt: cannot write output '{out}': {_why(exc)}")
        return _commit(ns, rep, code, None)
    try:
        if tmp:
            os.replace(tmp, os.path.realpath(path))
    except OSError as exc:
        _discard(tmp)
        return _fail(rep, f"eegt: cannot write report '{path}': {_why(exc)}")
    return code


def execute(argv: list[str]) -> int:
    """The registered command handler: the process exit code. Many inputs, a folder, a
    glob pattern, an output folder or a batch flag make it a batch (operators/batch.py),
    whose workers run this single-file command."""
    from . import batch
    argv = list(argv)
    if batch.is_batch(argv):
        return batch.run(argv)
    return run(argv)[0]


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
