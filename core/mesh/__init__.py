"""The mesh model: faces grouped by arity, their edges and boundary, node orders, the plane
a 3D mesh lies in, input checks and OBJ files. Every other room builds on this one; it
imports only `core.fpmath`.

- faces by arity (`faces.FaceSet`, `as_faceset`, `faces_from_csr`, a subset of them as
  its own FaceSet: `face_subset`); flat tables
  (`csr.ragged_arange`, `csr.bincount_csr`, Morton orders).
- edges, boundary and free nodes (`topology.EdgeInfo`, `edge_info`, `boundary_nodes`,
  `free_nodes`); cache-friendly renumbering of large meshes (`reorder`).
- consistent face orientation of clockwise or mixed faces (`orient.orient_faces`,
  `reverse_faces`).
- input points (`points.check_points`); the plane of a 3D mesh (`plane.PlaneFrame`).
- OBJ and legacy VTK files (`obj_io`).
"""

from .csr import bincount_csr, ragged_arange
from .faces import ArityGroup, FaceSet, as_faceset, face_subset, faces_from_csr
from .obj_io import read_legacy_vtk, read_obj, write_obj
from .orient import FaceOrientation, orient_faces, reverse_faces
from .plane import PlaneFrame, open_edges
from .points import check_points
from .topology import EdgeInfo, boundary_nodes, edge_info, free_nodes

__all__ = ["ArityGroup", "EdgeInfo", "FaceOrientation", "FaceSet", "PlaneFrame", "as_faceset",
           "bincount_csr", "boundary_nodes", "check_points", "edge_info", "face_subset",
           "faces_from_csr", "free_nodes", "open_edges", "orient_faces", "ragged_arange",
           "read_legacy_vtk", "read_obj", "reverse_faces", "write_obj"]
