"""Live Untangle GUI test, run inside the real Blender under Xvfb (1600x900, window at 0,0):
    blender --window-geometry 0 0 1600 900 live_input.blend --python bl_gui_live.py -- ART

In the UV Editing workspace (Edit Mode, everything selected, UV Sync Selection on), real X
input does the user's part: 1. hover a UV vertex near the island's centre, press the
shortcut Ctrl+Alt+L, press the left button, drag across the island in steps (the fan around
the vertex folds), hold still until the header's inverted count is 0, release; the UVs (read
through bmesh: what the editor shows) are checked with meshcheck.uv_check (its own welding
and inverted count): no inverted face, the island border and the pinned UVs bit-identical,
the vertex where it was dropped; 2. Ctrl+Z: every UV bit-identical to before; 3. the
shortcut, press, drag, Esc before the release: every UV bit-identical, no operator
registered. Screenshots: live_before, live_during (mid-drag), live_after.
Prints E2E-GUI-LIVE-OK / E2E-GUI-LIVE-FAIL and exits.
"""
import os
import sys

import bmesh
import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import guikit
import meshcheck
from guikit import (
    check,
    finish,
    live_frames,
    live_settled,
    log,
    n_ops,
    shot,
    to_x11,
    wait_until,
    xdo,
)

ART = sys.argv[sys.argv.index("--") + 1]
OBJ = "Live"
OP_ID = "UV_OT_eegt_live_untangle"
DRAG = np.array([0.24, 0.17])  # UV offset of the drag: about six cells
READ = {}


def uv_editor():
    win = bpy.context.window_manager.windows[0]
    area = next(a for a in win.screen.areas if a.type == "IMAGE_EDITOR")
    return win, area, {r.type: r for r in area.regions}


def read_uv():
    me = bpy.data.objects[OBJ].data
    bm = bmesh.from_edit_mesh(me)
    layer = bm.loops.layers.uv.active
    uv, pins, faces, verts, rim = [], [], [], [], []
    for f in bm.faces:
        faces.append(list(range(len(uv), len(uv) + len(f.loops))))
        for lp in f.loops:
            uv.append(tuple(lp[layer].uv))
            pins.append(bool(lp[layer].pin_uv))
            verts.append(lp.vert.index)
            rim.append(lp.vert.is_boundary)
    READ["rim"] = np.array(rim)  # loops of the mesh border: the island's border (no seams)
    return np.array(uv, dtype=np.float32), np.array(pins), faces, np.array(verts)


def screen_of(w, uv):
    x, y = w.view2d.view_to_region(float(uv[0]), float(uv[1]), clip=False)
    return to_x11(w.x + x, w.y + y)


def drag_to(w, start, n=12):
    for k in range(1, n + 1):
        xdo("mousemove", *screen_of(w, start + DRAG * k / n))
        yield 0.12


def steps():
    win = bpy.context.window_manager.windows[0]
    win.workspace = bpy.data.workspaces["UV Editing"]
    yield 1.0
    bpy.context.view_layer.objects.active = bpy.data.objects[OBJ]
    win, area, rg = uv_editor()
    with bpy.context.temp_override(window=win, area=area, region=rg["WINDOW"]):
        if bpy.context.mode != "EDIT_MESH":
            bpy.ops.object.mode_set(mode="EDIT")
        bpy.context.scene.tool_settings.use_uv_select_sync = True
        bpy.ops.mesh.select_all(action="SELECT")
    area.spaces.active.show_region_ui = False
    yield 0.5
    with bpy.context.temp_override(window=win, area=area, region=rg["WINDOW"]):
        bpy.ops.image.view_all(fit_view=True)
    area.tag_redraw()
    yield 1.0
    uv0, pins, faces, verts = read_uv()
    c0 = meshcheck.uv_check(uv0, faces, verts)
    check(c0["n_inverted"] == 0 and pins.sum() > 0, f"input: {c0['n_inverted']} inverted, "
                                                    f"{int(pins.sum())} pins")
    border = READ["rim"]  # (meshcheck's own border splits the Grid's one-ulp-apart UVs)
    start = np.array([0.5, 0.5])
    near = np.argmin(np.hypot(*(uv0 - start).T))
    start = uv0[near].astype(np.float64)
    grabbed = np.all(uv0 == uv0[near], axis=1)
    w = uv_editor()[2]["WINDOW"]
    shot("live_before", w)

    # 1. shortcut, press, drag, hold, release
    xdo("mousemove", *screen_of(w, start))
    yield 0.4
    xdo("key", "ctrl+alt+l")
    yield 0.5
    xdo("mousedown", "1")
    yield 0.3
    yield from drag_to(w, start)
    shot("live_during", w)
    count = len(live_frames())
    check(count > 0, "no live frame ran during the drag")
    ok = yield from wait_until(lambda: live_settled(0), 60)
    last = live_frames()[-1][0] if live_frames() else None
    check(ok, f"still tangled 60 s after the drag: {last}")
    before_release = n_ops()
    xdo("mouseup", "1")
    done = yield from wait_until(lambda: n_ops() > before_release
                                 and bpy.context.window_manager.operators[-1].bl_idname
                                 == OP_ID, 20)
    check(done, "the release registered no Live Untangle operator")
    yield 0.5
    uv1, _, faces1, verts1 = read_uv()
    c1 = meshcheck.uv_check(uv1, faces1, verts1)
    check(c1["n_inverted"] == 0 and c1["n_flipped"] == 0,
          f"after the drag: {c1['n_flipped']} flipped, {c1['n_inverted']} inverted")
    check(np.array_equal(uv1[border], uv0[border]), "UVs on the island border moved")
    check(np.array_equal(uv1[pins], uv0[pins]), "pinned UVs moved")
    moved = uv1[grabbed].astype(np.float64) - uv0[grabbed]
    err = float(np.abs(moved - DRAG).max())
    check(err < 0.02, f"the grabbed vertex is {err:.3f} off the drop point")
    n_moved = int(np.any(uv1 != uv0, axis=1).sum())
    check(n_moved > 8 * grabbed.sum(), f"only {n_moved} loops moved")
    area.tag_redraw()
    yield 0.8
    shot("live_after", uv_editor()[2]["WINDOW"])
    log(f"drag: {len(live_frames())} frames, 0 inverted, border and {int(pins.sum())} pinned "
        f"loops exact, {n_moved} loops moved, drop point within {err:.4f}")

    # 2. Ctrl+Z: every UV back
    xdo("key", "ctrl+z")
    back = yield from wait_until(lambda: read_uv()[0].tobytes() == uv0.tobytes(), 30)
    check(back, "Ctrl+Z did not restore every UV bit for bit")
    log("Ctrl+Z: every UV exactly back")

    # 3. Esc in the middle of a drag
    w = uv_editor()[2]["WINDOW"]
    xdo("mousemove", *screen_of(w, start))
    yield 0.4
    xdo("key", "ctrl+alt+l")
    yield 0.5
    xdo("mousedown", "1")
    yield 0.3
    yield from drag_to(w, start, 6)
    check(len(live_frames()) > 0, "no live frame ran during the second drag")
    mid = read_uv()[0]
    check(mid.tobytes() != uv0.tobytes(), "the second drag changed nothing before Esc")
    ops_before = n_ops()
    xdo("key", "Escape")
    yield 0.5
    xdo("mouseup", "1")
    restored = yield from wait_until(lambda: read_uv()[0].tobytes() == uv0.tobytes(), 20)
    check(restored, "Esc did not restore every UV bit for bit")
    yield 0.5
    check(n_ops() == ops_before, "Esc registered an operator")
    finish(True, f"drag: 0 inverted, border and pins exact, drop within {err:.4f}; Ctrl+Z "
                 f"exact on {len(uv0)} UVs; Esc mid-drag exact")


guikit.start(steps(), ART, "E2E-GUI-LIVE", watchdog_s=200.0)
