"""Run inside Blender (background, factory start-up): make the tangled UV test scene with
bench.uv_assets (a UV sphere cut along a meridian, unwrapped, interior UVs jittered, a few
UVs pinned) and save it, selected and active. Args after --: REPO OUTPUT.blend [SEED]
(the jitter's seed, default 0)."""
import sys

import bpy

args = sys.argv[sys.argv.index("--") + 1:]
repo, out = args[:2]
seed = int(args[2]) if len(args) > 2 else 0
sys.path.insert(0, repo)
from bench import uv_assets  # noqa: E402

for ob in list(bpy.data.objects):  # drop the default cube, camera and light
    bpy.data.objects.remove(ob)
ob = uv_assets.make_asset(bpy, "sphere")
uv_assets.tangle(bpy, ob, "jitter", seed=seed)
pins = uv_assets.pin_some(ob, fraction=0.02, rings=None)
ob.name = "Tangled"
bpy.context.view_layer.objects.active = ob
ob.select_set(True)
bpy.ops.wm.save_as_mainfile(filepath=out)
print("saved", out, len(ob.data.polygons), "faces,", int(pins.sum()), "pinned UVs")
