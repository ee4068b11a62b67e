"""Tables and pictures for mesh engineers: boundary modes and reference target shapes.

Run `python -m bench.engineers [--out docs] [--no-pictures]`. Prints markdown tables:

1. Boundary modes on the shared meshes (default parameters, and the paper's EEGT-only
   parameters): fixed vs slide, the whole mesh's q_min / q_avg and that of the faces
   touching the boundary, and the proof for slide: the largest distance of a result
   boundary vertex to its input boundary loop (relative to the mesh size; measured here,
   independently of core.eegt.boundary, against every segment of the loop), corners moved, loops
   whose cyclic order changed, boundary vertices that slid.
2. Free boundary: our three-quads-around-a-triangle case (Mesquite's fixed-flag convention:
   only boundary nodes, six pinned, the triangle's three start at one point) and the
   paper's Table 1 mesh (third-party, not bundled: docs/testing.md) with its fixed flags as pins
   (= the fixed mode) and without.
3. Reference target shapes: naca_deform with naca_undeformed as reference, and a generated
   boundary-layer O-grid (sizes 1:257, aspect up to 105) whose body moved: regular vs
   reference targets, the mean ratio (against the regular polygon and against the
   reference), and per face max(x / x_ref, x_ref / x) of the size (square root of the area)
   and of the aspect ratio: median and 95th percentile; the grading (largest / smallest
   size).
Pictures (--out): engineers_slide.png (quad_hole's boundary faces, fixed vs slide),
engineers_reference.png (the O-grid near its wall: reference, moved, regular, reference).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from core import EEGTParams, mesh_stats, quality, untangle_and_smooth
from core.mesh.faces import as_faceset
from core.mesh.obj_io import read_legacy_vtk, read_obj
from core.metrics.measures import face_values
from core.metrics.reference_shapes import reference_targets

from .meshgen import boundary_layer_annulus, moved_body

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
MESQUITE = ROOT.parent / "shared" / "meshes" / "mesquite" / "hole_in_square_tanglap.vtk"
SHARED = ["quad_hole", "mixed_quad_tri", "tri_two_holes", "polygon_voronoi", "naca_deform",
          "two_holes_twist"]


def load2d(name: str):
    v, f = read_obj(DATA / f"{name}.obj")
    return v[:, :2].copy(), f


def boundary_loops(faces, n: int) -> list[np.ndarray]:
    fs = as_faceset(faces, n)
    a = np.concatenate([g.nodes.ravel() for g in fs.groups])
    b = np.concatenate([np.roll(g.nodes, -1, axis=0).ravel() for g in fs.groups])
    key = np.minimum(a, b) * n + np.maximum(a, b)
    _, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    nxt = dict(zip(a[cnt[inv] == 1].tolist(), b[cnt[inv] == 1].tolist()))
    seen, loops = set(), []
    for s in nxt:
        if s in seen:
            continue
        loop, v = [], s
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt[v]
        loops.append(np.array(loop))
    return loops


def slide_proof(p0, p1, faces, feature: float = 30.0) -> dict:
    size = float(np.ptp(p0, axis=0).max())
    out = {"dist": 0.0, "corners": 0, "moved_corners": 0, "bad_order": 0, "slid": 0}
    for loop in boundary_loops(faces, len(p0)):
        a = p0[loop]
        b = np.roll(a, -1, axis=0)
        d = b - a
        q = p1[loop]
        u = np.clip(((q[:, None] - a[None]) * d[None]).sum(2) / (d * d).sum(1)[None], 0, 1)
        dist = np.sqrt(((a[None] + u[..., None] * d[None] - q[:, None]) ** 2).sum(2))
        k = dist.argmin(1)
        t = k + u[np.arange(len(loop)), k]
        out["dist"] = max(out["dist"], float(dist.min(1).max()) / size)
        e1 = a - np.roll(a, 1, axis=0)
        cos = (e1 * d).sum(1) / np.sqrt((e1 * e1).sum(1) * (d * d).sum(1))
        corner = cos < np.cos(np.radians(feature))
        out["corners"] += int(corner.sum())
        out["moved_corners"] += int(np.any(q[corner] != a[corner], axis=1).sum())
        gaps = (np.roll(t, -1) - t) % len(loop)
        out["bad_order"] += int(not (np.all(gaps > 0) and abs(gaps.sum() - len(loop)) < 1e-9))
        out["slid"] += int(np.any(q != a, axis=1).sum())
    return out


def near_boundary(p, faces, points) -> tuple[float, float]:
    """q_min, q_avg of the faces touching the boundary, at `points`."""
    fs = as_faceset(faces, len(p))
    on = np.zeros(len(p), dtype=bool)
    for loop in boundary_loops(faces, len(p)):
        on[loop] = True
    touch = np.array([on[f].any() for f in fs.to_lists()])
    q = quality(points, faces)[touch]
    return float(q.min()), float(q.mean())


def boundary_table() -> list[str]:
    rows = ["| mesh | params | boundary | inverted | q_min | q_avg | boundary faces q_min / "
            "q_avg | max off-curve | corners moved / corners | order changed | boundary "
            "vertices slid | seconds |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in SHARED:
        p, f = load2d(name)
        for label, base in (("default", EEGTParams()), ("paper", EEGTParams.paper())):
            for mode in ("fixed", "slide"):
                t0 = time.perf_counter()
                r = untangle_and_smooth(p, f, params=base.with_(boundary=mode))
                secs = time.perf_counter() - t0
                bq = near_boundary(p, f, r.points)
                pr = slide_proof(p, r.points, f)
                rows.append(
                    f"| {name} | {label} | {mode} | {r.after.n_inverted} | {r.after.q_min:.3f} "
                    f"| {r.after.q_avg:.3f} | {bq[0]:.3f} / {bq[1]:.3f} | {pr['dist']:.1e} | "
                    f"{pr['moved_corners']} / {pr['corners']} | {pr['bad_order']} | "
                    f"{pr['slid']} | {secs:.2f} |")
    return rows


def three_quads_around_a_triangle():
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3.0) / 2]])
    pts, faces = [*tri], [[0, 1, 2]]
    for k in range(3):
        u, v = k, (k + 1) % 3
        d = tri[v] - tri[u]
        out = np.array([d[1], -d[0]])
        pts += [tri[u] + out, tri[v] + out]
        faces.append([u, 3 + 2 * k, 4 + 2 * k, v])
    p = np.array(pts)
    p[:3] = tri.mean(axis=0)
    pins = np.zeros(len(p), dtype=bool)
    pins[3:] = True
    return p, faces, pins


def free_table() -> list[str]:
    rows = ["| mesh | pins | boundary | params | result | inverted | q_min | q_avg | pins "
            "moved |", "|---|---|---|---|---|---|---|---|---|"]
    p, faces, pins = three_quads_around_a_triangle()
    for mode in ("fixed", "free"):
        for label, base in (("default", EEGTParams()), ("paper", EEGTParams.paper())):
            try:
                r = untangle_and_smooth(p, faces, fixed=pins, params=base.with_(boundary=mode))
                moved = int(np.any(r.points[pins] != p[pins], axis=1).sum())
                rows.append(f"| 3 quads around a triangle | the 6 outer corners | {mode} | "
                            f"{label} | {r.status} | {r.after.n_inverted} | "
                            f"{r.after.q_min:.3f} | {r.after.q_avg:.3f} | {moved} |")
            except ValueError as exc:
                rows.append(f"| 3 quads around a triangle | the 6 outer corners | {mode} | "
                            f"{label} | refused: {exc} | | | | |")
    if MESQUITE.exists():
        pts, cells = read_legacy_vtk(MESQUITE)
        p2, quads = pts[:, :2].copy(), cells.reversed()
        tokens = MESQUITE.read_text().split()
        i = tokens.index("fixed") + 4
        flags = np.array(tokens[i : i + len(p2)], dtype=float) != 0
        paper = EEGTParams.paper()
        fixed = untangle_and_smooth(p2, quads, params=paper)
        for pins_label, pins2 in (("Mesquite's fixed flags (56)", flags), ("none", None)):
            r = untangle_and_smooth(p2, quads, fixed=pins2, params=paper.with_(boundary="free"))
            same = " (= fixed, bit for bit)" if np.array_equal(r.points, fixed.points) else ""
            moved = 0 if pins2 is None else int(np.any(r.points[flags] != p2[flags], 1).sum())
            rows.append(f"| Table 1 mesh (Mesquite) | {pins_label} | free | paper | "
                        f"{r.status}{same} | {r.after.n_inverted} | {r.after.q_min:.3f} | "
                        f"{r.after.q_avg:.3f} | {moved} |")
    return rows


def areas(p, faces) -> np.ndarray:
    fs = as_faceset(faces, len(p))
    out = np.empty(fs.n_faces)
    for g in fs.groups:
        x, y = p[g.nodes, 0], p[g.nodes, 1]
        out[g.ids] = 0.5 * np.sum(x * np.roll(y, -1, 0) - np.roll(x, -1, 0) * y, axis=0)
    return out


def against(p, r, faces) -> tuple[float, ...]:
    s = np.sqrt(np.abs(areas(p, faces)) / np.abs(areas(r, faces)))
    s = np.maximum(s, 1 / s)
    a = face_values(p, faces, "aspect_ratio") / face_values(r, faces, "aspect_ratio")
    a = np.maximum(a, 1 / a)
    size = np.sqrt(np.abs(areas(p, faces)))
    return (float(np.median(s)), float(np.percentile(s, 95)), float(np.median(a)),
            float(np.percentile(a, 95)), float(size.max() / size.min()))


def reference_cases():
    p, f = load2d("naca_deform")
    r, _ = load2d("naca_undeformed")
    yield "naca_deform (reference: naca_undeformed)", p, f, r
    ref, faces = boundary_layer_annulus()
    yield "boundary-layer O-grid, body moved (bench.meshgen)", moved_body(ref), faces, ref


def reference_table(results: dict) -> list[str]:
    rows = ["| case | target | boundary | inverted | q_min / q_avg (regular) | q_min / q_avg "
            "(vs reference) | size ratio median / p95 | aspect ratio median / p95 | grading "
            "(reference) | seconds |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, p, f, r in reference_cases():
        tg = reference_targets(r, f, len(r))
        g_ref = against(r, r, f)[4]
        rows.append(f"| {name} | input | | {mesh_stats(p, f).n_inverted} | | | "
                    "{:.3f} / {:.3f} | {:.3f} / {:.3f} | {:.0f} ({:.0f}) | |".format(
                        *against(p, r, f), g_ref))
        for target in ("regular", "reference"):
            for boundary in ("fixed", "slide"):
                t0 = time.perf_counter()
                res = untangle_and_smooth(p, f, params=EEGTParams(target=target,
                                                                  boundary=boundary),
                                          reference_points=r if target == "reference" else None)
                secs = time.perf_counter() - t0
                results[(name, target, boundary)] = res.points
                q = mesh_stats(res.points, f)
                qr = mesh_stats(res.points, f, targets=tg)
                m = against(res.points, r, f)
                rows.append(
                    f"| {name} | {target} | {boundary} | {q.n_inverted} | {q.q_min:.3f} / "
                    f"{q.q_avg:.3f} | {qr.q_min:.3f} / {qr.q_avg:.3f} | {m[0]:.3f} / "
                    f"{m[1]:.3f} | {m[2]:.3f} / {m[3]:.3f} | {m[4]:.0f} ({g_ref:.0f}) | "
                    f"{secs:.1f} |")
    return rows


def pictures(out: Path, results: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection, PolyCollection

    def draw(ax, pts, faces, q, title, view=None, vmin=0.3):
        polys = [pts[f] for f in as_faceset(faces, len(pts)).to_lists()]
        coll = PolyCollection(polys, array=q, cmap="RdYlGn", clim=(vmin, 1.0),
                              edgecolors="0.25", linewidths=0.25)
        ax.add_collection(coll)
        segs = []
        for loop in boundary_loops(faces, len(pts)):
            a = pts[loop]
            segs += list(np.stack([a, np.roll(a, -1, axis=0)], axis=1))
        ax.add_collection(LineCollection(segs, colors="k", linewidths=0.9))
        ax.set_aspect("equal")
        ax.autoscale_view()
        if view is not None:
            ax.set_xlim(view[0], view[1])
            ax.set_ylim(view[2], view[3])
        ax.set_axis_off()
        ax.set_title(title, fontsize=9)
        return coll

    p, f = load2d("quad_hole")
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.6), dpi=110)
    for ax, mode in zip(axes, ("fixed", "slide")):
        r = untangle_and_smooth(p, f, params=EEGTParams(boundary=mode))
        bq = near_boundary(p, f, r.points)
        coll = draw(ax, r.points, f, quality(r.points, f),
                    f"quad_hole, boundary '{mode}'\nq_min {r.after.q_min:.3f}, q_avg "
                    f"{r.after.q_avg:.3f}; faces at the boundary: q_avg {bq[1]:.3f}")
    fig.colorbar(coll, ax=axes, shrink=0.7, label="mean ratio")
    fig.savefig(out / "engineers_slide.png", bbox_inches="tight")
    plt.close(fig)

    name = "boundary-layer O-grid, body moved (bench.meshgen)"
    ref, faces = boundary_layer_annulus()
    moved = moved_body(ref)
    shown = [("reference (undeformed)", ref, (0.0, 0.0)),
             ("body moved: input", moved, (0.9, 0.3)),
             ("target 'regular'", results[(name, "regular", "fixed")], (0.9, 0.3)),
             ("target 'reference'", results[(name, "reference", "fixed")], (0.9, 0.3))]
    fig, axes = plt.subplots(2, 4, figsize=(16, 9), dpi=100)
    fig.subplots_adjust(wspace=0.15, hspace=0.25)
    for col, (title, pts, (cx, cy)) in enumerate(shown):
        # colour: the face's size against the reference's, log2 (0: the same size)
        ratio = np.log2(np.sqrt(np.abs(areas(pts, faces)) / np.abs(areas(ref, faces))))
        s = against(pts, ref, faces)
        a = face_values(pts, faces, "aspect_ratio")
        wall = a[:40]  # the first row of cells around the body
        for row, (half, note) in enumerate(((3.0, "around the body"),
                                            (0.06, "at the wall (first rows)"))):
            ax = axes[row, col]
            view = (cx - 1.0 - half, cx - 1.0 + half, cy - half, cy + half) if row else \
                (cx - half, cx + half, cy - half, cy + half)
            coll = draw(ax, pts, faces, ratio, "", view, vmin=-3.0)
            coll.set_clim(-3.0, 3.0)
            coll.set_cmap("coolwarm")
            ax.set_title((f"{title}\nsize ratio p95 {s[1]:.2f}, grading {s[4]:.0f}\n"
                          f"aspect of the wall cells {wall.mean():.0f}\n" if row == 0
                          else "") + note, fontsize=9)
    fig.colorbar(coll, ax=axes, shrink=0.6, label="log2(size / reference size)")
    fig.savefig(out / "engineers_reference.png", bbox_inches="tight")
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs", help="folder for the pictures")
    ap.add_argument("--no-pictures", action="store_true")
    args = ap.parse_args()
    print("## Boundary modes\n")
    print("\n".join(boundary_table()))
    print("\n## Free boundary\n")
    print("\n".join(free_table()))
    print("\n## Reference target shapes\n")
    results: dict = {}
    print("\n".join(reference_table(results)))
    if not args.no_pictures:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        pictures(out, results)
        print(f"\npictures: {out / 'engineers_slide.png'}, {out / 'engineers_reference.png'}")


if __name__ == "__main__":
    main()
