"""UV maps: the layout (welded UV vertices, islands), overlaps between faces, and the run
per island (`uv_untangle.untangle_uv`, docs/uv.md), and the targets of "Keep Shapes" (each face
its own laid-out shape, a folded face a neighbour's or its 3D face's:
`uv_targets.keep_shape_targets`).
"""

from .uv_layout import UVLayout, components, corner_loops, island_faces, weld_uv
from .uv_overlap import overlapping_faces
from .uv_targets import KeepShapes, keep_shape_targets
from .uv_untangle import (
    UVMeasures,
    UVResult,
    flipped_faces,
    keeps_corners,
    kept_as_given,
    kept_face_mask,
    measure,
    overlaps_around,
    tangled_faces,
    untangle_uv,
)

__all__ = ["KeepShapes", "UVLayout", "UVMeasures", "UVResult", "components", "corner_loops",
           "flipped_faces", "island_faces", "keep_shape_targets", "keeps_corners",
           "kept_as_given", "kept_face_mask", "measure", "overlapping_faces", "overlaps_around",
           "tangled_faces", "untangle_uv", "weld_uv"]
