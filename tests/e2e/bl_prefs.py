"""Run inside the real Blender (background, sandboxed user dirs, NOT factory start-up):
check the installed extension is enabled and loaded, then turn the splash screen off for the
GUI test and save the preferences. Prints E2E-PREFS-OK on success, raises otherwise."""
import addon_utils
import bpy

mod = "bl_ext.user_default.eegt_blender"
prefs = bpy.context.preferences
assert mod in prefs.addons, f"{mod} not enabled; enabled: {list(prefs.addons.keys())}"
loaded, enabled = addon_utils.check(mod)
assert loaded and enabled, f"{mod}: loaded={loaded} enabled={enabled}"
assert hasattr(bpy.types, "MESH_OT_eegt_untangle_smooth"), "operator not registered"
prefs.view.show_splash = False
prefs.use_preferences_save = True
bpy.ops.wm.save_userpref()
print("E2E-PREFS-OK")
