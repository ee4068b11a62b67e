"""One run result for mesh and UV runs (operators/shared/result.py): the shared base, the stats
block described once (fileio/run_stats.py), the one last-run store and sidebar section."""

from __future__ import annotations

import dataclasses
import importlib

import pytest

pytestmark = pytest.mark.blender


def mods(ext):
    return (importlib.import_module(f"{ext.__name__}.operators.{m}")
            for m in ("shared.result", "mesh.runner", "uv.uv_runner"))


class Layout:
    """A stand-in for a panel's layout: the labels drawn."""

    def __init__(self):
        self.labels = []

    def column(self, align=False):
        return self

    def label(self, text=""):
        self.labels.append(text)


def test_mesh_and_uv_results_share_one_base_and_say_their_kind(bpy, ext):
    result, runner, uv_runner = mods(ext)
    base = {f.name for f in dataclasses.fields(result.RunResult)}
    assert {"object", "mesh", "status", "message", "written", "before", "after", "seconds",
            "backend", "n_faces", "n_free", "notes", "untangle_iterations"} <= base
    for cls, kind in ((runner.ObjectResult, "mesh"), (uv_runner.UVObjectResult, "uv")):
        assert issubclass(cls, result.RunResult) and cls.KIND == kind
        d = cls(object="A", notes=["n"]).as_dict()
        assert d["kind"] == kind and base <= set(d) and d["notes"] == ["n"]
        assert cls.stats_kind().name == kind
    assert "uv_map" in uv_runner.UVObjectResult(object="A").as_dict()


def test_one_store_and_one_panel_section_for_both_kinds(bpy, ext):
    result, runner, uv_runner = mods(ext)
    bpy.ops.mesh.primitive_plane_add()
    obj = bpy.context.active_object
    mesh = runner.ObjectResult(object=obj.name, status="untangled", written=True,
                               before={"n_inverted": 3, "q_min": 0.0, "q_avg": 0.5},
                               after={"n_inverted": 0, "q_min": 0.25, "q_avg": 0.75},
                               untangle_iterations=4, smooth_iterations=6, seconds=1.5,
                               backend="numpy")
    uv = uv_runner.UVObjectResult(object=obj.name, uv_map="UVMap", status="untangled",
                                  written=True, seconds=2.0, backend="numpy",
                                  before={"flipped": 2, "inverted": 5, "overlapping": 7,
                                          "distortion_mean": 0.5, "distortion_worst": 0.0},
                                  after={"flipped": 0, "inverted": 0, "overlapping": 1,
                                         "distortion_mean": 0.9, "distortion_worst": 0.5})
    for r in (mesh, uv):
        result.store_last_run(obj, r)
    lr, lu = obj.eegt_last_run, obj.eegt_last_uv_run
    assert (lr.has_run, lr.status, lr.backend, lr.inverted_before, lr.q_avg_after,
            lr.untangle_iterations) == (True, "untangled", "numpy", 3, 0.75, 4)
    assert (lu.has_run, lu.uv_map, lu.flipped_before, lu.overlapping_after,
            lu.distortion_worst_after) == (True, "UVMap", 2, 1, 0.5)
    assert lr.message == mesh.line() and lu.message == uv.line()
    m, u = Layout(), Layout()
    result.draw_last_run(m, obj, "mesh", obj.name)
    result.draw_last_run(u, obj, "uv", f"{obj.name} 'UVMap'")
    assert m.labels == [f"{obj.name}: untangled", "Inverted: 3 -> 0", "q min: 0.000 -> 0.250",
                        "q avg: 0.500 -> 0.750", "Iterations: 4 + 6", "1.50 s, numpy"]
    assert u.labels == [f"{obj.name} 'UVMap': untangled", "Flipped: 2 -> 0", "Inverted: 5 -> 0",
                        "Overlapping: 7 -> 1", "Distortion mean: 0.500 -> 0.900",
                        "Distortion worst: 0.000 -> 0.500", "2.00 s"]
    empty = Layout()
    result.draw_last_run(empty, None, "uv", "")
    assert empty.labels == ["No UV run on the active object yet"]
