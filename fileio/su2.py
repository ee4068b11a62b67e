# SPDX-License-Identifier: GPL-3.0-or-later
"""SU2 meshes (single zone, NDIME 2 or 3) read and written without meshio's SU2 code, which
drops marker names and cannot read its own 3D output (docs/engineers.md).

A read gives a meshio mesh: the interior elements (``NELEM``) as cell blocks in file order
(a new block where the element type changes) with ``su2:tag`` 0, then every marker's
elements in file order with the marker's tag (its name when it is a number, else the
previous tag + 1: meshio's own numbering) and ``field_data[name] = [tag, NDIME - 1]``.
A write takes the interior from the cells of dimension NDIME and the markers from the
cells of dimension NDIME - 1, grouped by tag in the order they come, named from
``field_data`` (else the tag). Points are written with Python's shortest exact repr. The
index columns of the point, interior element and marker element records are the file's own
(kept in the layout when they are not the row numbers 0, 1, 2, ...), else the row numbers;
a marker whose records have none is written without. The angle offsets after NDIME
(`HEADER_KEYS`) and the sections after the markers (`TAIL_KEYS`: periodic transformations,
FFD boxes, to the end of the file) are written back as they are: FFD surface points keep
their parametric coordinates, those of the input's wall.
Anything the format has no place for is a `Su2Error` of one line.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

# SU2 (VTK) element type -> (meshio type, corners)
SU2_TYPES = {3: ("line", 2), 5: ("triangle", 3), 9: ("quad", 4), 10: ("tetra", 4),
             12: ("hexahedron", 8), 13: ("wedge", 6), 14: ("pyramid", 5)}
MESHIO_TO_SU2 = {name: code for code, (name, _) in SU2_TYPES.items()}
_DIM = {"line": 1, "triangle": 2, "quad": 2, "tetra": 3, "hexahedron": 3, "wedge": 3,
        "pyramid": 3}
TAG_NAMES = ("su2:tag", "gmsh:physical", "medit:ref", "CellEntityIds")
# What SU2 files carry besides the mesh, kept as they are: header lines after NDIME (the
# angle of attack and of sideslip the solver adds), and the sections after the markers
# (periodic transformations, FFD boxes), from their first keyword to the end of the file
HEADER_KEYS = ("AOA_OFFSET", "AOS_OFFSET")
TAIL_KEYS = ("NPERIODIC", "FFD_NBOX")


class Su2Error(ValueError):
    """An SU2 file that cannot be read, or a mesh SU2 cannot hold (one line)."""


def _records(lines: list[str]) -> list[tuple[int, str]]:
    """(line number, text) of every line with its ``%`` comment and blanks removed."""
    out = []
    for no, line in enumerate(lines, 1):
        text = line.split("%", 1)[0].strip()
        if text:
            out.append((no, text))
    return out


def _keyword(text: str) -> tuple[str, str] | None:
    if "=" not in text:
        return None
    key, value = text.split("=", 1)
    key = key.strip().upper()
    return (key, value.strip()) if key.replace("_", "").isalpha() else None


def read(path: str) -> tuple[Any, dict[str, Any]]:
    """The meshio mesh of an SU2 file and its layout (``ndime``, whether point and element
    records carry their index): what `write` needs to give the same records back."""
    import meshio

    with open(path, encoding="utf-8", errors="replace") as fh:
        lines = fh.readlines()
    recs = _records(lines)
    i, ndime, points, layout = 0, 0, None, {"point_index": False, "elem_index": False}
    blocks: list[tuple[str, list[list[int]], int]] = []  # (type, rows, tag)
    field_data: dict[str, np.ndarray] = {}
    tag, n_mark, marker = 0, None, None
    ids: list[str] = []  # the interior elements' own index column, as written
    n_interior = 0

    def elements(count: int, at: int, tag_: int, interior: bool) -> int:
        own: list[str] = []  # a marker's index column, as written
        for k in range(count):
            if at + k >= len(recs):
                raise Su2Error(f"{'NELEM' if interior else 'MARKER_ELEMS'} promises {count} "
                               f"elements, the file ends after {k}")
            no, text = recs[at + k]
            words = text.split()
            try:
                code = int(words[0])
                kind, n = SU2_TYPES[code]
                nodes = [int(w) for w in words[1:1 + n]]
            except (ValueError, KeyError):
                raise Su2Error(_not_an_element(no, text)) from None
            extra = len(words) - 1 - n
            if len(nodes) != n or extra not in (0, 1):
                raise Su2Error(f"line {no}: element type {code} takes {n} nodes")
            if interior and extra:
                layout["elem_index"] = True
                ids.append(words[-1])
            elif extra:
                own.append(words[-1])
            if k and blocks[-1][0] == kind:
                blocks[-1][1].append(nodes)
            else:
                blocks.append((kind, [nodes], tag_))
        if own:  # SU2 reads a marker element's nodes and skips what follows
            if len(own) != count:
                raise Su2Error(f"marker {marker}: some elements have an index column and "
                               "some do not")
            layout.setdefault("marker_ids", {})[marker] = _own_numbers(own)
        return at + count

    while i < len(recs):
        no, text = recs[i]
        kw = _keyword(text)
        if kw is None:
            raise Su2Error(f"line {no}: expected a KEYWORD= line, got '{text[:40]}'")
        key, value = kw
        i += 1
        try:
            if key == "NDIME":
                ndime = int(value)
                if ndime not in (2, 3):
                    raise Su2Error(f"line {no}: NDIME= {value} (2 or 3)")
            elif key == "NELEM":
                n_interior += int(value)
                i = elements(int(value), i, 0, True)
            elif key == "NPOIN":
                if ndime == 0:
                    raise Su2Error(f"line {no}: NPOIN before NDIME")
                n = int(value.split()[0])
                rows = recs[i:i + n]
                if len(rows) < n:
                    raise Su2Error(f"NPOIN promises {n} points, the file ends after "
                                   f"{len(rows)}")
                width = len(rows[0][1].split()) if rows else ndime
                if width not in (ndime, ndime + 1, ndime + 2):
                    raise Su2Error(f"line {rows[0][0]}: a point of NDIME= {ndime} has "
                                   f"{width} numbers")
                try:
                    flat = np.array(" ".join(t for _, t in rows).split(), dtype=np.float64)
                    points = flat.reshape(n, width)[:, :ndime].copy()
                except ValueError:
                    raise Su2Error(f"the {n} points after line {no} are not {width} numbers "
                                   "each") from None
                layout["point_index"] = width > ndime
                if width > ndime:
                    layout["point_ids"] = _own_numbers(
                        [t.split()[ndime] for _, t in rows])
                i += n
            elif key == "NMARK":
                n_mark = int(value)
            elif key in ("MARKER_TAG", "MARKERTAG"):
                if key == "MARKERTAG":  # SU2 reads a marker's name by position after
                    # 11 characters: "MARKERTAG= name" is read as "MARKER_TAG= name" (SU2's
                    # TestCases deformation/naca4412); written back as spelled
                    layout["marker_key"] = key
                marker = value
                try:
                    tag = int(value)
                except ValueError:
                    tag += 1
                field_data[marker] = np.array([tag, max(ndime - 1, 0)], dtype=np.int64)
            elif key == "MARKER_ELEMS":
                if marker is None:
                    raise Su2Error(f"line {no}: MARKER_ELEMS before MARKER_TAG")
                i = elements(int(value), i, tag, False)
                marker = None
            elif key in HEADER_KEYS and points is None and not blocks:
                layout.setdefault("header", []).append(f"{key}= {value}")
            elif key in TAIL_KEYS and n_mark is not None and marker is None and \
                    len(field_data) == n_mark:
                layout["tail"] = "".join(lines[no - 1:])  # written back after the markers
                break
            else:
                raise Su2Error(f"line {no}: '{key}' is not kept (single-zone meshes: NDIME, "
                               "NELEM, NPOIN, NMARK, MARKER_TAG (or MARKERTAG), MARKER_ELEMS; "
                               f"{', '.join(HEADER_KEYS)} before the elements; "
                               f"{', '.join(TAIL_KEYS)} after the markers)")
        except ValueError as exc:
            if isinstance(exc, Su2Error):
                raise
            raise Su2Error(f"line {no}: '{text[:40]}' is not a number") from None
    if points is None:
        raise Su2Error("no NPOIN section")
    if n_mark is not None and n_mark != len(field_data):
        raise Su2Error(f"NMARK= {n_mark} but {len(field_data)} markers")
    cells = [meshio.CellBlock(kind, np.array(rows, dtype=np.int64)) for kind, rows, _ in
             blocks]
    tags = [np.full(len(rows), t, dtype=np.int32) for _, rows, t in blocks]
    layout["ndime"] = ndime
    if layout["elem_index"]:
        if len(ids) != n_interior:
            raise Su2Error("some interior elements have an index column and some do not")
        layout["elem_ids"] = _own_numbers(ids)
    mesh = meshio.Mesh(points, cells, cell_data={"su2:tag": tags} if cells else {},
                       field_data=field_data)
    return mesh, layout


def _not_an_element(no: int, text: str) -> str:
    """The one line for a record where an element was expected."""
    kw = _keyword(text)
    if kw is not None:
        extra = (" (a SEND_RECEIVE marker: SU2 itself no longer reads them)"
                 if kw[0] == "SEND_TO" else "")
        return f"line {no}: '{kw[0]}' where an element was expected{extra}"
    head = text.split()[0] if text.split() else ""
    if head.isdigit() and int(head) not in SU2_TYPES:
        kinds = ", ".join(f"{c} {k}" for c, (k, _) in SU2_TYPES.items())
        order = " (a high-order element)" if int(head) >= 100 else ""
        return f"line {no}: element type {head}{order} is not one this reads ({kinds})"
    return f"line {no}: not an SU2 element ('{text[:40]}')"


def _own_numbers(words: list[str]) -> tuple[str, ...] | None:
    """A record index column as the file writes it, or None when it is the row numbers
    0, 1, 2, ... (what `write` writes without it)."""
    if all(w == str(k) for k, w in enumerate(words)):
        return None
    return tuple(words)


def _tags(mesh: Any) -> tuple[str | None, list[np.ndarray]]:
    for name in TAG_NAMES:
        if name in mesh.cell_data:
            return name, [np.asarray(a).reshape(len(a), -1)[:, 0].astype(np.int64)
                          for a in mesh.cell_data[name]]
    return None, [np.zeros(len(b.data), dtype=np.int64) for b in mesh.cells]


def plan(mesh: Any, layout: dict[str, Any] | None = None) -> tuple[int, str | None]:
    """(NDIME, None) when SU2 can hold `mesh`, else (0, the one-line reason)."""
    dims = {_DIM.get(b.type, -1) for b in mesh.cells if len(b.data)}
    odd = sorted({b.type for b in mesh.cells if b.type not in MESHIO_TO_SU2 and len(b.data)})
    if odd:
        return 0, f"SU2 has no element type for {', '.join(odd)} cells"
    ndime = (layout or {}).get("ndime") or max(dims | {2})
    pts = np.asarray(mesh.points)
    if ndime == 2 and pts.shape[1] == 3 and np.any(pts[:, 2] != 0):
        return 0, "a 2D SU2 mesh lies in z = 0 and these points do not"
    low = sorted({b.type for b in mesh.cells if len(b.data) and _DIM[b.type] < ndime - 1})
    if low:
        return 0, f"SU2 (NDIME= {ndime}) has no place for {', '.join(low)} cells"
    if ndime not in dims:
        return 0, f"SU2 needs interior elements of dimension {ndime}"
    return ndime, None


def write(path: str, mesh: Any, layout: dict[str, Any] | None = None) -> None:
    """Write `mesh` as SU2 (the `layout` of a read file gives its records back)."""
    ndime, why = plan(mesh, layout)
    if why:
        raise Su2Error(why)
    layout = layout or {}
    _, tags = _tags(mesh)
    names = {}
    for name, value in mesh.field_data.items():
        v = np.asarray(value).ravel().tolist()
        if v and (len(v) < 2 or int(v[1]) == ndime - 1):
            names.setdefault(int(v[0]), name)
    interior, markers = [], {}
    for block, t in zip(mesh.cells, tags):
        dim = _DIM[block.type]
        data = np.asarray(block.data, dtype=np.int64)
        if dim == ndime:  # elements of the mesh's own dimension are interior, whatever tag
            interior.append((block.type, data))
            continue
        cuts = [0, *(np.flatnonzero(t[1:] != t[:-1]) + 1).tolist(), len(data)]
        for lo, hi in itertools.pairwise(cuts):
            if hi > lo:
                markers.setdefault(int(t[lo]), []).append((block.type, data[lo:hi]))
    pts = np.asarray(mesh.points, dtype=np.float64)[:, :ndime]
    n_elem = sum(len(d) for _, d in interior)
    elem_ids = _ids(layout.get("elem_ids"), n_elem, "element")
    point_ids = _ids(layout.get("point_ids"), len(pts), "point")
    out = [f"NDIME= {ndime}\n", *(f"{h}\n" for h in layout.get("header", ())),
           f"NELEM= {n_elem}\n"]
    out += _element_lines(interior, elem_ids if layout.get("elem_index", True) else None)
    out.append(f"NPOIN= {len(pts)}\n")
    index = layout.get("point_index", True)
    for j, row in enumerate(pts.tolist()):
        out.append(" ".join(map(repr, row)) + (f" {point_ids[j]}\n" if index else "\n"))
    out.append(f"NMARK= {len(markers)}\n")
    marker_ids = layout.get("marker_ids", {})
    for t, parts in markers.items():
        name = names.get(t, str(t))
        count = sum(len(d) for _, d in parts)
        out.append(f"{layout.get('marker_key', 'MARKER_TAG')}= {name}\n")
        out.append(f"MARKER_ELEMS= {count}\n")
        out += _element_lines(parts, _ids(marker_ids[name], count, "element")
                              if name in marker_ids else None)
    tail = layout.get("tail")
    if tail:
        out.append(tail)
    with open(path, "w", encoding="utf-8") as fh:
        fh.writelines(out)


def _element_lines(parts: list[tuple[str, np.ndarray]], ids: Any) -> list[str]:
    """The records of the (type, node rows) parts: the SU2 type, the nodes, and the index
    column `ids` (one per record over all parts) unless it is None."""
    out, k = [], 0
    for kind, data in parts:
        code = MESHIO_TO_SU2[kind]
        for row in data.tolist():
            out.append(" ".join(map(str, [code, *row] if ids is None else
                                    [code, *row, ids[k]])) + "\n")
            k += 1
    return out


def _ids(own: tuple[str, ...] | None, n: int, what: str) -> Any:
    """The index column to write: the file's own (`own`), else the row numbers."""
    if own is None:
        return range(n)
    if len(own) != n:
        raise Su2Error(f"the file numbers {len(own)} {what}s, the mesh has {n}")
    return own
