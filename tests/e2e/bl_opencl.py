"""OpenCL inside the real Blender (Debian's python3-pyopencl + pocl-opencl-icd in the root):
    blender -b --python-exit-code 1 --python bl_opencl.py -- MESH.obj RESULT.json MODE
MODE "device": pyopencl must see a device; the operator run with backend OPENCL must give the
NumPy result (to 1e-6 of the mesh size, valid mesh) and name OpenCL as its backend, or, while
the OpenCL backend does not exist yet, fall back with a message naming NumPy and give the NumPy
result bit for bit. MODE "nodevice" (run with OCL_ICD_VENDORS pointing at an empty folder):
OpenCL is asked for, no device exists: the run must fall back to NumPy, say so, and give the
NumPy result bit for bit. Raises on failure; writes a summary to RESULT.json.
"""
import importlib.util
import json
import os
import sys

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import meshcheck

mesh_path, result_path, mode = sys.argv[sys.argv.index("--") + 1:][:3]
summary = {"mode": mode}

# What pyopencl sees inside Blender's Python.
try:
    import pyopencl as cl

    devices = [f"{p.name}: {d.name}" for p in cl.get_platforms() for d in p.get_devices()]
except Exception as exc:  # no platform at all raises (clGetPlatformIDs -1001)
    devices = []
    summary["pyopencl_error"] = str(exc).splitlines()[0]
summary["devices"] = devices
if mode == "device":
    assert devices, f"pyopencl sees no OpenCL device inside Blender: {summary}"
else:
    assert not devices, f"expected no OpenCL device with OCL_ICD_VENDORS empty: {devices}"

bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.wm.obj_import(filepath=mesh_path)
ob = bpy.context.selected_objects[0]
bpy.context.view_layer.objects.active = ob
me = ob.data
start = np.empty(len(me.vertices) * 3, dtype=np.float32)
me.attributes["position"].data.foreach_get("vector", start)
faces = [np.array(p.vertices) for p in me.polygons]
op_props = bpy.ops.mesh.eegt_untangle_smooth.get_rna_type().properties.keys()


def run(backend):
    """Run the operator from the original positions; return (positions, backend string)."""
    me.attributes["position"].data.foreach_set("vector", start)
    me.update()
    bpy.context.scene.eegt_settings.backend = backend
    kwargs = {"backend": backend} if "backend" in op_props else {}
    res = bpy.ops.mesh.eegt_untangle_smooth(**kwargs)
    assert res == {"FINISHED"}, f"{backend}: operator returned {res}"
    co = np.empty_like(start)
    me.attributes["position"].data.foreach_get("vector", co)
    return co.reshape(-1, 3), ob.eegt_last_run.backend


ref, ref_backend = run("NUMPY")
assert ref_backend == "numpy", f"NUMPY run says backend {ref_backend!r}"
assert meshcheck.stats(ref.astype(np.float64), faces)["n_inverted"] == 0, "NumPy result tangled"
got, backend = run("OPENCL")
summary["backend"] = backend
fell_back = backend.startswith("numpy")
# Once the extension ships an OpenCL engine, a device being present means it must be used.
pkg = bpy.types.MESH_OT_eegt_untangle_smooth.__module__.split(".operators")[0]
engine_spec = importlib.util.find_spec(f"{pkg}.core.eegt.engine_opencl")
summary["has_opencl_engine"] = engine_spec is not None
if mode == "device" and summary["has_opencl_engine"]:
    assert not fell_back, f"OpenCL device and engine present, but it fell back: {backend!r}"
if fell_back:
    # Fallback: must say so, naming NumPy, and be exactly the NumPy result.
    assert "NumPy" in backend, f"fallback without a message naming NumPy: {backend!r}"
    assert np.array_equal(got, ref), "fallback result differs from the NumPy result"
    summary["summary"] = f"{mode}: fell back to NumPy, identical result; message: {backend}"
else:
    assert mode == "device", f"backend {backend!r} without any OpenCL device"
    size = float(np.ptp(ref, axis=0).max())
    err = float(np.abs(got - ref).max()) / size
    inv = meshcheck.stats(got.astype(np.float64), faces)["n_inverted"]
    assert inv == 0, f"OpenCL result has {inv} inverted faces"
    assert err < 1e-6, f"OpenCL differs from NumPy by {err:.3e} (relative to the mesh size)"
    # (positions are float32 in Blender: differences below ~1e-7 vanish when written back)
    summary["summary"] = (f"OpenCL ({backend}) = NumPy to {err:.1e} of the mesh size after "
                          f"the float32 write-back; {devices[0]}")
with open(result_path, "w") as fh:
    json.dump(summary, fh, indent=1)
print("E2E-OPENCL", summary["summary"])
