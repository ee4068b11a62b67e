"""Headless Blender (PyPI ``bpy``) fixtures: build the real zip, install it, enable it.

HOME and BLENDER_USER_RESOURCES point at a temporary folder *before* bpy is imported, so the
extension goes into a sandboxed user repository and no user preferences are read.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from meshdata import DATA as DATA  # tests/data, re-exported: the CLI tests import it from here
from meshdata import path as mesh_path

ROOT = Path(__file__).resolve().parents[2]
EXT_ID = "eegt_blender"
MODULE = f"bl_ext.user_default.{EXT_ID}"

_SANDBOX = tempfile.mkdtemp(prefix="eegt_bpy_user_")
if "bpy" not in sys.modules:
    os.environ["HOME"] = _SANDBOX
    os.environ["BLENDER_USER_RESOURCES"] = _SANDBOX


def pytest_collection_modifyitems(items):
    """Every test in this folder needs bpy: mark them all ``blender``."""
    here = Path(__file__).parent
    for item in items:
        if Path(str(item.fspath)).is_relative_to(here):
            item.add_marker(pytest.mark.blender)


@pytest.fixture(scope="session")
def bpy_mod():
    """The bpy module, imported inside the sandbox."""
    bpy = pytest.importorskip("bpy", reason="the PyPI bpy module is not installed (make venv)")
    ext_dir = Path(bpy.utils.user_resource("EXTENSIONS"))
    assert ext_dir.is_relative_to(os.environ["BLENDER_USER_RESOURCES"]), (
        f"bpy was imported before the sandbox was set up: {ext_dir}")
    return bpy


@pytest.fixture(scope="session")
def ext(bpy_mod, tmp_path_factory):
    """Build the pure zip with Blender's builder, install and enable it; the extension module."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import build_extension
    finally:
        sys.path.pop(0)
    out = tmp_path_factory.mktemp("dist")
    zip_path = build_extension.build_pure(str(out))
    bpy = bpy_mod
    result = bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True)
    assert result == {"FINISHED"}
    assert MODULE in bpy.context.preferences.addons.keys()
    mod = sys.modules[MODULE]
    assert Path(mod.__file__).is_relative_to(_SANDBOX)
    yield mod
    shutil.rmtree(_SANDBOX, ignore_errors=True)


@pytest.fixture
def bpy(ext, bpy_mod):
    """A fresh empty scene for each test, with the extension enabled."""
    bpy_mod.ops.wm.read_homefile(use_empty=True)
    assert MODULE in bpy_mod.context.preferences.addons.keys()
    return bpy_mod


def import_obj(bpy, name: str, path: Path | None = None):
    """Import tests/data/NAME.obj (or ``path``) with Blender's OBJ importer, identity axes;
    the new object, selected and active."""
    bpy.ops.object.select_all(action="DESELECT") if bpy.context.view_layer.objects else None
    bpy.ops.wm.obj_import(filepath=str(path or mesh_path(name)), forward_axis="Y",
                          up_axis="Z")
    obj = bpy.context.selected_objects[0]
    bpy.context.view_layer.objects.active = obj
    return obj


def positions(obj) -> np.ndarray:
    """(N, 3) float32 copy of the vertex positions."""
    co = np.empty(len(obj.data.vertices) * 3, dtype=np.float32)
    obj.data.attributes["position"].data.foreach_get("vector", co)
    return co.reshape(-1, 3)


_FIELDS = {
    "FLOAT": ("value", np.float32, 1), "INT": ("value", np.int32, 1),
    "BOOLEAN": ("value", bool, 1), "FLOAT_VECTOR": ("vector", np.float32, 3),
    "FLOAT_COLOR": ("color", np.float32, 4), "BYTE_COLOR": ("color", np.float32, 4),
    "FLOAT2": ("vector", np.float32, 2), "INT8": ("value", np.int32, 1),
    "INT32_2D": ("value", np.int32, 2), "QUATERNION": ("value", np.float32, 4),
}


def snapshot(obj, skip=("position",)) -> dict:
    """Raw bytes of every attribute, vertex-group weight, material slot and shape key."""
    me = obj.data
    snap = {}
    for attr in me.attributes:
        if attr.name in skip:
            continue
        prop, dtype, width = _FIELDS[attr.data_type]
        buf = np.empty(len(attr.data) * width, dtype=dtype)
        attr.data.foreach_get(prop, buf)
        snap[f"attr:{attr.name}:{attr.domain}:{attr.data_type}"] = buf.tobytes()
    for v in me.vertices:  # small test meshes only
        for g in v.groups:
            snap[f"vg:{g.group}:{v.index}"] = np.float32(g.weight).tobytes()
    snap["materials"] = tuple(m.name if m else None for m in me.materials)
    snap["sizes"] = (len(me.vertices), len(me.edges), len(me.polygons), len(me.loops))
    snap["uv_layers"] = tuple(uv.name for uv in me.uv_layers)
    if me.shape_keys is not None:
        for kb in me.shape_keys.key_blocks:
            if kb.name not in skip:
                buf = np.empty(len(kb.data) * 3, dtype=np.float32)
                kb.data.foreach_get("co", buf)
                snap[f"key:{kb.name}"] = buf.tobytes()
    return snap


def mesh_quality(ext, obj) -> np.ndarray:
    """Per-face mean ratio of the object's current positions (the packaged core's definition)."""
    from importlib import import_module
    ops_quality = import_module(f"{MODULE}.operators.mesh.ops_quality")
    return ops_quality.face_quality(obj)
