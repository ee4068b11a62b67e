"""UV maps as planar meshes: weld face corners into UV vertices, find islands and their sides.

A UV map stores one 2D point per face corner (Blender's loop). Corners of one mesh vertex
whose UVs are within ``UV_CONNECT_LIMIT`` of each other (per axis, as Blender's own island
tools join them) are one UV vertex; the faces over those UV vertices form the UV mesh,
whose connected components are the islands. Seams and mesh borders are that mesh's
boundary. An island is either counterclockwise (its faces keep the 3D faces' orientation)
or mirrored (clockwise, as mirrored UVs of symmetric models are): its total signed area
tells which, and folds cannot change it. Everything here is NumPy; no Blender.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mesh.faces import FaceSet, face_subset, faces_from_csr, next_corner
from ..metrics.face_quality import signed_face_areas

# Blender's STD_UV_CONNECT_LIMIT: two corners of one vertex whose UVs differ by less than
# this in u and in v are one UV vertex for its island tools (Select Linked, UV islands).
UV_CONNECT_LIMIT = 1e-4

__all__ = [
    "UV_CONNECT_LIMIT",
    "UVLayout",
    "components",
    "corner_loops",
    "island_faces",
    "weld_uv",
]


def components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n,) component label (0..k-1, numbered by smallest member) of a graph with edges
    a[i] - b[i]: union-find by hooking roots to the smaller root, then pointer jumping,
    a few vectorized rounds (about log of the longest chain)."""
    parent = np.arange(n, dtype=np.int64)
    a = np.asarray(a, dtype=np.int64)
    b = np.asarray(b, dtype=np.int64)
    while True:
        ra, rb = parent[a], parent[b]
        differ = ra != rb
        if not differ.any():
            break
        lo, hi = np.minimum(ra[differ], rb[differ]), np.maximum(ra[differ], rb[differ])
        np.minimum.at(parent, hi, lo)  # a root hooks onto the smallest root it touches
        while True:  # compress: every node points at its root again
            jumped = parent[parent]
            if np.array_equal(jumped, parent):
                break
            parent = jumped
        a, b = a[differ], b[differ]  # edges inside one component stay inside it
    return np.unique(parent, return_inverse=True)[1].astype(np.int64)


def corner_loops(loop_start: np.ndarray, loop_total: np.ndarray) -> np.ndarray:
    """Loop index of every face corner in face order (a FaceSet's ``indices`` order), for
    Blender's face offsets whatever their order."""
    loop_start = np.asarray(loop_start, dtype=np.int64)
    loop_total = np.asarray(loop_total, dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(loop_total)])
    return np.repeat(loop_start - offsets[:-1], loop_total) + np.arange(int(offsets[-1]))


@dataclass(frozen=True)
class UVLayout:
    """A UV map welded into a polygon mesh over UV vertices (face order = Blender's)."""

    points: np.ndarray  # (V, 2) float64: the UV of each UV vertex (exact float32 values)
    vertex: np.ndarray  # (V,) mesh vertex of each UV vertex
    loop_node: np.ndarray  # (L,) UV vertex of each loop (Blender loop order)
    corner_loop: np.ndarray  # (C,) loop of each face corner, face order
    faces: FaceSet  # every face over UV vertices
    island: np.ndarray  # (F,) island of each face, 0..n_islands-1
    node_island: np.ndarray  # (V,) island of each UV vertex
    area: np.ndarray  # (n_islands,) signed UV area of each island

    @property
    def n_islands(self) -> int:
        return int(self.area.size)

    @property
    def n_nodes(self) -> int:
        return int(self.points.shape[0])

    def orientation(self, rel_tol: float = 1e-9) -> np.ndarray:
        """(n_islands,) +1 counterclockwise, -1 mirrored (clockwise), 0 no usable area: the
        island's |area| is at most ``rel_tol`` times its bounding box's area (collapsed to a
        point or a line, so its side cannot be told)."""
        lo = np.full((self.n_islands, 2), np.inf)
        hi = np.full((self.n_islands, 2), -np.inf)
        np.minimum.at(lo, self.node_island, self.points)
        np.maximum.at(hi, self.node_island, self.points)
        box = np.prod(hi - lo, axis=1)
        side = np.sign(self.area).astype(np.int8)
        side[~(np.abs(self.area) > rel_tol * box)] = 0
        return side

    def oriented_points(self, side: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """UV vertex positions (``points``, default the map's own) with every mirrored island
        reflected (u -> -u, exact), so that each island with area is counterclockwise."""
        p = np.array(self.points if points is None else points, dtype=np.float64)
        p[side[self.node_island] < 0, 0] *= -1.0
        return p


def _near_pairs(vert: np.ndarray, uv: np.ndarray, limit: np.float32) -> tuple[np.ndarray,
                                                                              np.ndarray]:
    """Pairs (a, b) of rows of one vertex whose float32 UVs differ by less than ``limit`` in
    u and in v (Blender's test, in float32). Rows sorted by (vertex, u): each row is compared
    with the next, the one after, ... while u stays within the limit (a few passes: one per
    row of the longest run of one vertex's UVs within the limit in u)."""
    n = vert.size
    order = np.lexsort((uv[:, 0], vert))
    vs, us, ws = vert[order], uv[order, 0], uv[order, 1]
    row = np.arange(n - 1)
    a, b = [], []
    d = 1
    while row.size:
        row = row[row + d < n]
        nxt = row + d
        close = (vs[nxt] == vs[row]) & (us[nxt] - us[row] < limit)
        row, nxt = row[close], nxt[close]  # u sorted: a row that fails stays failed
        hit = np.abs(ws[nxt] - ws[row]) < limit
        a.append(order[row[hit]])
        b.append(order[nxt[hit]])
        d += 1
    empty = np.zeros(0, dtype=np.int64)
    return (np.concatenate(a) if a else empty), (np.concatenate(b) if b else empty)


def weld_uv(loop_start, loop_total, corner_verts, uv,
            limit: float = UV_CONNECT_LIMIT) -> UVLayout:
    """Weld a UV map: loops of one mesh vertex whose float32 UVs differ by less than
    ``limit`` in u and in v (chained: a ~ b and b ~ c weld all three) become one UV vertex,
    as Blender's island tools see them; ``limit`` 0 welds equal values only (-0 = +0). A UV
    vertex sits at the value most of its loops hold (ties: the first by vertex, then float32
    bits); the result does not depend on the order of faces or loops. ValueError (one line)
    for NaN/infinite UVs or mismatched arrays."""
    loop_start = np.asarray(loop_start, dtype=np.int64)
    loop_total = np.asarray(loop_total, dtype=np.int64)
    corner_verts = np.asarray(corner_verts, dtype=np.int64)
    uv = np.asarray(uv, dtype=np.float32).reshape(-1, 2)
    if uv.shape[0] != corner_verts.size:
        raise ValueError(f"the UV map has {uv.shape[0]} values for {corner_verts.size} face "
                         "corners")
    if loop_start.size == 0:
        raise ValueError("mesh has no faces")
    corner_loop = corner_loops(loop_start, loop_total)
    used = np.zeros(corner_verts.size, dtype=bool)
    used[corner_loop] = True
    finite = np.isfinite(uv).all(axis=1)
    if not finite[used].all():
        bad = int(np.count_nonzero(used & ~finite))
        raise ValueError(f"{bad} UVs are NaN or infinite")
    clean = uv + np.float32(0.0)  # -0.0 + 0.0 = +0.0: equal values, equal bits
    bits = clean.view(np.uint32).astype(np.int64)
    order = np.lexsort((bits[:, 1], bits[:, 0], corner_verts))
    keys = np.stack([corner_verts[order], bits[order, 0], bits[order, 1]], axis=1)
    new = np.ones(order.size, dtype=bool)
    new[1:] = np.any(keys[1:] != keys[:-1], axis=1)
    loop_exact = np.empty(order.size, dtype=np.int64)
    loop_exact[order] = np.cumsum(new) - 1
    first = order[new]  # one loop per distinct (vertex, value), in (vertex, bits) order
    a, b = _near_pairs(corner_verts[first], clean[first], np.float32(limit)) \
        if limit > 0 else (np.zeros(0, np.int64), np.zeros(0, np.int64))
    if a.size:  # near values of one vertex: one UV vertex at its most used value
        group = components(first.size, a, b)
        count = np.bincount(loop_exact, minlength=first.size)
        pick = np.lexsort((np.arange(first.size), -count, group))
        lead = np.ones(pick.size, dtype=bool)
        lead[1:] = group[pick[1:]] != group[pick[:-1]]
        first = first[pick[lead]]
        loop_node = group[loop_exact]
    else:
        loop_node = loop_exact
    points = clean[first].astype(np.float64)
    faces = faces_from_csr(loop_start, loop_total, loop_node)
    n = points.shape[0]
    node_island = components(n, faces.indices, faces.indices[next_corner(faces)])
    island = node_island[faces.indices[faces.offsets[:-1]]]
    n_islands = int(node_island.max()) + 1 if n else 0
    area = np.bincount(island, weights=signed_face_areas(points, faces), minlength=n_islands)
    return UVLayout(points, corner_verts[first], loop_node, corner_loop, faces, island,
                    node_island, area)


island_faces = face_subset  # an island's (or any set of faces') own FaceSet: core.mesh.faces
