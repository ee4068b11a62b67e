"""Live Untangle GUI test in the 3D View, run inside the real Blender under Xvfb (1600x900,
window at 0,0):
    blender --window-geometry 0 0 1600 900 live_input.blend --python bl_gui_live3d.py -- ART

The "Live" Grid of bl_make_live_blend.py (in the XY plane) gets three interior vertices
pinned (the ``eegt_pinned`` vertex group: set-up, not under test), Edit Mode, top view. Real
X input does the user's part: hover the vertex nearest the Grid's centre, press the shortcut
Ctrl+Alt+L, press the left button, drag six cells in three moves (faster than the fan can
follow: the frames escalate or start from the carried guess), hold still until the last
frame is neither tangled nor smoothing, release. Checked on the edit mesh's positions
(BMesh: what the viewport shows), with meshcheck's own projection and inverted count: no
inverted face, every border vertex and the pinned ones bit-identical, no vertex off the
plane, the grabbed vertex at the drop point; then Ctrl+Z puts every position back bit for
bit. Screenshots: live3d_before, live3d_during, live3d_after.
Prints E2E-GUI-LIVE3D-OK / E2E-GUI-LIVE3D-FAIL and exits.
"""
import os
import sys

import bmesh
import bpy
import numpy as np
from bpy_extras.view3d_utils import location_3d_to_region_2d
from mathutils import Vector

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
OP_ID = "MESH_OT_eegt_live_untangle"
DRAG = np.array([0.5, 0.34, 0.0])  # the drop point's offset: six cells right, four up
PIN_AT = [(-0.5, -0.5), (0.45, -0.3), (-0.3, 0.6)]  # the vertices nearest to these go into
#                                                    eegt_pinned (away from the drag)


def view3d():
    win = bpy.context.window_manager.windows[0]
    area = max((a for a in win.screen.areas if a.type == "VIEW_3D"),
               key=lambda a: a.width * a.height)
    return win, area, {r.type: r for r in area.regions}


def positions():
    """The vertex positions (float32, as stored) and faces: the edit mesh's (BMesh: what the
    viewport shows) in Edit Mode, else the mesh's (an undo step may leave Edit Mode)."""
    ob = bpy.data.objects[OBJ]
    if ob.mode != "EDIT":
        me = ob.data
        co = np.empty(len(me.vertices) * 3, dtype=np.float32)
        me.vertices.foreach_get("co", co)
        return co.reshape(-1, 3), [np.array(f.vertices) for f in me.polygons], None
    bm = bmesh.from_edit_mesh(ob.data)
    bm.verts.ensure_lookup_table()
    co = np.array([v.co[:] for v in bm.verts], dtype=np.float32)
    faces = [np.array([v.index for v in f.verts]) for f in bm.faces]
    border = np.array([v.is_boundary for v in bm.verts])
    return co, faces, border


def screen_of(w, rv3d, co):
    ob = bpy.data.objects[OBJ]
    p = location_3d_to_region_2d(w, rv3d, ob.matrix_world @ Vector(tuple(co)))
    return to_x11(w.x + p.x, w.y + p.y)


def steps():
    win = bpy.context.window_manager.windows[0]
    win.workspace = bpy.data.workspaces["Layout"]
    yield 1.0
    ob = bpy.data.objects[OBJ]
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)
    win, area, rg = view3d()
    with bpy.context.temp_override(window=win, area=area, region=rg["WINDOW"]):
        if bpy.context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        xy = np.array([v.co[:2] for v in ob.data.vertices])
        pinned = [int(np.argmin(np.hypot(*(xy - at).T))) for at in PIN_AT]
        group = ob.vertex_groups.get("eegt_pinned") or ob.vertex_groups.new(name="eegt_pinned")
        group.add(pinned, 1.0, "REPLACE")
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        bpy.ops.view3d.view_axis(type="TOP")
        bpy.ops.view3d.view_selected()
        bpy.ops.mesh.select_all(action="DESELECT")  # only the vertex under the cursor moves
    space = area.spaces.active
    space.show_region_ui = False
    space.overlay.show_face_orientation = True
    yield 1.0
    co0, faces, border = positions()
    s0 = meshcheck.stats(co0.astype(np.float64), faces)
    check(s0["n_inverted"] == 0 and border.any() and not border[pinned].any(),
          f"input: {s0['n_inverted']} inverted, {int(border.sum())} border vertices, "
          f"pins on the border: {border[pinned]}")
    grab = int(np.argmin(np.hypot(co0[:, 0], co0[:, 1])))
    start = co0[grab].astype(np.float64)
    w, rv3d = rg["WINDOW"], space.region_3d
    a, b = screen_of(w, rv3d, start), screen_of(w, rv3d, start + DRAG)
    check(abs(b[0] - a[0]) > 60, f"the view is too small for the drag: {a} -> {b}")
    area.tag_redraw()
    yield 0.5
    shot("live3d_before", w)

    # 1. shortcut, press, drag, hold, release
    xdo("mousemove", *a)
    yield 0.4
    xdo("key", "ctrl+alt+l")
    yield 0.5
    xdo("mousedown", "1")
    yield 0.3
    for k in range(1, 4):  # three cells a move: faster than the fan can follow
        xdo("mousemove", *screen_of(w, rv3d, start + DRAG * k / 3))
        yield 0.12
    shot("live3d_during", w)
    check(len(live_frames()) > 0, "no live frame ran during the drag")
    tangled = sum(f.status == "tangled" for f, _ in live_frames())
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
    co1, faces1, _ = positions()
    s1 = meshcheck.stats(co1.astype(np.float64), faces1)
    check(s1["n_inverted"] == 0, f"after the drag: {s1['n_inverted']} inverted faces")
    check(np.array_equal(co1[border], co0[border]), "border vertices moved")
    check(np.array_equal(co1[pinned], co0[pinned]), "eegt_pinned vertices moved")
    check(np.array_equal(co1[:, 2], co0[:, 2]), "a vertex left the Grid's plane")
    # the drop point in pixels back to the plane: within two pixels' worth of the cursor
    err = float(np.abs(co1[grab, :2].astype(np.float64) - (start + DRAG)[:2]).max())
    check(err < 0.03, f"the grabbed vertex is {err:.3f} off the drop point")
    n_moved = int(np.any(co1 != co0, axis=1).sum())
    check(n_moved > 8, f"only {n_moved} vertices moved")
    area.tag_redraw()
    yield 0.8
    shot("live3d_after", w)
    log(f"drag: {len(live_frames())} frames ({tangled} tangled), 0 inverted, border and pins "
        f"exact, {n_moved} vertices moved, drop point within {err:.4f}")

    # 2. Ctrl+Z: every position back
    xdo("key", "ctrl+z")
    back = yield from wait_until(lambda: positions()[0].tobytes() == co0.tobytes(), 30)
    check(back, "Ctrl+Z did not restore every vertex bit for bit")
    finish(True, f"drag: 0 inverted ({tangled} tangled frames on the way), border and pins "
                 f"exact, drop within {err:.4f}; Ctrl+Z exact on {len(co0)} vertices")


guikit.start(steps(), ART, "E2E-GUI-LIVE3D", watchdog_s=200.0)
