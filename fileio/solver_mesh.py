# SPDX-License-Identifier: GPL-3.0-or-later
"""Solver meshes (Gmsh, VTK, Abaqus, Medit, SU2) read and written through meshio, with
everything the untangler does not touch kept as it was (docs/engineers.md).

Only the 2D cells (triangle, quad and polygon blocks) are faces the untangler moves; every
other cell block (lines, vertices, volume cells), every point, cell and field data array,
the groups and the file's format version (Gmsh 2.2 or 4.1, ASCII or binary; VTK legacy
ASCII or binary; VTU ASCII, binary or compressed) pass through: `write_moved` changes only
the coordinates of the nodes given as moved.

Groups are named by name or by tag: meshio's cell sets and point sets (Abaqus element and
node sets), Gmsh's physical names and SU2's marker names (field data ``name -> [tag, dim]``)
and the tag arrays of the formats' cells (``gmsh:physical``, ``medit:ref``, ``su2:tag``,
``CellEntityIds``). SU2 is read and written by `su2` (meshio's SU2 code drops marker names);
Gmsh sections meshio does not model are refused at read; a conversion to another format is
checked first by `can_write`.

No bpy and no core: the command, its batches and the Blender import/export all call this
module (faces come out as CSR arrays, which ``core.faces_from_csr`` takes). Every problem
with a file is a `SolverMeshError` of one line.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import hashlib
import io
import os
import re
import tempfile
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import gmsh41_nodes, su2
from .solver_formats import SOLVER_FORMATS, solver_format

FACE_TYPES = ("triangle", "quad", "polygon")  # the 2D cells the untangler moves
TAG_ARRAYS = ("gmsh:physical", "medit:ref", "su2:tag", "CellEntityIds")
_POINT_TYPES = ("vertex",)
_LINE_PREFIX = "line"
_FACE_PREFIXES = ("triangle", "quad", "polygon")
# the Gmsh sections meshio reads and writes back; any other is refused at read
GMSH_SECTIONS = ("MeshFormat", "PhysicalNames", "Entities", "Nodes", "Elements", "Periodic",
                 "NodeData", "ElementData")
_GMSH_TAGS = ("gmsh:physical", "gmsh:geometrical", "cell_tags")


class SolverMeshError(ValueError):
    """A solver mesh that cannot be read, used or written (a one-line message)."""


def cell_dim(cell_type: str) -> int:
    """The topological dimension of a meshio cell type (0 vertex, 1 line, 2 face, 3 volume)."""
    if cell_type in _POINT_TYPES:
        return 0
    if cell_type.startswith(_LINE_PREFIX):
        return 1
    if cell_type.startswith(_FACE_PREFIXES):
        return 2
    return 3


def file_digest(path: str) -> str:
    """SHA-256 of a file's bytes (hex): ties a Blender mesh to the file it came from."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


@contextlib.contextmanager
def _quiet():
    """meshio prints warnings on the console: they are not the command's one line."""
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        yield


def write_options(path: str, fmt: str) -> dict[str, Any]:
    """The writer options that keep a file's own format version: Gmsh's version and
    binary flag, VTK's legacy version and ASCII/binary, VTU's encoding and compression."""
    with open(path, "rb") as fh:
        head = fh.read(4096)
    if fmt == "msh":
        m = re.search(rb"\$MeshFormat\s+(\S+)\s+(\d)", head)
        if not m:
            return {"fmt_version": "4.1", "binary": False}
        version = "2.2" if m.group(1).startswith(b"2") else "4.1"
        return {"fmt_version": version, "binary": m.group(2) == b"1"}
    if fmt == "vtk":
        lines = head.split(b"\n")
        version = "5.1" if lines and b"Version 5" in lines[0] else "4.2"
        binary = len(lines) > 2 and lines[2].strip().upper().startswith(b"BINARY")
        return {"fmt_version": version, "binary": binary}
    if fmt == "vtu":
        with open(path, "rb") as fh:
            text = fh.read()
        compression = None
        m = re.search(rb'compressor="vtk(\w+)DataCompressor"', text)
        if m:
            compression = {b"ZLib": "zlib", b"LZMA": "lzma", b"LZ4": "lz4"}.get(m.group(1))
        binary = re.search(rb'format="(binary|appended)"', text) is not None
        return {"binary": binary, "compression": compression if binary else None}
    if fmt == "mesh" or fmt == "inp":
        return {"float_fmt": ".16e"}
    if fmt == "su2":
        return su2.read(path)[1]
    return {}


@dataclass
class SolverMesh:
    """A read solver mesh: meshio's mesh, where it came from, and its 2D cells as faces."""

    path: str
    fmt: str
    mesh: Any  # meshio.Mesh
    options: dict[str, Any]
    face_blocks: list[int]  # indices of the 2D cell blocks, in file order
    offsets: np.ndarray  # (F + 1,) CSR offsets of the faces (the 2D cells, block by block)
    corners: np.ndarray  # (offsets[-1],) node of every face corner

    @property
    def n_points(self) -> int:
        return int(self.mesh.points.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.offsets.size - 1)

    def points3d(self) -> np.ndarray:
        """(N, 3) float64 positions; 2D files get z = 0."""
        p = np.asarray(self.mesh.points, dtype=np.float64)
        if p.shape[1] == 3:
            return p.copy()
        out = np.zeros((p.shape[0], 3), dtype=np.float64)
        out[:, :p.shape[1]] = p
        return out

    def counts(self) -> np.ndarray:
        """(F,) corners of every face."""
        return np.diff(self.offsets)

    def face_block_ranges(self) -> list[tuple[int, int, int]]:
        """(block index, first face, end face) of every 2D block."""
        out, start = [], 0
        for b in self.face_blocks:
            n = len(self.mesh.cells[b].data)
            out.append((b, start, start + n))
            start += n
        return out

    # groups ----------------------------------------------------------------------------

    def group_names(self) -> list[str]:
        """The names groups can be given by (names first, then tags), each once."""
        names = [n for n in self.mesh.cell_sets if not n.startswith("gmsh:")]
        names += [n for n in self.mesh.field_data if n not in names]
        names += [n for n in self.mesh.point_sets if n not in names]
        tags = sorted({int(t) for arr in self._tag_arrays() for t in np.unique(arr)})
        return names + [str(t) for t in tags if str(t) not in names]

    def _tag_arrays(self) -> list[np.ndarray]:
        for name in TAG_ARRAYS:
            if name in self.mesh.cell_data:
                return [np.asarray(a).reshape(len(a), -1)[:, 0]
                        for a in self.mesh.cell_data[name]]
        return []

    def group_cells(self, name: str) -> list[np.ndarray]:
        """Per cell block, the bool mask of the cells in group `name` (a name or a tag)."""
        blocks = self.mesh.cells
        sets = {k: v for k, v in self.mesh.cell_sets.items() if not k.startswith("gmsh:")}
        if name in sets:
            out = []
            for block, idx in zip(blocks, sets[name]):
                mask = np.zeros(len(block.data), dtype=bool)
                if idx is not None and len(idx):
                    mask[np.asarray(idx, dtype=np.int64)] = True
                out.append(mask)
            return out
        tags = self._tag_arrays()
        if name in self.mesh.field_data and tags:
            tag, dim = [*np.asarray(self.mesh.field_data[name]).ravel().tolist(), -1, -1][:2]
            return [(t == tag) & (dim < 0 or cell_dim(b.type) == dim)
                    for b, t in zip(blocks, tags)]
        if re.fullmatch(r"-?\d+", name.strip()) and tags:
            tag = int(name)
            masks = [t == tag for t in tags]
            if any(m.any() for m in masks):
                return masks
        have = ", ".join(self.group_names()[:20]) or "none"
        raise SolverMeshError(f"no group '{name}' in '{self.path}' (its groups: {have})")

    def _point_set(self, name: str) -> np.ndarray | None:
        """(N,) bool of node set `name` (Abaqus ``*NSET``) when `name` is one and no cell
        group, else None."""
        if name not in self.mesh.point_sets or name in self.mesh.cell_sets or \
                name in self.mesh.field_data:
            return None
        out = np.zeros(self.n_points, dtype=bool)
        idx = np.asarray(self.mesh.point_sets[name], dtype=np.int64).ravel()
        out[idx[(idx >= 0) & (idx < self.n_points)]] = True
        return out

    def group_nodes(self, name: str) -> np.ndarray:
        """(N,) bool: the nodes of the cells of group `name`, or of node set `name`."""
        nodes = self._point_set(name)
        if nodes is not None:
            return nodes
        out = np.zeros(self.n_points, dtype=bool)
        for block, mask in zip(self.mesh.cells, self.group_cells(name)):
            if mask.any():
                out[np.asarray(block.data)[mask].ravel()] = True
        return out

    def group_faces(self, name: str) -> np.ndarray:
        """(F,) bool: the faces (2D cells) of group `name` (none for a node set)."""
        if self._point_set(name) is not None:
            return np.zeros(self.n_faces, dtype=bool)
        masks = self.group_cells(name)
        return np.concatenate([masks[b] for b in self.face_blocks])

    def face_groups(self) -> dict[str, np.ndarray]:
        """Every group holding 2D cells -> its (F,) face mask (the report's per-group
        quality)."""
        out = {}
        for name in self.group_names():
            faces = self.group_faces(name)
            if faces.any() and not any(np.array_equal(faces, f) for f in out.values()):
                out[name] = faces
        return out

    # pins ------------------------------------------------------------------------------

    def pin_field(self, name: str) -> np.ndarray:
        """(N,) bool: the nodes where point-data array `name` is non-zero (any component)."""
        data = self.mesh.point_data
        if name not in data:
            have = ", ".join(sorted(data)[:20]) or "none"
            raise SolverMeshError(f"no point data '{name}' in '{self.path}' (its point data: "
                                  f"{have})")
        arr = np.asarray(data[name])
        return (arr.reshape(arr.shape[0], -1) != 0).any(axis=1)

    # nodes that must stay --------------------------------------------------------------

    def periodic_nodes(self) -> np.ndarray:
        """(K, 2) int64: the point indices of every Gmsh ``$Periodic`` pair (node, master);
        (0, 2) when the file has none."""
        links = getattr(self.mesh, "gmsh_periodic", None) or []
        pairs = [np.asarray(sm_, dtype=np.int64).reshape(-1, 2) for *_, sm_ in links]
        return np.concatenate(pairs) if pairs else np.zeros((0, 2), dtype=np.int64)

    def volume_nodes(self) -> np.ndarray:
        """(N,) bool: the nodes of cells of dimension 3 (tetrahedra, hexahedra, ...)."""
        out = np.zeros(self.n_points, dtype=bool)
        for block in self.mesh.cells:
            if cell_dim(block.type) == 3 and len(block.data):
                out[np.asarray(block.data, dtype=np.int64).ravel()] = True
        return out

    # writing ---------------------------------------------------------------------------

    def with_positions(self, positions: np.ndarray, moved: np.ndarray) -> Any:
        """A copy of the meshio mesh whose `moved` nodes take `positions` ((N, 3) or the
        file's own (N, d)); every other array is the same object as in the file."""
        pts = np.array(self.mesh.points, copy=True)
        moved = np.asarray(moved, dtype=bool)
        if moved.any():
            d = pts.shape[1]
            pts[moved] = np.asarray(positions, dtype=pts.dtype)[moved, :d]
        out = copy.copy(self.mesh)
        out.points = pts
        return out


def _gmsh_sections(path: str) -> None:
    """Refuse a Gmsh file with a section meshio does not model (it would be dropped), or a
    Gmsh 2 file whose elements carry more tags than physical and elementary (meshio keeps
    those two: partition tags would be dropped)."""
    with open(path, "rb") as fh:
        text = fh.read()
    for m in re.finditer(rb"(?m)^\$(\w+)\r?$", text):
        name = m.group(1).decode("ascii", "replace")
        if not name.startswith("End") and name not in GMSH_SECTIONS:
            raise SolverMeshError(f"cannot read '{path}' as msh: its ${name} section would "
                                  f"be lost (kept: {', '.join(GMSH_SECTIONS)})")
    most = _gmsh2_most_tags(text)
    if most > 2:
        raise SolverMeshError(
            f"cannot read '{path}' as msh: its elements carry {most} tags (physical, "
            f"elementary and {most - 2} more, e.g. mesh partitions), which would be lost "
            "(meshio keeps physical and elementary: re-export it from Gmsh without "
            "partitions, or as version 4.1)")


def _gmsh2_most_tags(text: bytes) -> int:
    """The largest number of tags an element of a Gmsh 2.x file carries (ASCII or binary);
    0 for other versions or when the file has no $Elements section."""
    fmt = re.search(rb"\$MeshFormat\r?\n\s*(\S+)\s+(\d)\s+(\d+)", text)
    start = text.find(b"$Elements")
    if not fmt or not fmt.group(1).startswith(b"2") or start < 0:
        return 0
    body_at = text.index(b"\n", start) + 1
    count_end = text.index(b"\n", body_at)
    n = int(text[body_at:count_end].split()[0])
    at = count_end + 1
    if fmt.group(2) == b"0":  # ASCII: elm-number elm-type number-of-tags ...
        end = text.find(b"$EndElements", at)
        rows = text[at:end].split(b"\n")
        return max((int(r.split()[2]) for r in rows if len(r.split()) > 2), default=0)
    most, done = 0, 0  # binary: blocks of (type, count, tags) then count * (1 + tags +
    nodes = {1: 2, 2: 3, 3: 4, 4: 4, 5: 8, 6: 6, 7: 5, 8: 3, 9: 6, 10: 9, 11: 10, 12: 27,
             13: 18, 14: 14, 15: 1, 16: 8, 17: 20, 18: 15, 19: 13}  # nodes) int32
    while done < n and at + 12 <= len(text):
        kind, count, tags = np.frombuffer(text, dtype="<i4", count=3, offset=at).tolist()
        if kind not in nodes or count <= 0:
            break  # a type whose node count is not listed here: stop counting
        most = max(most, tags)
        at += 12 + 4 * count * (1 + tags + nodes[kind])
        done += count
    return most


def _read_mesh(path: str, fmt: str) -> tuple[Any, dict[str, Any]]:
    """The meshio mesh of `path` and its writer options; meshio's and the SU2 reader's own
    errors (SystemExit too) as they are."""
    if fmt == "su2":
        return su2.read(path)
    import meshio

    if fmt == "msh":
        _gmsh_sections(path)
    with _quiet():
        mesh = getattr(meshio, SOLVER_FORMATS[fmt][1]).read(path)
    return mesh, write_options(path, fmt)


def _shown(text: str, path: str, shown: str | None) -> str:
    """`text` with `path` replaced by the name the user knows (`shown`)."""
    if not shown or shown == path:
        return text
    return text.replace(path, shown).replace(os.path.basename(path), os.path.basename(shown))


def read(path: str, fmt: str | None = None) -> SolverMesh:
    """Read a solver mesh; SolverMeshError (one line) when it cannot be read or has no 2D
    cells to work on."""
    fmt = fmt or solver_format(path)
    if fmt not in SOLVER_FORMATS:
        raise SolverMeshError(f"'{path}' is not a solver mesh (use "
                              f"{', '.join(e for e, _ in SOLVER_FORMATS.values())})")
    try:
        mesh, options = _read_mesh(path, fmt)
    except SolverMeshError:
        raise
    except OSError as exc:
        raise SolverMeshError(f"cannot read '{path}': "
                              f"{(exc.strerror or str(exc)).lower()}") from None
    except (Exception, SystemExit) as exc:  # meshio exits on some files it cannot parse
        why = _one_line(exc)
        if fmt == "msh" and "Incompatible cell data 'gmsh:physical'" in why:
            why = (f"some of its elements are in physical groups and some are not (Gmsh's "
                   f"'save all elements' with groups), which meshio cannot read; save it "
                   f"with every element in a group, or with no groups ({why})")
        raise SolverMeshError(f"cannot read '{path}' as {fmt}: {why}") from None
    sm = _checked(path, fmt, mesh, options)
    pairs = sm.periodic_nodes()
    if pairs.size and (pairs.min() < 0 or pairs.max() >= sm.n_points):
        raise SolverMeshError(f"cannot read '{path}' as msh: its $Periodic pairs name nodes "
                              "the file does not have (nodes must be numbered 1..N)")
    return sm


def _checked(path: str, fmt: str, mesh: Any, options: dict[str, Any]) -> SolverMesh:
    """The faces of a read mesh, after checking there are 2D cells and sane numbers."""
    pts = np.asarray(mesh.points)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3) or pts.shape[0] == 0:
        raise SolverMeshError(f"'{path}' has no points")
    if not np.isfinite(pts).all():
        bad = int(np.count_nonzero(~np.isfinite(pts).all(axis=1)))
        raise SolverMeshError(f"'{path}': {bad} points have NaN or infinite coordinates")
    face_blocks = [i for i, b in enumerate(mesh.cells) if b.type in FACE_TYPES
                   and len(b.data)]
    if not face_blocks:
        kinds = sorted({b.type for b in mesh.cells if len(b.data)})
        dims = {cell_dim(k) for k in kinds}
        if kinds and dims == {3}:
            why = "volume cells only (" + ", ".join(kinds) + ")"
        elif any(cell_dim(k) == 2 for k in kinds):
            why = "only higher-order 2D cells (" + ", ".join(
                k for k in kinds if cell_dim(k) == 2) + ")"
        else:
            why = "no cells" if not kinds else "no 2D cells (" + ", ".join(kinds) + ")"
        raise SolverMeshError(f"'{path}' has {why}: nothing to untangle (2D cells: "
                              f"{', '.join(FACE_TYPES)})")
    counts, corners = [], []
    for b in face_blocks:
        data = np.asarray(mesh.cells[b].data, dtype=np.int64)
        counts.append(np.full(data.shape[0], data.shape[1], dtype=np.int64))
        corners.append(data.ravel())
    offsets = np.zeros(sum(c.size for c in counts) + 1, dtype=np.int64)
    np.cumsum(np.concatenate(counts), out=offsets[1:])
    flat = np.concatenate(corners)
    if flat.min() < 0 or flat.max() >= pts.shape[0]:
        raise SolverMeshError(f"'{path}': a 2D cell uses a point number out of range")
    return SolverMesh(path, fmt, mesh, options, face_blocks, offsets, flat)


def write(sm: SolverMesh, path: str, positions: np.ndarray | None = None,
          moved: np.ndarray | None = None, shown: str | None = None) -> None:
    """Write `sm` to `path` in the format of its extension: the moved nodes take
    `positions`, everything else is the file's own. Same format as the source: its own
    version and encoding; another format: `convert`ed. SolverMeshError (one line, naming
    `shown` or `path`) when the writer refuses."""
    fmt = solver_format(path)
    if fmt == sm.fmt == "msh" and sm.options.get("fmt_version") == "4.1":  # the file's
        # own bytes, the moved coordinates put in: meshio's 4.1 writer needs physical groups,
        # keeps one per entity and writes some files it cannot read back
        try:
            gmsh41_nodes.write_moved(sm.path, path, positions, moved)
        except gmsh41_nodes.Gmsh41Error as exc:
            raise SolverMeshError(f"cannot write '{shown or path}' as msh: {exc}") from None
        return
    mesh = sm.mesh if positions is None or moved is None else \
        sm.with_positions(positions, moved)
    if fmt is not None and fmt != sm.fmt:
        why = _convert_refusal(sm, fmt)
        if why:
            raise SolverMeshError(f"cannot write '{shown or path}' as {fmt}: {why}")
        mesh = convert(mesh, fmt)
    write_mesh(mesh, path, sm.options if fmt == sm.fmt else None, shown)


def convert(mesh: Any, fmt: str) -> Any:
    """A copy of `mesh` for another format's writer: Gmsh's private arrays (entity tags,
    bounding entities) dropped, cell sets as integer arrays (a Gmsh set's missing blocks
    empty: NumPy 1 made them float Abaqus numbers), the cell tags (the first of
    `TAG_ARRAYS`) under the target's name (``gmsh:physical`` and ``gmsh:geometrical``,
    ``medit:ref``), SU2 left to `su2.write` (it takes any of them). To .msh, a mesh without
    cell tags (Abaqus) has its element sets as named physical groups (`_sets_as_tags`)."""
    out = copy.copy(mesh)
    out.point_data = {k: v for k, v in mesh.point_data.items() if not k.startswith("gmsh:")}
    out.cell_sets = {k: [np.zeros(0, dtype=np.int64) if x is None else
                         np.asarray(x, dtype=np.int64) for x in v]
                     for k, v in mesh.cell_sets.items() if not k.startswith("gmsh:")}
    out.gmsh_periodic = None
    tag = next((k for k in TAG_ARRAYS if k in mesh.cell_data), None)
    data = {k: v for k, v in mesh.cell_data.items() if k != "gmsh:geometrical"}
    if tag is not None:
        tags = [np.asarray(a).reshape(len(a), -1)[:, 0].astype(np.int32)
                for a in mesh.cell_data[tag]]
        target = {"msh": ("gmsh:physical", "gmsh:geometrical"), "mesh": ("medit:ref",)}
        if fmt in target:
            data.pop(tag)
            data.update({k: [t.copy() for t in tags] for k in target[fmt]})
    if tag is None and fmt == "msh" and out.cell_sets:
        tags, names = _sets_as_tags(out)
        data.update({"gmsh:physical": tags, "gmsh:geometrical": [t.copy() for t in tags]})
        out.field_data = {**names, **mesh.field_data}
    out.cell_data = data
    return out


def _sets_as_tags(mesh: Any) -> tuple[list[np.ndarray], dict[str, np.ndarray]]:
    """Element sets (Abaqus ``*ELSET``) as Gmsh physical tags: set k (in order) is tag k,
    named by ``field_data``; cells in no set get 0. `_sets_refusal` has checked first that
    no cell is in two sets and each set has cells of one dimension."""
    tags = [np.zeros(len(b.data), dtype=np.int32) for b in mesh.cells]
    names = {}
    for k, (name, parts) in enumerate(mesh.cell_sets.items(), 1):
        dims = set()
        for b, (block, idx) in enumerate(zip(mesh.cells, parts)):
            if idx is not None and len(idx):
                tags[b][np.asarray(idx, dtype=np.int64)] = k
                dims.add(cell_dim(block.type))
        names[name] = np.array([k, dims.pop() if dims else 2], dtype=np.int64)
    return tags, names


def _sets_refusal(mesh: Any) -> str | None:
    """Why a mesh's sets cannot become Gmsh physical groups (node sets have no place in
    .msh; a Gmsh element has one physical tag; a physical group has one dimension)."""
    if mesh.point_sets:
        some = ", ".join(f"'{n}'" for n in list(mesh.point_sets)[:3])
        return (f"its node sets ({some}{', ...' if len(mesh.point_sets) > 3 else ''}) have "
                "no place in .msh (write .inp, or remove them)")
    owner: list[dict[int, str]] = [{} for _ in mesh.cells]
    for name, parts in mesh.cell_sets.items():
        if name.startswith("gmsh:"):
            continue
        dims = set()
        for b, idx in enumerate(parts):
            for i in ([] if idx is None else np.asarray(idx, dtype=np.int64).tolist()):
                if i in owner[b] and owner[b][i] != name:
                    return (f"its element sets '{owner[b][i]}' and '{name}' share cells: a "
                            "Gmsh element has one physical group")
                owner[b][i] = name
                dims.add(cell_dim(mesh.cells[b].type))
        if len(dims) > 1:
            return (f"its element set '{name}' holds cells of dimensions "
                    f"{', '.join(map(str, sorted(dims)))}: a Gmsh physical group has one")
    return None


@functools.cache
def _abaqus_cannot(cell_type: str, nodes: int) -> bool:
    """Whether meshio's Abaqus writer has no element for `cell_type` (cells of `nodes`
    nodes): one such cell written through meshio's public `write` into a temporary file
    (its writer raises KeyError on a type its table lacks); asked once per type (a
    conversion's dry write and its write both ask)."""
    import meshio

    one = meshio.Mesh(np.zeros((nodes, 3)), [(cell_type, np.arange(nodes)[None, :])])
    with tempfile.TemporaryDirectory(prefix="eegt-inp-") as folder:
        try:
            meshio.write(os.path.join(folder, "probe.inp"), one, file_format="abaqus")
        except KeyError:
            return True
    return False


def _convert_refusal(sm: SolverMesh, fmt: str) -> str | None:
    """Why `sm` cannot go to `fmt` at all (before any writing), or None."""
    if sm.periodic_nodes().size and fmt != "msh":
        return f"its Gmsh $Periodic pairs have no place in .{fmt}"
    if fmt == "su2":
        return su2.plan(sm.mesh)[1]
    if fmt == "inp":
        kinds = {b.type: b.data.shape[1] for b in sm.mesh.cells if len(b.data)}
        odd = sorted(t for t, k in kinds.items() if _abaqus_cannot(t, k))
        if odd:
            return f"Abaqus (meshio's writer) has no element type for {', '.join(odd)} cells"
    if fmt == "msh" and not any(k in sm.mesh.cell_data for k in TAG_ARRAYS):
        return _sets_refusal(sm.mesh)
    return None


def _gmsh_ascii_safe(mesh: Any) -> Any:
    """A copy whose data arrays (not tags) hold Python numbers: meshio 5.3 writes Gmsh ASCII
    data with ``{!r}``, which under NumPy 2 gives ``np.float64(1.0)`` and a file that
    does not read back."""
    def plain(a: Any) -> np.ndarray:
        a = np.asarray(a)
        out = np.empty(a.shape, dtype=object)
        out[...] = a.tolist() if a.ndim else a.item()
        return out

    out = copy.copy(mesh)
    out.point_data = {k: (v if k.startswith("gmsh:") else plain(v))
                      for k, v in mesh.point_data.items()}
    out.cell_data = {k: (v if k in _GMSH_TAGS else [plain(a) for a in v])
                     for k, v in mesh.cell_data.items()}
    return out


def write_mesh(mesh: Any, path: str, options: dict[str, Any] | None = None,
               shown: str | None = None) -> None:
    """Write a meshio mesh to `path` in the format of its extension with these writer
    options (default: `write_options_default`). SolverMeshError (one line, meshio's reason,
    naming `shown` or `path`) when the writer refuses it or exits; OSError as it is."""
    import meshio

    fmt = solver_format(path)
    where = shown or path
    if fmt is None:
        raise SolverMeshError(f"'{where}' is not a solver mesh path")
    opts = write_options_default(fmt) if options is None else options
    try:
        if fmt == "su2":
            su2.write(path, mesh, opts)
            return
        if fmt == "msh" and not opts.get("binary", False):
            mesh = _gmsh_ascii_safe(mesh)
        with _quiet():
            getattr(meshio, SOLVER_FORMATS[fmt][1]).write(path, mesh, **opts)
    except OSError:
        raise
    except (Exception, SystemExit) as exc:  # meshio exits on some meshes it cannot write
        why = _shown(_one_line(exc), path, shown)
        raise SolverMeshError(f"cannot write '{where}' as {fmt}: {why}") from None


def write_options_default(fmt: str) -> dict[str, Any]:
    """Writer options for a format other than the source's: full precision text where
    the writer takes a number format; Gmsh 2.2 ASCII (meshio's 4.1 writer needs Gmsh's
    entity arrays, which only a Gmsh source has); SU2 with point and element indices."""
    if fmt == "msh":
        return {"fmt_version": "2.2", "binary": False, "float_fmt": ".16e"}
    return {"float_fmt": ".16e"} if fmt in ("inp", "mesh") else {}


def check_written(sm: SolverMesh, path: str, shown: str | None = None) -> str | None:
    """Why the freshly written `path` is not whole (read back: the same number of points
    and cells per type as `sm`), or None."""
    fmt = solver_format(path)
    try:
        back, _ = _read_mesh(path, fmt)
    except (Exception, SystemExit) as exc:
        return f"the written file does not read back: {_shown(_one_line(exc), path, shown)}"
    if back.points.shape[0] != sm.n_points:
        return f"the written file has {back.points.shape[0]} of {sm.n_points} points"
    want = sorted((b.type, len(b.data)) for b in sm.mesh.cells)
    have = sorted((b.type, len(b.data)) for b in back.cells)
    if _totals(want) != _totals(have):
        return "the written file does not hold every cell"
    if fmt == sm.fmt:
        try:
            return groups_changed(sm, _checked(path, fmt, back, sm.options))
        except SolverMeshError as exc:
            return f"the written file does not read back: {_shown(str(exc), path, shown)}"
    return None


def groups_changed(sm: SolverMesh, back: SolverMesh) -> str | None:
    """Why `back` (the same format written back) does not hold `sm`'s groups, each by its
    name or tag, with the same nodes (a writer that keeps one Gmsh physical group per
    entity drops the others), or None. Another format's groups are `convert`'s rules."""
    if back.fmt != sm.fmt:
        return None
    have = set(back.group_names())
    for name in sm.group_names():
        want = sm.group_nodes(name)
        got = back.group_nodes(name) if name in have else np.zeros_like(want)
        if not np.array_equal(want, got):
            return (f"its group '{name}' would change ({int(np.count_nonzero(want))} -> "
                    f"{int(np.count_nonzero(got))} nodes; meshio's writer keeps one "
                    "physical group per Gmsh entity)" if sm.fmt == "msh" else
                    f"its group '{name}' would change ({int(np.count_nonzero(want))} -> "
                    f"{int(np.count_nonzero(got))} nodes)")
    return None


def can_write(sm: SolverMesh, fmt: str, path: str | None = None) -> str | None:
    """None when `sm` can be written as `fmt` (a --format name) and read back whole, else
    the one-line reason, naming `path` (else 'a .FMT file'). Explicit rules first
    (periodic pairs outside Gmsh, what SU2 cannot hold), then a dry write of the mesh into
    a temporary folder and its read-back: costs one write and one read of the mesh."""
    if fmt not in SOLVER_FORMATS:
        return f"'{fmt}' is not a solver format ({', '.join(SOLVER_FORMATS)})"
    ext = SOLVER_FORMATS[fmt][0]
    where = path or f"a {ext} file"
    if fmt != sm.fmt:
        why = _convert_refusal(sm, fmt)
        if why:
            return f"cannot write '{where}' as {fmt}: {why}"
    with tempfile.TemporaryDirectory(prefix="eegt-can-write-") as folder:
        tmp = os.path.join(folder, "dry" + ext)
        try:
            write(sm, tmp, shown=where)
        except SolverMeshError as exc:
            return _shown(str(exc), tmp, where)
        except OSError as exc:
            return f"cannot write '{where}': {(exc.strerror or str(exc)).lower()}"
        why = check_written(sm, tmp, shown=where)
    return f"cannot write '{where}' as {fmt}: {why}" if why else None


def _totals(blocks: list[tuple[str, int]]) -> dict[str, int]:
    out: dict[str, int] = {}
    for t, n in blocks:
        out[t] = out.get(t, 0) + n
    return out


@dataclass(frozen=True)
class NodeChoice:
    """Which nodes the file's flags pin and the boundary mode the run takes."""

    pinned: np.ndarray  # (N,) bool
    boundary: str
    notes: tuple[str, ...] = ()


def node_choice(sm: SolverMesh, boundary: str, on_boundary: np.ndarray,
                pin_field: str | None = None, fixed_groups: tuple[str, ...] = (),
                slide_groups: tuple[str, ...] = ()) -> NodeChoice:
    """Pins from a point-data array and groups: the pin field's non-zero nodes and the
    fixed groups' nodes stay; the slide groups' boundary nodes slide along the boundary
    (run in mode ``slide`` with every other boundary node pinned, unless `boundary` is
    already ``slide``); the rest of the boundary follows `boundary`. A node in a fixed and
    a slide group stays. Always held, with a note: the nodes of Gmsh ``$Periodic`` pairs
    and the nodes of volume cells. `on_boundary`: (N,) bool, the faces' boundary nodes
    (``core.boundary_nodes``)."""
    pinned = np.zeros(sm.n_points, dtype=bool)
    notes = []
    pairs = sm.periodic_nodes()
    if pairs.size:
        pinned[pairs.ravel()] = True
        notes.append(f"{int(np.count_nonzero(pinned))} nodes of Gmsh $Periodic pairs held "
                     "(moving one end of a pair and not the other breaks the pair)")
    volume = sm.volume_nodes()
    if volume.any():
        pinned |= volume
        notes.append(f"{int(np.count_nonzero(volume))} nodes shared with volume cells held "
                     "(the 2D run does not see those cells and could invert them)")
    if pin_field:
        pinned |= sm.pin_field(pin_field)
        notes.append(f"{int(np.count_nonzero(pinned))} nodes pinned by '{pin_field}'")
    for name in fixed_groups:
        pinned |= sm.group_nodes(name)
    mode = boundary
    if slide_groups:
        if boundary == "free":
            raise SolverMeshError("--slide-groups needs --boundary fixed or slide (with free "
                                  "every boundary node already moves)")
        sliding = np.zeros(sm.n_points, dtype=bool)
        for name in slide_groups:
            sliding |= sm.group_nodes(name)
        if boundary == "fixed":
            pinned |= np.asarray(on_boundary, dtype=bool) & ~sliding
            mode = "slide"
            notes.append("boundary outside the slide groups kept fixed")
    return NodeChoice(pinned, mode, tuple(notes))


def volume_cells_inverted(sm: SolverMesh, positions: np.ndarray) -> int:
    """How many tetrahedra of `sm` have a signed volume at `positions` ((N, 3) or the
    file's (N, d)) that is zero or of the other sign than in the file: a result that
    inverts one must not be written. Other volume cells are held by `node_choice`."""
    before = sm.points3d()
    after = np.zeros_like(before)
    pos = np.asarray(positions, dtype=np.float64)
    after[:, :pos.shape[1]] = pos[:, :3]
    bad = 0
    for block in sm.mesh.cells:
        if block.type != "tetra" or not len(block.data):
            continue
        t = np.asarray(block.data, dtype=np.int64)
        v0, v1 = (_tet_volumes(p, t) for p in (before, after))
        bad += int(np.count_nonzero((v0 != 0) & (np.sign(v1) != np.sign(v0))))
    return bad


def _tet_volumes(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    a, b, c, d = (p[t[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def parse_groups(text: str | None) -> tuple[str, ...]:
    """A comma list of group names or tags."""
    return tuple(w.strip() for w in (text or "").split(",") if w.strip())
