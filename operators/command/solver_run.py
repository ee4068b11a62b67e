# SPDX-License-Identifier: GPL-3.0-or-later
"""The single-file command's solver mesh part (docs/engineers.md): the checks of the solver
flags and paths, reading the input into a Blender object with the file's pins and boundary
choices, and the quality per group of faces. The flags are ``parser.py``'s, the output's
staging ``output_files.py``'s.

Every problem is a :class:`UsageError` of one line (exit 2), raised before anything is
written.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
from typing import Any

import bpy
import numpy as np

from ...core import EEGTParams, boundary_nodes, faces_from_csr, summaries
from ...fileio import solver_mesh
from ...fileio.solver_formats import SOLVER_EXTENSIONS, solver_format
from ..mesh import runner
from ..solver_io import blender_mesh
from .usage import UsageError


def is_solver(path: str | None) -> bool:
    """Whether `path` names a solver mesh by its extension."""
    return bool(path) and solver_format(path) is not None


def check_paths(ns: argparse.Namespace) -> None:
    """Solver flags only with a solver input; a solver output only from a solver input
    (its blocks and data come from there); --pin-field not with --no-pinned; no --uv."""
    solver_in = is_solver(ns.input)
    flags = [f for f, v in (("--pin-field", ns.pin_field), ("--fixed-groups", ns.fixed_groups),
                            ("--slide-groups", ns.slide_groups)) if v]
    if flags and not solver_in:
        raise UsageError(f"eegt: {flags[0]} needs a solver mesh input "
                         f"({', '.join(SOLVER_EXTENSIONS)})")
    if ns.pin_field and ns.no_pinned:
        raise UsageError("eegt: give --pin-field or --no-pinned, not both")
    if is_solver(ns.output) and not solver_in:
        raise UsageError(f"eegt: a solver mesh output ('{ns.output}') needs a solver mesh "
                         "input: its other blocks, data and groups come from there")
    if solver_in and ns.uv is not None:
        raise UsageError("eegt: --uv works on .blend, .obj, .ply and .stl meshes")


def load(ns: argparse.Namespace, params: EEGTParams) -> tuple[EEGTParams, dict[str, Any]]:
    """Read the solver mesh input into a new object (in an empty scene); the run's
    parameters (the boundary mode the groups ask for) and the report's "solver_mesh"."""
    try:
        sm = solver_mesh.read(ns.input)
        choice = solver_mesh.node_choice(
            sm, params.boundary, boundary_nodes(sm.n_points, _faces(sm)), ns.pin_field,
            solver_mesh.parse_groups(ns.fixed_groups),
            solver_mesh.parse_groups(ns.slide_groups))
    except ValueError as exc:
        raise UsageError(f"eegt: {exc}") from None
    bpy.ops.wm.read_homefile(use_empty=True)
    name = os.path.splitext(os.path.basename(ns.input))[0] or "mesh"
    blender_mesh.build_object(sm, name, choice.pinned, groups=False)
    if choice.boundary != params.boundary:
        params = dataclasses.replace(params, boundary=choice.boundary)
    info = {"format": sm.fmt, "points": sm.n_points, "faces": sm.n_faces,
            "pinned": int(np.count_nonzero(choice.pinned)), "boundary": choice.boundary,
            "notes": list(choice.notes)}
    return params, info


def _faces(sm: solver_mesh.SolverMesh) -> Any:
    return faces_from_csr(sm.offsets[:-1], sm.counts(), sm.corners, sm.n_points)


def group_metrics(job: Any, result: Any, names: tuple[str, ...]) -> dict[str, Any] | None:
    """group -> measure -> {"before", "after"} over the faces of every group of 2D cells in
    the input file (the summaries as ``core.MeasureSummary.as_dict``)."""
    if job.error is not None or job.points2d is None:
        return None
    me = bpy.data.objects[job.object].data
    sm = blender_mesh.source_of(me)
    lut = np.full(sm.n_points, -1, dtype=np.int64)
    lut[job.nodes] = np.arange(job.nodes.size)
    after = job.points2d
    if result.written and job.new_co is not None:
        after = runner.written_2d(job, job.new_co)
    counts = sm.counts()
    out = {}
    for group, mask in sm.face_groups().items():
        corner_mask = np.repeat(mask, counts)
        sub = faces_from_csr(np.cumsum(counts[mask]) - counts[mask], counts[mask],
                             lut[sm.corners[corner_mask]], job.nodes.size)
        b, a = summaries(job.points2d, sub, names), summaries(after, sub, names)
        out[group] = {"faces": int(np.count_nonzero(mask)),
                      **{n: {"before": b[n].as_dict(), "after": a[n].as_dict()}
                         for n in names}}
    return out
