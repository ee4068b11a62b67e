"""Target "Keep Shapes" of a UV run (``choices.UV_TARGET`` "KEEP"): each UV face is pulled
towards its own shape as the user laid it out, so that a repair of a fold keeps the layout
(its per-face proportions: grading, anisotropy, stretch) everywhere else.

A tangled face (``uv_untangle.tangled_faces``: inverted, i.e. zero or reversed area or a
corner that does not turn left, corners kept as given excepted; or overlapping another face
of its island) has no usable shape of its own: a folded face has none at all, and the faces
a fold drags over others are distorted by it. It takes the shape of a face of its arity
across one of its edges, turned half a turn (``core.run.repair.neighbour_shapes``, the
solver-mesh repair's rule: a cell of a structured layout gets its neighbour's aspect),
spreading from the untangled faces; a tangled face that no such neighbour reaches takes its
3D face's shape (``core.metrics.face_shapes_2d``, what target "3D" uses) when given, else
keeps its own corners (a folded face's then fall back to the regular polygon in the core: a
target with a corner that does not turn left does, and is counted).

The targets are in the island's orientation (``UVLayout.oriented_points``: a mirrored
island reflected, u -> -u, exact), as the runs see their faces; only a face's shape counts
(position, rotation and size are free).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..run.repair import neighbour_shapes
from .uv_layout import UVLayout
from .uv_untangle import tangled_faces

__all__ = ["KeepShapes", "keep_shape_targets"]


class KeepShapes(NamedTuple):
    """Targets of "Keep Shapes" and where the tangled faces' came from; (F,) masks."""

    targets: np.ndarray  # (C, 2) per-corner targets in ``layout.faces`` corner order
    tangled: np.ndarray  # faces without a usable shape of their own
    from_neighbour: np.ndarray  # ... that took a same-arity neighbour's shape
    from_3d: np.ndarray  # ... that took their 3D face's shape (no neighbour reached them)

    @property
    def n_own(self) -> int:
        """Tangled faces left with their own corners (no neighbour, no 3D shape)."""
        return int(np.count_nonzero(self.tangled & ~self.from_neighbour & ~self.from_3d))

    def note(self) -> str:
        """One report line on the tangled faces' targets, "" when there were none."""
        n_t, n_n, n_3 = (int(np.count_nonzero(m)) for m in (self.tangled, self.from_neighbour,
                                                             self.from_3d))
        if not n_t:
            return ""
        parts = [f"{n_n} a neighbour's"] if n_n else []
        parts += [f"{n_3} their 3D face's"] if n_3 else []
        parts += [f"{self.n_own} their own"] if self.n_own else []
        return f"{n_t} tangled faces took the shape of: " + ", ".join(parts)


def keep_shape_targets(layout: UVLayout, points: np.ndarray | None = None,
                       faces: np.ndarray | None = None, fixed: np.ndarray | None = None,
                       shapes3d: np.ndarray | None = None, side: np.ndarray | None = None,
                       keep: bool = True, tangled: np.ndarray | None = None) -> KeepShapes:
    """The targets of "Keep Shapes" for the UV vertex ``points`` (default
    ``layout.points``, as stored): every face's own corners (island orientation), a tangled
    face's from a same-arity neighbour across an edge, else from ``shapes3d`` ((C, 2), the
    3D faces' shapes in ``layout.faces`` corner order) when given.

    Tangled: the mask ``tangled`` when the caller has it, else ``tangled_faces`` for a run on
    the faces ``faces`` (default every face) with the pins ``fixed`` and the rule ``keep``
    for corners kept as given (False: the paper's mode, none); a face whose only
    non-convex corners are kept as given keeps its own shape, which the core measures
    without those corners."""
    side = layout.orientation() if side is None else side
    pts = layout.points if points is None else np.asarray(points, dtype=np.float64)
    fs = layout.faces
    corners = layout.oriented_points(side, pts)[fs.indices].astype(np.float64, copy=True)
    if tangled is None:
        faces = np.ones(fs.n_faces, dtype=bool) if faces is None else faces
        tangled = tangled_faces(layout, pts, faces, side, fixed=fixed, keep=keep)
    tangled = np.asarray(tangled, dtype=bool)
    none = np.zeros(fs.n_faces, dtype=bool)
    if not tangled.any():
        return KeepShapes(corners, tangled, none, none.copy())
    reached = neighbour_shapes(corners, fs, tangled)
    left = tangled & ~reached
    from_3d = none.copy()
    if shapes3d is not None and left.any():
        shapes3d = np.asarray(shapes3d, dtype=np.float64)
        if shapes3d.shape != corners.shape:
            raise ValueError(f"shapes3d must be a {corners.shape} array, got {shapes3d.shape}")
        rows = np.repeat(left, fs.counts)
        corners[rows] = shapes3d[rows]
        from_3d = left
    return KeepShapes(corners, tangled, reached, from_3d)
