"""The operators write what the core computes for the same job, bit for bit.

Mesh: Untangle & Smooth (``mesh.eegt_untangle_smooth``, NumPy backend, default parameters)
on a tangled mesh of tests/data, against the core called directly on the same mesh read
from the OBJ file by tests/meshdata.py (the test first checks that Blender holds exactly
those float32 positions and faces). The core (this checkout's ``core`` package, not the
extension's installed copy) runs its own 3D entry ``core.untangle_and_smooth_3d`` on the
float32 positions with ``stored=np.float32``: it centres and scales the points, fits the
plane, runs in it, and judges the float32 positions it returns with the one acceptance rule
(``core.run.accept``, float32 ties). The operator (operators/mesh/runner.py ``compute``)
makes that same call, so the written positions are the returned ones, bit for bit, on a
mesh at z = 0 and on a tilted one alike. Shared with the operator: the mesh file and the
parameters, read from the scene's settings as the operator reads them (Blender keeps them
as float32; the operators read them back as typed, ``props.params_from``, so they run the
core's and the command's defaults exactly: ``test_operator_defaults_are_the_core_defaults``).

UV: Untangle & Smooth UVs (``uv.eegt_untangle_smooth``, Edit Mode, every face selected,
defaults: 3D target shapes, scope "tangles") on a jittered UV sphere (bench.uv_assets),
against ``core.uv.uv_untangle.untangle_uv`` on the UV map welded by ``core.uv.uv_layout.weld_uv``
from the mesh's arrays read here with ``foreach_get``, targets
``core.metrics.targets.face_shapes_2d`` of its 3D faces and the core's default acceptance
(``core.run.accept`` with float32 ties, the operator's too). Shared with the operator: the
Blender mesh being read and the parameters, as for the mesh.
"""

from __future__ import annotations

import numpy as np
import pytest
from meshdata import load

from bench import uv_assets
from core import EEGTParams, faces_from_csr, untangle_and_smooth_3d
from core.metrics.targets import face_shapes_2d
from core.run import accept
from core.uv.uv_layout import weld_uv
from core.uv.uv_untangle import untangle_uv

from .conftest import import_obj, positions
from .uvtools import tangled, uv_values

pytestmark = pytest.mark.blender

MESHES = ["quad_hole", "mixed_quad_tri", "tilted_plane"]


def operator_params(ext, settings) -> EEGTParams:
    """The parameters the operators run with, read as they read them (as this checkout's
    EEGTParams: the extension's installed copy has a class of its own)."""
    got = ext.operators.ui.props.params_from(settings)
    return EEGTParams(**{name: getattr(got, name) for name in EEGTParams.field_names()})


def test_blender_holds_the_float_defaults_as_float32(bpy, ext):
    settings, core = bpy.context.scene.eegt_settings, EEGTParams()
    for name in EEGTParams.field_names():
        want = getattr(core, name)
        if isinstance(want, float):
            want = float(np.float32(want))
        assert getattr(settings, name) == want, name


def test_operator_defaults_are_the_core_defaults(bpy, ext):
    assert operator_params(ext, bpy.context.scene.eegt_settings) == EEGTParams()


def test_a_typed_value_reads_back_as_typed(bpy, ext):
    settings = bpy.context.scene.eegt_settings
    old = settings.a
    try:
        settings.a = 0.3
        assert settings.a == float(np.float32(0.3)) != 0.3
        assert operator_params(ext, settings).a == 0.3
    finally:
        settings.a = old


def operator_run(bpy, name: str) -> tuple[np.ndarray, np.ndarray, object]:
    """(float32 positions before, after Untangle & Smooth, the OBJ's faces); checks that
    Blender holds the OBJ's mesh: its positions rounded to float32, its faces in order."""
    obj = import_obj(bpy, name)
    v, faces = load(name)
    before = positions(obj)
    assert np.array_equal(before, v.astype(np.float32))
    ls, lt, cv = uv_assets.mesh_csr(obj)
    assert np.array_equal(ls, faces.offsets[:-1]) and np.array_equal(lt, np.diff(faces.offsets))
    assert np.array_equal(cv, faces.indices)
    assert bpy.ops.mesh.eegt_untangle_smooth(backend="NUMPY") == {"FINISHED"}
    assert obj.eegt_last_run.status == "untangled" and obj.eegt_last_run.backend == "numpy"
    return before, positions(obj), faces


@pytest.mark.parametrize("name", MESHES)
def test_mesh_operator_is_the_core_3d_entry(bpy, ext, name):
    params = operator_params(ext, bpy.context.scene.eegt_settings)
    before, written, faces = operator_run(bpy, name)
    res = untangle_and_smooth_3d(before.astype(np.float64), faces, params=params,
                                 backend="numpy", stored=np.float32)
    assert res.status == "untangled" and accept(res.before, res.after, np.float32)
    expected = res.points
    assert expected.dtype == np.float32 and not np.array_equal(written, before)
    changed = np.any(written != expected, axis=1)
    assert not changed.any(), (
        f"{int(changed.sum())} of {len(written)} vertices differ from untangle_and_smooth_3d's, "
        f"by up to {float(np.abs(written.astype(np.float64) - expected).max()):.3g}")
    assert written.tobytes() == expected.tobytes()  # -0.0 and +0.0 too


def test_uv_operator_writes_the_core_result_bit_for_bit(bpy, ext):
    params = operator_params(ext, bpy.context.scene.eegt_settings)
    uv_settings = bpy.context.scene.eegt_uv_settings
    assert (uv_settings.target_shape, uv_settings.scope, uv_settings.use_pins) == (
        "3D", "TANGLES", True)
    obj = tangled(bpy, "sphere", "jitter")
    me = obj.data
    uv0 = uv_values(obj)
    co = positions(obj)
    ls, lt, cv = uv_assets.mesh_csr(obj)
    pins = np.zeros(len(me.loops), bool)
    if len(me.uv_layers.active.pin) == len(me.loops):
        me.uv_layers.active.pin.foreach_get("value", pins)
    assert not pins.any()  # nothing pinned: the core runs with fixed=None

    bpy.context.scene.tool_settings.use_uv_select_sync = True  # selection = mesh selection
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    assert bpy.ops.uv.eegt_untangle_smooth(backend="NUMPY") == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    written = uv_values(obj)
    assert obj.eegt_last_uv_run.status == "untangled"

    lay = weld_uv(ls, lt, cv, uv0)
    targets = face_shapes_2d(co.astype(np.float64), faces_from_csr(ls, lt, cv, len(co)))
    selected = np.ones(len(ls), dtype=bool)
    res = untangle_uv(lay, selected, targets=targets, params=params, backend="numpy",
                      scope="tangles")
    assert res.status == "untangled" and res.moved.any()
    expected = uv0.copy()
    loops = res.moved[lay.loop_node]
    expected[loops] = res.points[lay.loop_node[loops]].astype(np.float32)
    assert not np.array_equal(written, uv0)
    changed = np.any(written != expected, axis=1)
    assert not changed.any(), (
        f"{int(changed.sum())} of {len(written)} UV loops differ from the core's, by up to "
        f"{float(np.abs(written.astype(np.float64) - expected).max()):.3g}")
    assert written.tobytes() == expected.tobytes()
