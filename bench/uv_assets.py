"""Tangled UV test assets made by script in Blender (bpy module or a real Blender).

Meshes: a UV sphere cut along one meridian, a subdivided monkey cut in two halves (one
half's UVs mirrored, as mirrored UVs of symmetric models are), and an organic height-field
surface; each unwrapped with ``bpy.ops.uv.unwrap``. Tangles, all deterministic (seeded):
(a) ``jitter``: interior UV vertices moved at random by a fraction of the mean UV edge;
(b) ``rotate``: the UVs of an inner disc of an island turned by 90-180 degrees (the ring
around it folds: no local relax undoes that); (c) ``mesh_edit``: 3D vertices moved with
Correct Face Attributes on (their UVs follow and flip), then moved back with it off, as an
artist who fixes the mesh but not the UVs does. ``pin_some`` pins a few interior UVs away
from the tangle.
Every UV vertex moves as one (all its loops together), island borders never move.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from core import boundary_nodes
from core.uv.uv_layout import UVLayout, weld_uv

__all__ = ["ASSETS", "TANGLES", "make_asset", "pin_some", "read_uv", "tangle", "write_uv"]


def read_uv(obj: Any) -> np.ndarray:
    """(L, 2) float32 values of the active UV map."""
    me = obj.data
    buf = np.empty(len(me.loops) * 2, np.float32)
    me.attributes[me.uv_layers.active.name].data.foreach_get("vector", buf)
    return buf.reshape(-1, 2)


def write_uv(obj: Any, uv: np.ndarray) -> None:
    """Set the active UV map from (L, 2)."""
    me = obj.data
    me.attributes[me.uv_layers.active.name].data.foreach_set(
        "vector", np.ascontiguousarray(uv, np.float32).ravel())
    me.update()


def mesh_csr(obj: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(loop_start, loop_total, corner_verts) of ``obj``'s mesh, read with foreach_get."""
    me = obj.data
    ls = np.empty(len(me.polygons), np.int64)
    lt = np.empty(len(me.polygons), np.int64)
    cv = np.empty(len(me.loops), np.int64)
    me.polygons.foreach_get("loop_start", ls)
    me.polygons.foreach_get("loop_total", lt)
    me.loops.foreach_get("vertex_index", cv)
    return ls, lt, cv


def layout(obj: Any, uv: np.ndarray | None = None) -> UVLayout:
    """The welded UV map of ``obj`` (Object Mode)."""
    return weld_uv(*mesh_csr(obj), read_uv(obj) if uv is None else uv)


def _positions(me: Any) -> np.ndarray:
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    return co.reshape(-1, 3)


def _unwrap(bpy: Any, obj: Any, seams: np.ndarray | None) -> None:
    """Mark ``seams`` (bool per edge), select everything and unwrap (angle based)."""
    me = obj.data
    if seams is not None:
        me.edges.foreach_set("use_seam", seams)
    for coll in (me.vertices, me.edges, me.polygons):
        coll.foreach_set("select", np.ones(len(coll), bool))
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.uv.unwrap(method="ANGLE_BASED", margin=0.02)
    bpy.ops.object.mode_set(mode="OBJECT")


def _edge_verts(me: Any) -> np.ndarray:
    ev = np.empty(len(me.edges) * 2, np.int64)
    me.edges.foreach_get("vertices", ev)
    return ev.reshape(-1, 2)


def _add(bpy: Any, op: str, name: str, **kw: Any) -> Any:
    if bpy.context.mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.object.select_all(action="DESELECT")
    getattr(bpy.ops.mesh, op)(**kw)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    return obj


def make_sphere(bpy: Any, name: str = "Sphere", segments: int = 32, rings: int = 16) -> Any:
    """A UV sphere cut from pole to pole along the meridian y = 0, x > 0: one island."""
    obj = _add(bpy, "primitive_uv_sphere_add", name, segments=segments, ring_count=rings)
    me = obj.data
    co = _positions(me)
    on = (np.abs(co[:, 1]) < 1e-6) & (co[:, 0] >= -1e-6)
    _unwrap(bpy, obj, on[_edge_verts(me)].all(axis=1))
    return obj


def make_monkey(bpy: Any, name: str = "Monkey", levels: int = 2) -> Any:
    """A monkey subdivided ``levels`` times, cut along x = 0; the x > 0 half's UVs are then
    mirrored in place (a clockwise island), its eyes are islands of their own."""
    obj = _add(bpy, "primitive_monkey_add", name)
    mod = obj.modifiers.new("Subdivision", "SUBSURF")
    mod.levels = levels
    bpy.ops.object.modifier_apply(modifier=mod.name)
    me = obj.data
    co = _positions(me)
    mid = np.abs(co[:, 0]) < 1e-5
    _unwrap(bpy, obj, mid[_edge_verts(me)].all(axis=1))
    lay = layout(obj)
    cv = lay.vertex[lay.loop_node]
    right_face = np.zeros(lay.faces.n_faces, bool)
    np.logical_or.at(right_face, np.repeat(np.arange(lay.faces.n_faces), lay.faces.counts),
                     co[lay.vertex[lay.faces.indices], 0] > 1e-5)
    isl = np.unique(lay.island[right_face])
    big = isl[np.argmax(np.bincount(lay.island, minlength=lay.n_islands)[isl])]
    nodes = lay.node_island == big
    uv = read_uv(obj).copy()
    loops = nodes[lay.loop_node]
    c = 0.5 * (uv[loops, 0].min() + uv[loops, 0].max())
    uv[loops, 0] = 2 * c - uv[loops, 0]
    del cv
    write_uv(obj, uv)
    return obj


def make_organic(bpy: Any, name: str = "Organic", n: int = 48) -> Any:
    """A bumpy height-field grid (an open surface): one island."""
    obj = _add(bpy, "primitive_grid_add", name, x_subdivisions=n, y_subdivisions=n, size=2)
    me = obj.data
    co = _positions(me).astype(np.float64)
    x, y = co[:, 0], co[:, 1]
    co[:, 2] = 0.35 * np.sin(2.5 * x) * np.cos(2.0 * y) + 0.25 * np.exp(-4 * (x * x + y * y))
    me.attributes["position"].data.foreach_set("vector", co.astype(np.float32).ravel())
    me.update()
    _unwrap(bpy, obj, None)
    return obj


ASSETS = {"sphere": make_sphere, "monkey": make_monkey, "organic": make_organic}


def make_asset(bpy: Any, kind: str, **kw: Any) -> Any:
    """One of ``ASSETS`` in the current scene, unwrapped, in Object Mode, selected."""
    return ASSETS[kind](bpy, **kw)


def _interior(lay: UVLayout) -> np.ndarray:
    """(V,) UV vertices off every island border."""
    return ~boundary_nodes(lay.n_nodes, lay.faces)


def _mean_edge(lay: UVLayout) -> float:
    p = lay.points[lay.faces.indices]
    nxt = np.arange(1, lay.faces.n_corners + 1)
    nxt[lay.faces.offsets[1:] - 1] = lay.faces.offsets[:-1]
    return float(np.linalg.norm(lay.points[lay.faces.indices[nxt]] - p, axis=1).mean())


def _set_nodes(obj: Any, lay: UVLayout, points: np.ndarray) -> None:
    """Write UV vertex positions (every loop of a UV vertex gets the same value)."""
    write_uv(obj, points[lay.loop_node].astype(np.float32))


def jitter(obj: Any, amount: float = 0.5, seed: int = 0) -> None:
    """(a) Interior UV vertices moved by up to ``amount`` mean UV edge lengths."""
    lay = layout(obj)
    free = _interior(lay)
    rng = np.random.default_rng(seed)
    h = amount * _mean_edge(lay)
    p = lay.points.copy()
    p[free] += rng.uniform(-h, h, (int(free.sum()), 2))
    _set_nodes(obj, lay, p)


def rotate(obj: Any, degrees: float = 150.0, radius: float = 0.2, seed: int = 0) -> None:
    """(b) The interior UV vertices within ``radius`` (a fraction of the largest island's
    size) of a point inside that island turned by ``degrees`` about that point."""
    lay = layout(obj)
    free = _interior(lay)
    big = int(np.argmax(np.abs(lay.area)))
    inside = free & (lay.node_island == big)
    pts = lay.points
    centre = pts[inside].mean(axis=0)
    centre = pts[inside][np.argmin(np.linalg.norm(pts[inside] - centre, axis=1))]
    size = float(np.ptp(pts[lay.node_island == big], axis=0).max())
    d = pts - centre
    disc = inside & (np.linalg.norm(d, axis=1) < radius * size)
    t = np.radians(degrees)
    rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    p = pts.copy()
    p[disc] = centre + d[disc] @ rot.T
    _set_nodes(obj, lay, p)


def mesh_edit(bpy: Any, obj: Any, shift: float = 1.2, radius: float = 3.0, seed: int = 0) -> None:
    """(c) A patch of 3D vertices (those within ``radius`` mean edge lengths of an interior
    vertex of the largest island) moved ``shift`` patch radii along the surface with
    Correct Face Attributes on (their UVs follow, the patch's UVs fold over), then put back
    in 3D as they were (a move with the option off): the UVs stay folded."""
    me = obj.data
    lay = layout(obj)
    free = _interior(lay)
    big = int(np.argmax(np.abs(lay.area)))
    co = _positions(me).astype(np.float64)
    ev = _edge_verts(me)
    h = float(np.linalg.norm(co[ev[:, 0]] - co[ev[:, 1]], axis=1).mean())
    # mesh vertices whose every UV vertex is interior (not on a seam or border)
    on_border = np.zeros(len(me.vertices), bool)
    on_border[lay.vertex[~free]] = True
    cand = np.flatnonzero(np.isin(np.arange(len(me.vertices)),
                                  lay.vertex[lay.node_island == big]) & ~on_border)
    rng = np.random.default_rng(seed)
    centre_v = int(cand[rng.integers(cand.size)])
    dist = np.linalg.norm(co - co[centre_v], axis=1)
    patch = (dist < radius * h) & ~on_border
    normal = np.array(me.vertices[centre_v].normal)
    tangent = np.cross(normal, [0.0, 0.0, 1.0])
    if np.linalg.norm(tangent) < 1e-6:
        tangent = np.cross(normal, [1.0, 0.0, 0.0])
    tangent /= np.linalg.norm(tangent)
    before = _positions(me).copy()
    for coll in (me.edges, me.polygons):
        coll.foreach_set("select", np.zeros(len(coll), bool))
    me.vertices.foreach_set("select", patch)
    ts = bpy.context.scene.tool_settings
    old = ts.use_transform_correct_face_attributes, ts.use_transform_correct_keep_connected
    ts.use_transform_correct_face_attributes = ts.use_transform_correct_keep_connected = True
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_mode(type="VERT")
    bpy.ops.transform.translate(value=tuple(shift * radius * h * tangent))
    bpy.ops.object.mode_set(mode="OBJECT")
    ts.use_transform_correct_face_attributes, ts.use_transform_correct_keep_connected = old
    me.attributes["position"].data.foreach_set("vector", before.ravel())
    me.update()


def tangle(bpy: Any, obj: Any, kind: str, seed: int = 0) -> None:
    """Apply one of ``TANGLES`` to the active UV map of ``obj`` (Object Mode)."""
    if kind == "jitter":
        jitter(obj, seed=seed)
    elif kind == "rotate":
        rotate(obj, seed=seed)
    elif kind == "mesh_edit":
        mesh_edit(bpy, obj, seed=seed)
    else:
        raise ValueError(f"unknown tangle {kind!r} (one of {', '.join(TANGLES)})")


TANGLES = ("jitter", "rotate", "mesh_edit")


def pin_some(obj: Any, fraction: float = 0.01, seed: int = 1,
             rings: int | None = 2) -> np.ndarray:
    """Pin a few interior UV vertices (all their loops) away from the tangle: none within
    ``rings`` faces of a flipped, inverted or overlapping face (a pin inside a fold can make
    it impossible to undo, and an artist pins what is right; None: anywhere); (L,) bool
    pins."""
    from core.uv.uv_overlap import overlapping_faces
    from core.uv.uv_untangle import flipped_faces

    me = obj.data
    lay = layout(obj)
    side = lay.orientation()
    bad = flipped_faces(lay, lay.points, side, corners=True) | overlapping_faces(
        lay.oriented_points(side), lay.faces, lay.island)
    face_of = np.repeat(np.arange(lay.faces.n_faces), lay.faces.counts)
    near = np.zeros(lay.n_nodes, bool)
    for _ in range(0 if rings is None else rings + 1):
        near[lay.faces.indices[bad[face_of]]] = True
        bad = np.zeros_like(bad)
        np.logical_or.at(bad, face_of, near[lay.faces.indices])
    rng = np.random.default_rng(seed)
    free = np.flatnonzero(_interior(lay) & ~near)
    chosen = rng.choice(free, min(free.size, max(1, int(fraction * free.size))), replace=False)
    on = np.zeros(lay.n_nodes, bool)
    on[chosen] = True
    pins = on[lay.loop_node]
    layer = me.uv_layers.active
    if hasattr(layer, "pin_ensure"):  # Blender 5.0 makes the pin layer on demand
        layer.pin_ensure()
    layer.pin.foreach_set("value", pins)
    me.update()
    return pins
