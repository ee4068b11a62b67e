"""EEGT core: untangle and smooth planar polygon meshes (NumPy; never imports bpy).

from core import untangle_and_smooth, quality, EEGTParams
res = untangle_and_smooth(points, faces, fixed=None, params=None, backend="numpy")
quality(points, faces, measure="min_angle"); summaries(points, faces)  # docs/measures.md
"""

from .faces import FaceSet, as_faceset, faces_from_csr
from .measures import MEASURE_NAMES, MEASURES, Measure, MeasureSummary, summaries, summarize
from .params import EEGTParams
from .pipeline import Cancelled, EEGTResult, free_nodes, untangle_and_smooth
from .planar import untangle_and_smooth_3d
from .plane import PlaneFrame
from .quality import Stats, mesh_stats, quality
from .topology import boundary_nodes

__version__ = "0.1.0"

__all__ = [
    "MEASURES",
    "MEASURE_NAMES",
    "Cancelled",
    "EEGTParams",
    "EEGTResult",
    "FaceSet",
    "Measure",
    "MeasureSummary",
    "PlaneFrame",
    "Stats",
    "as_faceset",
    "boundary_nodes",
    "faces_from_csr",
    "free_nodes",
    "mesh_stats",
    "quality",
    "summaries",
    "summarize",
    "untangle_and_smooth",
    "untangle_and_smooth_3d",
]
