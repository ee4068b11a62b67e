# SPDX-License-Identifier: GPL-3.0-or-later
"""The command's output file: exported to a hidden temporary file beside the target, checked
for the format's own end (Blender's writers report success on a full disk), then renamed into
place by the caller; see ``cli.py`` for the whole promise. A solver mesh output is staged by
``solver_run.py`` through ``fileio.checked_write`` (written, read back whole)."""

from __future__ import annotations

import os
import struct
from typing import Any

import bpy

from ...fileio.checked_write import discard, tmp_path
from .usage import UsageError, why

# A compressed .blend is zstd frames closed by a seek table (a skippable frame whose last
# four bytes are this magic), written last: a cut file lacks it.
ZSTD_MAGIC, ZSTD_SEEKABLE_END = b"\x28\xb5\x2f\xfd", b"\xb1\xea\x92\x8f"


def first_line(exc: RuntimeError, default: str) -> str:
    """A Blender operator's error as one line, without its "Error: " prefix."""
    text = str(exc).strip()
    return text.splitlines()[0].removeprefix("Error: ") if text else default


def stage(path: str) -> str:
    """Export to a temporary file beside `path` and check it is whole; its name. On any
    failure it is removed and UsageError (exit 2) raised: `path` is never touched here."""
    ext = os.path.splitext(path)[1].lower()
    tmp = tmp_path(path)
    try:
        _export(tmp, ext)
        problem = incomplete(tmp, ext)
    except RuntimeError as exc:
        problem = first_line(exc, "write error")
    except OSError as exc:
        problem = why(exc)
    except BaseException:
        discard(tmp)
        raise
    if problem:
        discard(tmp)
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


def incomplete(path: str, ext: str) -> str | None:
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
