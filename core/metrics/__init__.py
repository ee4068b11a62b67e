"""What a mesh is judged by: the mean ratio quality (against regular polygons or per-face
target shapes), the other element measures, and the target shapes themselves.

- the mean ratio per arity group (`mean_ratio.group_quality`, the scale-safe
  `scaled_group_quality`); per face and summed up (`face_quality.quality`, `mesh_stats`,
  `Stats`, `folded_area`, `inverted_corners`, `signed_face_areas`); which corners are
  kept as given outside the paper's mode (`kept.kept_corners`: a straight or concave
  corner of fixed vertices only).
- other measures (min angle, skewness, aspect, ...): `measures` (docs/measures.md).
- target shapes (`targets.prepare_targets`, `Targets`, `face_shapes_2d`) and the shapes of
  a reference mesh (`reference_shapes.reference_targets`), docs/targets.md.
"""

from .face_quality import (
    Stats,
    folded_area,
    inverted_corners,
    mesh_stats,
    quality,
    signed_face_areas,
    stats_of,
)
from .kept import Kept, kept_corners, kept_note
from .measures import (
    MEASURE_NAMES,
    MEASURES,
    Measure,
    MeasureSummary,
    goodness,
    summaries,
    summarize,
)
from .reference_shapes import reference_targets, reference_to_2d
from .targets import Targets, face_shapes_2d, prepare_targets

__all__ = ["MEASURES", "MEASURE_NAMES", "Kept", "Measure", "MeasureSummary", "Stats",
           "Targets", "face_shapes_2d", "folded_area", "goodness", "inverted_corners",
           "kept_corners", "kept_note", "mesh_stats", "prepare_targets", "quality",
           "reference_targets", "reference_to_2d", "signed_face_areas", "stats_of",
           "summaries", "summarize"]
