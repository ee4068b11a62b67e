"""Run inside Blender (background, factory start-up): import a tangled OBJ and save a .blend
with it selected and active, for the GUI test. Args after --: INPUT.obj OUTPUT.blend"""
import sys

import bpy

inp, out = sys.argv[sys.argv.index("--") + 1:][:2]
for ob in list(bpy.data.objects):  # drop the default cube, camera and light
    bpy.data.objects.remove(ob)
bpy.ops.wm.obj_import(filepath=inp)
ob = bpy.context.selected_objects[0]
ob.name = "Tangled"
ob.rotation_euler = (0.0, 0.0, 0.0)  # the OBJ importer turns Y-up into Z-up: lie flat
bpy.context.view_layer.objects.active = ob
ob.select_set(True)
bpy.ops.wm.save_as_mainfile(filepath=out)
print("saved", out, len(ob.data.vertices), "vertices")
