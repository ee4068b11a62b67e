"""Helpers of the UV tests: assets (bench.uv_assets), UV reads, selections made by Blender."""

from __future__ import annotations

import numpy as np

from bench import uv_assets


def uv_values(obj, name: str | None = None) -> np.ndarray:
    """(L, 2) float32 copy of a UV map (default: the active one)."""
    me = obj.data
    layer = me.uv_layers[name] if name else me.uv_layers.active
    buf = np.empty(len(me.loops) * 2, np.float32)
    me.attributes[layer.name].data.foreach_get("vector", buf)
    return buf.reshape(-1, 2)


def face_signed_areas(uv: np.ndarray, face: np.ndarray) -> np.ndarray:
    """Each face's signed UV area (twice it: the shoelace sum), from ``uv`` (L, 2) and
    ``face`` (L,) the face of every loop (``loop_faces``: a face's loops are consecutive, in
    its order). Counted here, loop by loop, independently of the extension."""
    uv = np.asarray(uv, dtype=np.float64)
    nxt = np.arange(1, face.size + 1)
    last = np.flatnonzero(np.append(face[1:] != face[:-1], True))
    nxt[last] = np.append(0, last[:-1] + 1)
    return np.bincount(face, uv[:, 0] * uv[nxt, 1] - uv[nxt, 0] * uv[:, 1])


def corner_verts(obj) -> np.ndarray:
    me = obj.data
    cv = np.empty(len(me.loops), np.int64)
    me.loops.foreach_get("vertex_index", cv)
    return cv


def loop_faces(obj) -> np.ndarray:
    """Face of every loop."""
    me = obj.data
    ls = np.empty(len(me.polygons), np.int64)
    lt = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("loop_start", ls)
    me.polygons.foreach_get("loop_total", lt)
    out = np.empty(len(me.loops), np.int64)
    out[np.repeat(ls, lt) + np.arange(lt.sum()) - np.repeat(np.cumsum(lt) - lt, lt)] = \
        np.repeat(np.arange(len(ls)), lt)
    return out


STD_UV_CONNECT_LIMIT = np.float32(1e-4)  # Blender's own, in its island tools


def loop_steps(obj) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(face, next loop, previous loop) of every loop (a face's loops are contiguous)."""
    me = obj.data
    ls = np.empty(len(me.polygons), np.int64)
    lt = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("loop_start", ls)
    me.polygons.foreach_get("loop_total", lt)
    lf = loop_faces(obj)
    k = np.arange(lf.size) - ls[lf]
    return lf, ls[lf] + (k + 1) % lt[lf], ls[lf] + (k - 1) % lt[lf]


def uv_vertex_groups(obj, uv: np.ndarray) -> np.ndarray:
    """(L,) UV vertex of every loop, computed here from scratch as Blender's UV vertex map
    does (``BKE_mesh_uv_vert_map_create``): per mesh vertex, each loop joins the first group
    whose first loop's UV is within STD_UV_CONNECT_LIMIT in u and in v (float32)."""
    cv = corner_verts(obj)
    uv = np.asarray(uv, np.float32)
    out = np.empty(cv.size, np.int64)
    n = 0
    order = np.argsort(cv, kind="stable")
    for part in np.split(order, np.flatnonzero(np.diff(cv[order])) + 1):
        heads = []  # (first UV, group) of this vertex; a few loops each: a loop is fine here
        for loop in part.tolist():
            for head, g in heads:
                if (np.abs(uv[loop] - head) < STD_UV_CONNECT_LIMIT).all():
                    out[loop] = g
                    break
            else:
                heads.append((uv[loop], n))
                out[loop] = n
                n += 1
    return out


def uv_border_loops(obj, groups: np.ndarray) -> np.ndarray:
    """(L,) bool: loops of UV vertices on a UV border (an edge of UV vertices used by one
    face: seams and mesh borders), from ``uv_vertex_groups``."""
    _, nxt, _ = loop_steps(obj)
    a, b = groups, groups[nxt]
    edges = np.sort(np.stack([a, b], 1), axis=1)
    _, inv, cnt = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    lone = cnt[inv.reshape(-1)] == 1
    on = np.zeros(int(groups.max()) + 1, bool)
    on[a[lone]] = True
    on[b[lone]] = True
    return on[groups]


def inverted_uv_faces(obj, uv: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """(F,) bool: faces with a corner turned the wrong way (cross product <= 0) against
    their island's orientation (islands and their total signed area from ``groups``):
    computed here, not by the extension."""
    lf, nxt, prv = loop_steps(obj)
    nf = len(obj.data.polygons)
    p = uv.astype(np.float64)
    area = np.bincount(lf, 0.5 * (p[:, 0] * p[nxt, 1] - p[nxt, 0] * p[:, 1]), nf)
    parent = np.arange(int(groups.max()) + 1)  # islands: union-find over face edges

    def root(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x
    for a, b in zip(groups.tolist(), groups[nxt].tolist()):
        ra, rb = root(a), root(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    first = np.full(nf, -1)
    first[lf[::-1]] = np.arange(lf.size)[::-1]  # a loop of each face
    island = np.array([root(g) for g in groups[first].tolist()])
    side = {i: np.sign(area[island == i].sum()) for i in set(island.tolist())}
    s = np.array([side[i] for i in island])
    d1, d2 = p[nxt] - p, p[prv] - p
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    bad = np.zeros(nf, bool)
    np.logical_or.at(bad, lf, cross * s[lf] <= 0)
    return bad | (area * s <= 0)


PRIMITIVES = {  # Blender's primitives with a UV map, as the Add menu makes them
    "grid": ("primitive_grid_add", {"x_subdivisions": 10, "y_subdivisions": 10, "size": 2}),
    "plane": ("primitive_plane_add", {}),
    "cube": ("primitive_cube_add", {}),
    "cylinder": ("primitive_cylinder_add", {}),
    "sphere": ("primitive_uv_sphere_add", {}),
    "ico_sphere": ("primitive_ico_sphere_add", {}),
    "torus": ("primitive_torus_add", {}),
    "monkey": ("primitive_monkey_add", {}),
}


def primitive(bpy, kind: str):
    """A Blender primitive (``PRIMITIVES``), Object Mode, selected and active."""
    op, kw = PRIMITIVES[kind]
    getattr(bpy.ops.mesh, op)(**kw)
    obj = bpy.context.active_object
    assert obj.data.uv_layers.active is not None, kind
    return obj


def jitter_uv_vertices(obj, uv: np.ndarray, groups: np.ndarray, free: np.ndarray,
                       amount: float, seed: int) -> np.ndarray:
    """UVs with each UV vertex of ``free`` (bool per group) moved by up to ``amount`` times
    its shortest UV edge: every loop of it by the same float32 offset, so loops a float32
    step apart stay apart (float32 (L, 2))."""
    _, nxt, _ = loop_steps(obj)
    length = np.linalg.norm(uv[nxt].astype(np.float64) - uv, axis=1)
    short = np.full(int(groups.max()) + 1, np.inf)
    np.minimum.at(short, groups, length)
    np.minimum.at(short, groups[nxt], length)
    rng = np.random.default_rng(seed)
    h = amount * np.where(free, short, 0.0)
    delta = (rng.uniform(-1.0, 1.0, (h.size, 2)) * h[:, None]).astype(np.float32)
    return (uv + delta[groups]).astype(np.float32)


def one_ulp_apart(uv: np.ndarray, groups: np.ndarray, seed: int) -> np.ndarray:
    """UVs with one loop of every UV vertex used by several loops one float32 step higher
    in u, as Blender 4.2-4.5's Grid primitive stores some of its UVs (float32 (L, 2))."""
    rng = np.random.default_rng(seed)
    order = np.lexsort((rng.random(groups.size), groups))
    head = np.ones(order.size, bool)
    head[1:] = groups[order[1:]] != groups[order[:-1]]
    many = np.bincount(groups)[groups[order]] > 1
    out = uv.copy()
    bump = order[head & many]
    out[bump, 0] = np.nextafter(out[bump, 0], np.float32(np.inf))
    return out


def tangled(bpy, kind: str = "sphere", tangle: str = "jitter", **kw):
    """An unwrapped asset with a tangled active UV map, Object Mode, selected and active."""
    obj = uv_assets.make_asset(bpy, kind, **kw)
    uv_assets.tangle(bpy, obj, tangle)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return obj


def set_mesh_selection(obj, faces: np.ndarray) -> None:
    """Select exactly ``faces`` (and their vertices and edges) in the mesh (Object Mode)."""
    me = obj.data
    cv = corner_verts(obj)
    vsel = np.zeros(len(me.vertices), bool)
    vsel[cv[faces[loop_faces(obj)]]] = True
    ev = np.empty(2 * len(me.edges), np.int64)
    me.edges.foreach_get("vertices", ev)
    me.polygons.foreach_set("select", faces)
    me.vertices.foreach_set("select", vsel)
    me.edges.foreach_set("select", vsel[ev.reshape(-1, 2)].all(axis=1))


def uv_select_by_blender(bpy, obj, faces: np.ndarray) -> None:
    """In Edit Mode, UV Sync Selection off: select the UVs of ``faces`` with Blender's own
    operators (pin exactly their loops, Select Pinned, restore the pins)."""
    me = obj.data
    bpy.ops.object.mode_set(mode="OBJECT")
    layer = me.uv_layers.active  # looked up in Object Mode: a mode switch reallocates it
    if hasattr(layer, "pin_ensure"):
        layer.pin_ensure()
    old = np.zeros(len(me.loops), bool)
    layer.pin.foreach_get("value", old)
    layer.pin.foreach_set("value", faces[loop_faces(obj)])
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.uv.select_all(action="DESELECT")
    assert bpy.ops.uv.select_pinned() == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    layer = me.uv_layers.active
    if hasattr(layer, "pin_ensure"):
        layer.pin_ensure()
    layer.pin.foreach_set("value", old)
    bpy.ops.object.mode_set(mode="EDIT")
