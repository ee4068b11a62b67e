"""Independent mesh checks for the e2e tests (NumPy only; runs in Blender's Python 3.13 / NumPy 2.2
and in any Python 3.11+). Deliberately does NOT import the project's core: it re-implements the
mean ratio (docs/method.md 3) so the e2e tests check the extension against a second implementation.

Command line:  python3 meshcheck.py stats FILE.obj            -> JSON stats
               python3 meshcheck.py compare IN.obj OUT.obj    -> JSON: topology same? boundary kept?
"""
import json
import math
import os
import sys

import numpy as np

# the tests' one boundary oracle (tests/oracles.py: NumPy only, none of the project's code);
# tests/ goes last on the path, so it shadows nothing a Blender script imports
_TESTS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if _TESTS not in sys.path:
    sys.path.append(_TESTS)
from oracles import boundary_loops, boundary_nodes  # noqa: E402


def read_obj(path):
    """Return (verts float64 (N,3), faces list of int arrays, 0-based). Only v and f lines."""
    verts, faces = [], []
    with open(path) as fh:
        for line in fh:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                verts.append([float(x) for x in parts[1:4]])
            elif parts[0] == "f":
                # "f 1/2/3 ..." -> vertex index only; negative = relative to the end
                idx = [int(p.split("/")[0]) for p in parts[1:]]
                faces.append(np.array([i - 1 if i > 0 else len(verts) + i for i in idx]))
    return np.asarray(verts, dtype=np.float64).reshape(-1, 3), faces


def plane_2d(verts, faces):
    """Project to 2D in the mesh plane (normal = vector area, docs/method.md 5); the valid
    orientation is counterclockwise."""
    n = np.zeros(3)
    for f in faces:  # Newell: sum of face area vectors
        p = verts[f]
        n += 0.5 * np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)
    n /= np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    c = verts.mean(axis=0)
    xy = np.stack([(verts - c) @ u, (verts - c) @ v], axis=1)
    off_plane = np.abs((verts - c) @ n).max() if len(verts) else 0.0
    return xy, off_plane


def face_quality(xy, f):
    """Mean ratio of one n-gon (docs/method.md 3): mean of corner q_k, 0 if any corner det <= 0."""
    p = xy[f]
    nn = len(f)
    a = (nn - 2) * math.pi / nn
    w_inv = np.linalg.inv(np.array([[1.0, math.cos(a)], [0.0, math.sin(a)]]))
    e1 = np.roll(p, -1, axis=0) - p  # p_{k+1} - p_k
    e2 = np.roll(p, 1, axis=0) - p  # p_{k-1} - p_k
    det_j = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    if np.any(det_j <= 0):
        return 0.0
    qs = []
    for k in range(nn):
        m = np.column_stack([e1[k], e2[k]]) @ w_inv
        qs.append(2.0 * np.linalg.det(m) / np.sum(m * m))
    return float(np.mean(qs))


def stats(verts, faces):
    xy, off_plane = plane_2d(verts, faces)
    q = np.array([face_quality(xy, f) for f in faces])
    size = float(np.ptp(verts, axis=0).max()) if len(verts) else 0.0
    return {
        "n_nodes": len(verts),
        "n_faces": len(faces),
        "n_inverted": int(np.sum(q <= 0.0)),
        "q_min": float(q.min()),
        "q_avg": float(q.mean()),
        "finite": bool(np.isfinite(verts).all()),
        "off_plane_rel": float(off_plane / size) if size else 0.0,
    }


def compare(path_in, path_out):
    """Same topology? Boundary nodes bit-identical (as written)? How far did interior nodes move?"""
    vi, fi = read_obj(path_in)
    vo, fo = read_obj(path_out)
    same_topo = len(fi) == len(fo) and all(np.array_equal(a, b) for a, b in zip(fi, fo))
    res = {"same_topology": bool(same_topo and len(vi) == len(vo))}
    if res["same_topology"]:
        b = boundary_nodes(fi)
        # OBJ text round trip: allow float32 print precision on the fixed nodes
        res["boundary_max_move"] = float(np.abs(vi[b] - vo[b]).max()) if b else 0.0
        res["max_move"] = float(np.abs(vi - vo).max())
    res["in"] = stats(vi, fi)
    res["out"] = stats(vo, fo)
    return res


def uv_check(uv, faces, corner_verts):
    """A UV map checked on its own: uv (L, 2) per loop, faces as lists of loop indices,
    corner_verts (L,) the mesh vertex of each loop. Loops of one vertex with equal UVs are
    one UV vertex; the map is taken as one island, its orientation from its total signed
    area. Returns n_inverted (a corner det <= 0 in that orientation), n_flipped (area <= 0)
    and the loops on the UV border (edges used by one face of the welded UV mesh)."""
    uv = np.asarray(uv, dtype=np.float64)
    area = [0.5 * float(np.sum(uv[f, 0] * np.roll(uv[f, 1], -1) - np.roll(uv[f, 0], -1)
                                * uv[f, 1])) for f in faces]
    side = 1.0 if sum(area) > 0 else -1.0
    xy = uv * [side, 1.0]
    q = [face_quality(xy, np.asarray(f)) for f in faces]
    ids = {}
    node = [ids.setdefault((int(v), float(a), float(b)), len(ids))
            for v, (a, b) in zip(corner_verts, uv)]
    welded = [np.array([node[i] for i in f]) for f in faces]
    border = set(boundary_nodes(welded))
    return {"n_inverted": int(sum(x <= 0.0 for x in q)),
            "n_flipped": int(sum(side * a <= 0.0 for a in area)),
            "orientation": int(side), "n_uv_vertices": len(ids),
            "border_loops": [i for i, n in enumerate(node) if n in border]}


def slide_check(path_in, path_out, feature_deg=30.0):
    """Boundary sliding: each output boundary vertex's distance to its input loop polyline
    (relative to the size), how far the corners (turning angle > feature_deg) moved, whether
    every loop kept its vertices' cyclic order, how many boundary vertices moved."""
    vi, fi = read_obj(path_in)
    vo, _ = read_obj(path_out)
    xi, _ = plane_2d(vi, fi)
    xo = plane_2d_like(vi, fi, vo)
    size = float(np.ptp(xi, axis=0).max())
    res = {"dist_rel": 0.0, "corners": 0, "corner_move_rel": 0.0, "order_kept": True,
           "moved": 0}
    for loop in boundary_loops(fi):
        a = xi[loop]
        b = np.roll(a, -1, axis=0)
        d = b - a
        q = xo[loop]
        u = np.clip(((q[:, None] - a[None]) * d[None]).sum(2) / (d * d).sum(1)[None], 0, 1)
        dist = np.sqrt(((a[None] + u[..., None] * d[None] - q[:, None]) ** 2).sum(2))
        k = dist.argmin(1)
        t = k + u[np.arange(len(loop)), k]
        res["dist_rel"] = max(res["dist_rel"], float(dist.min(1).max()) / size)
        e1, e2 = a - np.roll(a, 1, axis=0), d
        cos = (e1 * e2).sum(1) / np.sqrt((e1 * e1).sum(1) * (e2 * e2).sum(1))
        corner = cos < math.cos(math.radians(feature_deg))
        res["corners"] += int(corner.sum())
        if corner.any():
            move = np.sqrt(((q[corner] - a[corner]) ** 2).sum(1)).max() / size
            res["corner_move_rel"] = max(res["corner_move_rel"], float(move))
        gaps = (np.roll(t, -1) - t) % len(loop)
        res["order_kept"] &= bool(np.all(gaps > 0) and abs(gaps.sum() - len(loop)) < 1e-6)
        res["moved"] += int((np.sqrt(((q - a) ** 2).sum(1)) > 1e-4 * size).sum())
    return res


def plane_2d_like(verts_ref, faces, verts):
    """`verts` in the 2D frame plane_2d gives `verts_ref` (so both compare in one frame)."""
    n = np.zeros(3)
    for f in faces:
        p = verts_ref[f]
        n += 0.5 * np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)
    n /= np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    c = verts_ref.mean(axis=0)
    return np.stack([(verts - c) @ u, (verts - c) @ v], axis=1)


if __name__ == "__main__":
    if sys.argv[1] == "stats":
        print(json.dumps(stats(*read_obj(sys.argv[2]))))
    elif sys.argv[1] == "compare":
        print(json.dumps(compare(sys.argv[2], sys.argv[3])))
    else:
        sys.exit("usage: meshcheck.py stats FILE | compare IN OUT")
