# SPDX-License-Identifier: GPL-3.0-or-later
"""A Gmsh 4.1 file written back as it is, with only its moved nodes' coordinates changed.

meshio's 4.1 writer cannot write a file without physical groups (what Gmsh saves when none
are defined), keeps one physical group per entity, and writes some files it then cannot
read back (found on Gmsh's own 2D benchmarks). A Gmsh 4.1 file written as Gmsh 4.1 is
therefore copied byte for byte, the moved nodes' coordinates put into its ``$Nodes``
section: ASCII as Python's shortest exact repr, binary as the file's own doubles. The node
order is the file's (meshio's points are the nodes in file order, block by block);
parametric nodes are not read by meshio, so there are none here.
"""

from __future__ import annotations

import re

import numpy as np

__all__ = ["Gmsh41Error", "write_moved"]


class Gmsh41Error(ValueError):
    """A Gmsh 4.1 file whose ``$Nodes`` section cannot be patched (one line)."""


def _section(data: bytes) -> tuple[bool, int, int]:
    """(binary, size_t bytes, offset just after the ``$Nodes`` line)."""
    m = re.search(rb"\$MeshFormat\r?\n\s*4\.1\s+(\d)\s+(\d+)", data)
    if not m:
        raise Gmsh41Error("not a Gmsh 4.1 file")
    binary, size_t = m.group(1) == b"1", int(m.group(2))
    n = re.search(rb"(?m)^\$Nodes\r?\n", data)
    if not n:
        raise Gmsh41Error("no $Nodes section")
    if binary and size_t not in (4, 8):
        raise Gmsh41Error(f"size_t of {size_t} bytes")
    if binary and int.from_bytes(data[m.end():m.end() + 8].lstrip(b"\r\n")[:4],
                                 "little") != 1:
        raise Gmsh41Error("a binary file of the other byte order")
    return binary, size_t, n.end()


def _ascii_lines(data: bytes, start: int, n_points: int) -> np.ndarray:
    """(n_points, 2) byte spans [begin, end) of the nodes' coordinate lines (without the
    line break), in file order."""
    buf = np.frombuffer(data, dtype=np.uint8)
    ends = np.flatnonzero(buf[start:] == 10) + start
    begins = np.concatenate([[start], ends[:-1] + 1])
    line = 0

    def words(k: int) -> list[bytes]:
        return data[begins[k]:ends[k]].split()

    n_blocks, total = (int(w) for w in words(line)[:2])
    if total != n_points:
        raise Gmsh41Error(f"$Nodes holds {total} nodes, the mesh {n_points}")
    line += 1
    spans = np.empty((n_points, 2), dtype=np.int64)
    at = 0
    for _ in range(n_blocks):
        head = words(line)
        if len(head) != 4 or int(head[2]) != 0:
            raise Gmsh41Error("a $Nodes block with parametric coordinates")
        count = int(head[3])
        first = line + 1 + count  # the tags come first, then the coordinates
        spans[at:at + count, 0] = begins[first:first + count]
        e = ends[first:first + count]
        spans[at:at + count, 1] = e - (buf[e - 1] == 13)  # without the CR of a CR LF
        at += count
        line = first + count
    if at != n_points:
        raise Gmsh41Error(f"$Nodes blocks hold {at} nodes, the mesh {n_points}")
    return spans


def _binary_offsets(data: bytes, start: int, size_t: int, n_points: int) -> np.ndarray:
    """(n_points,) byte offsets of the nodes' x coordinates (x, y, z: three doubles)."""
    st = np.dtype(f"<u{size_t}")
    n_blocks, total = (int(v) for v in np.frombuffer(data, st, 2, start))
    if total != n_points:
        raise Gmsh41Error(f"$Nodes holds {total} nodes, the mesh {n_points}")
    at, pos = 0, start + 4 * size_t
    offsets = np.empty(n_points, dtype=np.int64)
    for _ in range(n_blocks):
        _, _, parametric = (int(v) for v in np.frombuffer(data, "<i4", 3, pos))
        count = int(np.frombuffer(data, st, 1, pos + 12)[0])
        if parametric != 0:
            raise Gmsh41Error("a $Nodes block with parametric coordinates")
        coords = pos + 12 + size_t + count * size_t
        offsets[at:at + count] = coords + 24 * np.arange(count, dtype=np.int64)
        at += count
        pos = coords + 24 * count
    if at != n_points:
        raise Gmsh41Error(f"$Nodes blocks hold {at} nodes, the mesh {n_points}")
    return offsets


def write_moved(src: str, dst: str, positions: np.ndarray | None,
                moved: np.ndarray | None) -> None:
    """Copy the Gmsh 4.1 file `src` to `dst` with the `moved` nodes at `positions` ((N, 3)
    or (N, 2): z kept); everything else byte for byte. Gmsh41Error when its ``$Nodes``
    section is not the N nodes of meshio's reading."""
    with open(src, "rb") as fh:
        data = fh.read()
    out: bytes | bytearray = data
    if positions is not None and moved is not None and np.any(moved):
        pos = np.asarray(positions, dtype=np.float64)
        ids = np.flatnonzero(np.asarray(moved, dtype=bool))
        k = min(pos.shape[1], 3)  # x, y (and z when given)
        binary, size_t, start = _section(data)
        if binary:
            offsets = _binary_offsets(data, start, size_t, len(moved))
            out = bytearray(data)
            for i in ids.tolist():  # the moved nodes only
                out[offsets[i]:offsets[i] + 8 * k] = pos[i, :k].astype("<f8").tobytes()
        else:
            spans = _ascii_lines(data, start, len(moved))
            pieces, last = [], 0
            for i in ids.tolist():
                b, e = int(spans[i, 0]), int(spans[i, 1])
                xyz = [repr(float(v)) for v in pos[i, :k]]
                xyz += [w.decode() for w in data[b:e].split()[k:3]]
                pieces += [data[last:b], " ".join(xyz).encode()]
                last = e
            pieces.append(data[last:])
            out = b"".join(pieces)
    with open(dst, "wb") as fh:
        fh.write(out)
