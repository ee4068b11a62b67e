# SPDX-License-Identifier: GPL-3.0-or-later
"""Live Untangle: modal tools of the UV editor (``uv.eegt_live_untangle``) and the 3D View's
Edit Mode (``mesh.eegt_live_untangle``).

Press the left mouse button on a vertex (none under the cursor: the selection is grabbed)
and drag: a timer runs one frame at a time with the latest cursor position (mouse moves that
arrive meanwhile only update that position, so a slow frame skips to where the cursor is,
never queues), each frame (core and writes) kept under ``core.run.live.FRAME_BUDGET``; the
drags keep the cursor within ``core.run.live.cursor_bounds``. Release or Enter keeps the
result (one undo step); Esc or the right button puts every value back.
"""

from __future__ import annotations

import time
from typing import Any

import bpy
import numpy as np
from bpy_extras import view3d_utils
from mathutils import Vector, geometry

from ...core.run import (
    FINISH_BUDGET,
    FINISH_GO_ON,
    FINISH_KEEP,
    FINISH_LIMIT,
    RestFrames,
)
from ..ui import props
from ..uv import uv_props
from .drag import MeshDrag, UVDrag

TICK = 1.0 / 60.0  # the timer's period (s): a frame runs on the first tick after a move
PICK_PIXELS = 12.0  # a vertex within this many pixels of the cursor is grabbed

LAST_FRAMES: list[Any] = []  # the frames of the last drag (read by the tests)


def _window_region(area: bpy.types.Area) -> bpy.types.Region | None:
    return next((r for r in area.regions if r.type == "WINDOW"), None)


def status_text(frame: Any, finishing: float | None = None) -> str:
    """The header line of a running drag (``finishing``: seconds since a release began to
    finish the repair)."""
    if frame is None:
        return "Live Untangle: press the left mouse button on a vertex and drag (Esc: cancel)"
    s = frame.stats
    if finishing is not None:
        what = "the vertex on its way to the cursor" if frame.pull_iterations else \
            f"{s.n_inverted} faces still inverted"
        return f"Live Untangle: finishing, {what}, {finishing:.1f} s  |  Esc: cancel the drag"
    held = "  |  the layout holds the vertex back from the cursor" if frame.held_back else ""
    return (f"Live Untangle: inverted {s.n_inverted}, worst {s.q_min:.3f}, mean "
            f"{s.q_avg:.3f}{held}  |  release / Enter: apply, Esc / right button: cancel")


class _LiveModal:
    """The modal loop shared by both tools; subclasses make the drag and map the cursor."""

    _drag: Any = None

    def _start(self, context: bpy.types.Context, event: bpy.types.Event) -> None:
        raise NotImplementedError

    def _cursor(self, event: bpy.types.Event) -> Any:
        raise NotImplementedError

    def invoke(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        area = context.area
        self._region = _window_region(area) if area is not None else None
        if self._region is None:
            self.report({"WARNING"}, "Live Untangle needs an editor's main region")
            return {"CANCELLED"}
        try:
            self._params = props.params_from(context.scene.eegt_settings)
        except ValueError as exc:
            self.report({"WARNING"}, str(exc))
            return {"CANCELLED"}
        self._area, self._drag, self._at, self._pending = area, None, None, False
        self._rest = RestFrames()  # the frames run with the cursor still
        self._finish_from: float | None = None  # perf_counter when a release began finishing
        LAST_FRAMES.clear()
        wm = context.window_manager
        self._timer = wm.event_timer_add(TICK, window=context.window)
        wm.modal_handler_add(self)
        area.header_text_set(status_text(None))
        if event.type == "LEFTMOUSE" and event.value == "PRESS":
            return self._press(context, event)
        return {"RUNNING_MODAL"}

    def _press(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        try:
            self._start(context, event)
        except ValueError as exc:
            self.report({"WARNING"}, str(exc).splitlines()[0])
            return self._end(context, {"CANCELLED"})
        self._at, self._pending = self._cursor(event), True
        return {"RUNNING_MODAL"}

    def _end(self, context: bpy.types.Context, result: set[str]) -> set[str]:
        context.window_manager.event_timer_remove(self._timer)
        self._area.header_text_set(None)
        self._area.tag_redraw()
        return result

    def _frame(self) -> None:
        if self._finish_from is not None:
            frame = self._drag.step(None, budget=FINISH_BUDGET)
        else:
            frame = self._drag.step(self._at if self._pending else None)
        LAST_FRAMES.append((frame, self._drag.times))
        self._rest.after(frame, moved=self._pending)
        self._pending = False
        since = None if self._finish_from is None else time.perf_counter() - self._finish_from
        self._area.header_text_set(status_text(frame, since))
        self._area.tag_redraw()

    def _release(self, context: bpy.types.Context) -> set[str]:
        """Release or Enter (and each frame after one that goes on finishing): keep the
        result when nothing is left to open (one undo step), go on with frames while the
        escalation opens a fold or the rest's pull brings the vertex on; when it cannot,
        the one-shot repair with the grabbed vertices let go (``LiveSession.released``),
        else every value back (warned)."""
        late = self._finish_from is not None and \
            time.perf_counter() - self._finish_from > FINISH_LIMIT
        what = self._drag.session.finishing(self._drag.frame, out_of_time=late)
        if what == FINISH_KEEP:
            return self._end(context, {"FINISHED"})
        if what == FINISH_GO_ON:
            if self._finish_from is None:
                self._finish_from = time.perf_counter()
                self._area.header_text_set(status_text(self._drag.frame, 0.0))
            return {"RUNNING_MODAL"}
        kept = self._drag.session.released(self._drag.frame.points)
        if kept is not None:  # the grabbed vertices let go: the repair opens the fold
            self._drag.write_points(kept)
            self.report({"INFO"}, "Live Untangle let the grabbed vertices move to open the "
                        "fold (with them at the cursor it stayed folded)")
            return self._end(context, {"FINISHED"})
        self._drag.restore()
        self.report({"WARNING"}, "Live Untangle could not open the fold: every value put "
                    "back (nothing kept)")
        return self._end(context, {"CANCELLED"})

    def _frame_or_restore(self) -> bool:
        """Run a frame; False when the mesh cannot take it (every value put back, warned)."""
        try:
            self._frame()
        except ValueError as exc:
            self._drag.restore()
            self.report({"WARNING"}, str(exc).splitlines()[0])
            return False
        return True

    def _busy(self) -> bool:
        """Whether the mesh may still change with the cursor still (`RestFrames`)."""
        return self._rest.busy(self._drag.frame)

    def modal(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        kind, value = event.type, event.value
        if kind in {"ESC", "RIGHTMOUSE"} and value == "PRESS":
            if self._drag is not None:
                self._drag.restore()
            return self._end(context, {"CANCELLED"})
        if self._finish_from is not None:  # finishing the repair: frames until it is done
            if kind == "TIMER":
                if not self._frame_or_restore():
                    return self._end(context, {"CANCELLED"})
                return self._release(context)
            return {"RUNNING_MODAL"}
        if (kind in {"RET", "NUMPAD_ENTER"} and value == "PRESS") or \
                (kind == "LEFTMOUSE" and value == "RELEASE" and self._drag is not None):
            if self._drag is None:
                return self._end(context, {"CANCELLED"})
            if self._pending and not self._frame_or_restore():
                return self._end(context, {"CANCELLED"})
            return self._release(context)
        if kind == "LEFTMOUSE" and value == "PRESS" and self._drag is None:
            return self._press(context, event)
        if kind in {"MOUSEMOVE", "INBETWEEN_MOUSEMOVE"} and self._drag is not None:
            self._at, self._pending = self._cursor(event), True
            return {"RUNNING_MODAL"}
        if kind == "TIMER":  # ours or another: either way a chance to run a frame
            if self._drag is not None and (self._pending or self._busy()) and \
                    not self._frame_or_restore():
                return self._end(context, {"CANCELLED"})
            return {"RUNNING_MODAL"}
        if kind in {"MIDDLEMOUSE", "WHEELUPMOUSE", "WHEELDOWNMOUSE", "TRACKPADPAN",
                    "TRACKPADZOOM"}:
            return {"PASS_THROUGH"}
        return {"RUNNING_MODAL"}


def _uv_annotations() -> dict[str, Any]:
    return uv_props.option_annotations({"SKIP_SAVE"})


class UV_OT_eegt_live_untangle(_LiveModal, bpy.types.Operator):
    """Drag a UV vertex (or the selection): the rest of its island untangles and smooths live (EEGT). Release or Enter applies, Esc or right-click cancels"""  # noqa: E501

    bl_idname = "uv.eegt_live_untangle"
    bl_label = "Live Untangle"
    bl_options = {"REGISTER", "UNDO", "BLOCKING"}  # noqa: RUF012
    __annotations__ = _uv_annotations()

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        if context.mode != "EDIT_MESH" or context.edit_object is None:
            cls.poll_message_set("Needs mesh Edit Mode (UV editing)")
            return False
        return context.area is not None and context.area.type == "IMAGE_EDITOR"

    def _uv_at(self, x: float, y: float) -> np.ndarray:
        r = self._region
        return np.array(r.view2d.region_to_view(x - r.x, y - r.y), dtype=np.float64)

    def _cursor(self, event: bpy.types.Event) -> np.ndarray:
        return self._uv_at(event.mouse_x, event.mouse_y)

    def _start(self, context: bpy.types.Context, event: bpy.types.Event) -> None:
        settings = context.scene.eegt_uv_settings
        for name in uv_props.OPTION_NAMES:
            if not self.properties.is_property_set(name):
                setattr(self, name, getattr(settings, name))
        ts = context.scene.tool_settings
        at = self._cursor(event)
        radius = float(np.hypot(*(self._uv_at(event.mouse_x + PICK_PIXELS, event.mouse_y)
                                  - at)))
        self._drag = UVDrag(context.edit_object, tuple(at), self._params, radius=radius,
                            use_pins=self.use_pins, target_shape=self.target_shape,
                            scope=self.scope.lower(), sync=bool(ts.use_uv_select_sync),
                            select_mode=str(ts.uv_select_mode))


class MESH_OT_eegt_live_untangle(_LiveModal, bpy.types.Operator):
    """Drag a vertex (or the selection) of a planar mesh: the rest untangles and smooths live (EEGT). Release or Enter applies, Esc or right-click cancels"""  # noqa: E501

    bl_idname = "mesh.eegt_live_untangle"
    bl_label = "Live Untangle"
    bl_options = {"REGISTER", "UNDO", "BLOCKING"}  # noqa: RUF012

    use_pinned: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Keep Pinned", default=True,
        description="Vertices pinned with EEGT Pin (eegt_pinned) stay")

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        if context.mode != "EDIT_MESH" or context.edit_object is None:
            cls.poll_message_set("Needs mesh Edit Mode")
            return False
        return context.area is not None and context.area.type == "VIEW_3D"

    def _screen(self, co: np.ndarray) -> np.ndarray:
        """(N, 2) region pixel positions of the object's vertex positions ``co``."""
        r = self._region
        m = np.array(r.data.perspective_matrix) @ np.array(self._obj.matrix_world)
        h = np.c_[co, np.ones(co.shape[0])] @ m.T
        w = np.where(h[:, 3] > 1e-9, h[:, 3], np.nan)
        return np.c_[(h[:, 0] / w + 1.0) * 0.5 * r.width, (h[:, 1] / w + 1.0) * 0.5 * r.height]

    def _cursor(self, event: bpy.types.Event) -> np.ndarray | None:
        r = self._region
        xy = (event.mouse_x - r.x, event.mouse_y - r.y)
        origin = view3d_utils.region_2d_to_origin_3d(r, r.data, xy)
        ray = view3d_utils.region_2d_to_vector_3d(r, r.data, xy)
        frame, mw = self._drag.job.frame, self._obj.matrix_world
        point = mw @ Vector(frame.origin)
        normal = (mw.to_3x3().inverted().transposed() @ Vector(frame.normal)).normalized()
        hit = geometry.intersect_line_plane(origin, origin + ray, point, normal)
        if hit is None:
            return self._at
        return self._drag.plane_point(np.array(hit), mw)

    def _start(self, context: bpy.types.Context, event: bpy.types.Event) -> None:
        self._obj = context.edit_object
        r = self._region
        cursor = np.array([event.mouse_x - r.x, event.mouse_y - r.y], dtype=np.float64)
        self._drag = MeshDrag(self._obj, self._params, use_pinned=self.use_pinned,
                              pick=(self._screen, cursor, PICK_PIXELS))


classes = (UV_OT_eegt_live_untangle, MESH_OT_eegt_live_untangle)
