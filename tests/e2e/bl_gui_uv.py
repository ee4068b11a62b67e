"""UV GUI test, run inside the real Blender under Xvfb (1600x900, window at 0,0):
    blender --window-geometry 0 0 1600 900 uv_input.blend --python bl_gui_uv.py -- ARTIFACT_DIR

In the UV Editing workspace (Edit Mode, the whole mesh selected, UV Sync Selection on), real
X input events do the user's part: 1. click the UV editor sidebar's "EEGT" tab, 2. click the
"Untangle & Smooth UVs" button, 3. Ctrl+Z over the UV editor. Python prepares the view and
reads the UVs (through bmesh: what the UV editor shows) to check them with meshcheck.uv_check
(its own welding and inverted count, not the extension's): no inverted UV face after the
click, border and pinned UVs bit-identical, every UV bit-identical again after Ctrl+Z.
4. Ctrl+Shift+Z: exactly the result again. Screenshots of the UV editor (stretch overlay:
blue = like the 3D face, red = distorted) go to ARTIFACT_DIR: uv_before / uv_after (whole
editor), the README pair uv_readme_before / uv_readme_after (cropped to the UVs, sidebar
closed) and uv_panel_after (the sidebar with the last run's numbers).
Prints E2E-GUI-UV-OK / E2E-GUI-UV-FAIL and exits.
"""
import os
import subprocess
import sys

import bmesh
import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import guikit
import meshcheck
from guikit import check, click, finish, log, probe, shot, to_x11, wait_until, xdo

ART = sys.argv[sys.argv.index("--") + 1]
OBJ = "Tangled"
OP_ID = "UV_OT_eegt_untangle_smooth"


def uv_editor():
    win = bpy.context.window_manager.windows[0]
    area = next(a for a in win.screen.areas if a.type == "IMAGE_EDITOR")
    return win, area, {r.type: r for r in area.regions}


def read_uv():
    """(uv (L, 2), pins (L,), faces as loop lists, corner vertices) of the edit mesh, in
    loop order (a few thousand loops: a Python loop is fine in a test)."""
    me = bpy.data.objects[OBJ].data  # looked up again: undo replaces the datablock
    bm = bmesh.from_edit_mesh(me)
    layer = bm.loops.layers.uv.active
    uv, pins, faces, verts = [], [], [], []
    for f in bm.faces:
        faces.append(list(range(len(uv), len(uv) + len(f.loops))))
        for lp in f.loops:
            uv.append(tuple(lp[layer].uv))
            pins.append(bool(lp[layer].pin_uv))
            verts.append(lp.vert.index)
    return np.array(uv), np.array(pins), faces, np.array(verts)


def last_op():
    ops = bpy.context.window_manager.operators
    return ops[-1] if len(ops) else None


def steps():
    # Prepare (not what is tested): the UV Editing workspace, Edit Mode, everything selected
    # with UV Sync Selection, the sidebar open, the stretch overlay on, the UVs framed.
    win = bpy.context.window_manager.windows[0]
    win.workspace = bpy.data.workspaces["UV Editing"]
    yield 1.0
    ob = bpy.data.objects[OBJ]
    bpy.context.view_layer.objects.active = ob
    win, area, rg = uv_editor()
    with bpy.context.temp_override(window=win, area=area, region=rg["WINDOW"]):
        if bpy.context.mode != "EDIT_MESH":
            bpy.ops.object.mode_set(mode="EDIT")
        bpy.context.scene.tool_settings.use_uv_select_sync = True
        bpy.ops.mesh.select_all(action="SELECT")
    space = area.spaces.active
    space.show_region_ui = True
    space.uv_editor.show_stretch = True
    space.uv_editor.display_stretch_type = "ANGLE"
    yield 0.5
    with bpy.context.temp_override(window=win, area=area, region=rg["WINDOW"]):
        bpy.ops.image.view_all(fit_view=True)
    area.tag_redraw()
    yield 1.0
    check(bpy.context.mode == "EDIT_MESH", f"not in Edit Mode ({bpy.context.mode})")
    uv0, pins, faces, verts = read_uv()
    c0 = meshcheck.uv_check(uv0, faces, verts)
    check(c0["n_inverted"] > 0 and c0["n_flipped"] > 0, f"the input UVs are not tangled: {c0}")
    check(pins.sum() > 0, "no pinned UVs in the input")
    shot("uv_before", rg["WINDOW"])
    log(f"before: {c0['n_flipped']} flipped, {c0['n_inverted']} inverted UV faces, "
        f"{int(pins.sum())} pinned loops")

    # 1. the EEGT tab of the UV editor's sidebar
    win, area, rg = uv_editor()
    ui = rg["UI"]
    clicks = yield from guikit.open_tab(ui, "EEGT")
    log(f"EEGT tab open after {clicks} clicks on the tab strip")
    yield 0.5
    shot("uv_panel", ui)

    # 2. the Untangle & Smooth UVs button (found by its Python command), a real click
    bx = ui.x + (ui.width - 24) // 2
    pts = [to_x11(bx, wy) for wy in range(ui.y + ui.height - 30, ui.y + 10, -10)]
    pt, _ = yield from probe(pts, "ctrl+c", lambda t: "uv.eegt_untangle_smooth" in t)
    check(pt, "no button with bpy.ops.uv.eegt_untangle_smooth found in the EEGT tab")
    n_ops = len(bpy.context.window_manager.operators)
    yield from click(pt)
    log(f"clicked Untangle & Smooth UVs at {pt}")
    done = yield from wait_until(
        lambda: len(bpy.context.window_manager.operators) > n_ops
        and last_op().bl_idname == OP_ID, 120)
    check(done, "the operator did not finish (no new registered operator) within 120 s")
    yield 0.5
    check(bpy.context.mode == "EDIT_MESH", f"left Edit Mode ({bpy.context.mode})")
    uv1, pins1, faces1, verts1 = read_uv()
    check(np.array_equal(verts1, verts) and np.array_equal(pins1, pins), "topology or pins "
                                                                          "changed")
    c1 = meshcheck.uv_check(uv1, faces1, verts1)
    check(c1["n_inverted"] == 0 and c1["n_flipped"] == 0, f"after the click: {c1['n_flipped']} "
                                                          f"flipped, {c1['n_inverted']} inverted")
    check(c1["orientation"] == c0["orientation"], "the island's orientation changed")
    border = c0["border_loops"]
    check(len(border) > 0 and np.array_equal(uv1[border], uv0[border]),
          "UVs on the island border moved")
    check(np.array_equal(uv1[pins], uv0[pins]), "pinned UVs moved")
    moved = np.any(uv1 != uv0, axis=1)
    check(moved.sum() > len(uv0) // 2, f"only {int(moved.sum())} loops moved")
    check(c1["n_uv_vertices"] == c0["n_uv_vertices"], "UV vertices were merged or split")
    area.tag_redraw()
    yield 1.0
    win, area, rg = uv_editor()
    shot("uv_after", rg["WINDOW"])
    log(f"after the click: 0 flipped, 0 inverted; border and {int(pins.sum())} pinned loops "
        f"exact; {int(moved.sum())} loops moved")

    # 3. Ctrl+Z over the UV editor: every UV exactly as before
    w = rg["WINDOW"]
    xdo("mousemove", *to_x11(w.x + w.width // 2, w.y + w.height // 2))
    yield 0.2
    xdo("key", "ctrl+z")
    back = yield from wait_until(lambda: np.array_equal(read_uv()[0], uv0), 30)
    now = read_uv()[0]
    check(back, f"Ctrl+Z: {int(np.any(now != uv0, axis=1).sum())} UVs not back, max error "
                f"{float(np.abs(now - uv0).max()):.3e}")
    log("Ctrl+Z: every UV exactly back")

    # README pair, sidebar closed: the input (now), then Ctrl+Shift+Z (exactly the result)
    space = area.spaces.active
    space.show_region_ui = space.show_region_toolbar = False
    area.tag_redraw()
    yield 1.0
    box = np.concatenate([uv0, uv1]).min(axis=0), np.concatenate([uv0, uv1]).max(axis=0)
    shot_uv("uv_readme_before", box)
    xdo("key", "ctrl+shift+z")
    again = yield from wait_until(lambda: np.array_equal(read_uv()[0], uv1), 30)
    check(again, "Ctrl+Shift+Z did not restore the result exactly")
    area.tag_redraw()
    yield 1.0
    shot_uv("uv_readme_after", box)
    space.show_region_ui = True
    area.tag_redraw()
    yield 1.0
    win, area, rg = uv_editor()
    shot("uv_panel_after", rg["UI"])
    log("Ctrl+Shift+Z: the result exactly back")
    finish(True, f"click: flipped {c0['n_flipped']} -> 0, inverted {c0['n_inverted']} -> 0, "
                 f"border and pins exact; Ctrl+Z exact on {len(uv0)} UVs; redo exact")


def shot_uv(name, box, margin=12, width=380):
    """Screenshot of the UV editor cropped to the UV box (lo, hi), resized to `width`."""
    w = uv_editor()[2]["WINDOW"]
    (u0, v0), (u1, v1) = box
    x0, y0 = w.view2d.view_to_region(float(u0), float(v0), clip=False)
    x1, y1 = w.view2d.view_to_region(float(u1), float(v1), clip=False)
    left, top = to_x11(w.x + x0 - margin, w.y + y1 + margin)
    right, bottom = to_x11(w.x + x1 + margin, w.y + y0 - margin)
    subprocess.run(["import", "-window", "root", "-crop",
                    f"{right - left}x{bottom - top}+{left}+{top}", "-resize", f"{width}x",
                    "-depth", "8", "-colors", "256", f"{ART}/{name}.png"], check=True, timeout=30)


guikit.start(steps(), ART, "E2E-GUI-UV", watchdog_s=150.0)
