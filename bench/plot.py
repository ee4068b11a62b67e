"""Mesh pictures: inverted faces red, others grey, boundary edges black (matplotlib)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection, PolyCollection

from core.mesh.faces import FaceSet
from core.mesh.topology import EdgeInfo
from core.metrics.face_quality import quality


def draw(ax, points: np.ndarray, faces: FaceSet, title: str) -> None:
    q = quality(points, faces)
    polys = [points[f] for f in faces.to_lists()]
    colors = np.where(q[:, None] == 0, [[0.85, 0.1, 0.1, 1.0]], [[0.86, 0.86, 0.86, 1.0]])
    ax.add_collection(PolyCollection(polys, facecolors=colors, edgecolors="0.35", linewidths=0.2))
    e = EdgeInfo(faces, len(points))
    open_edges = e.counts == 1
    segs = np.stack([points[e.lo[open_edges]], points[e.hi[open_edges]]], axis=1)
    ax.add_collection(LineCollection(segs, colors="k", linewidths=0.8))
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_axis_off()
    inv = int((q == 0).sum())
    ax.set_title(f"{title}\n{inv} inverted, q_min {q.min():.3f}, q_avg {q.mean():.3f}", fontsize=9)


def before_after_png(
    path,
    before: np.ndarray,
    after: np.ndarray,
    faces: FaceSet,
    name: str,
    view: tuple[float, float, float, float] | None = None,
) -> None:
    """One PNG with the tangled input left and the result right."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 5), dpi=110)
    draw(axes[0], before, faces, f"{name}: input")
    draw(axes[1], after, faces, f"{name}: result")
    if view is not None:
        for ax in axes:
            ax.set_xlim(view[0], view[1])
            ax.set_ylim(view[2], view[3])
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
