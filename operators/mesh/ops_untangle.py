# SPDX-License-Identifier: GPL-3.0-or-later
"""``mesh.eegt_untangle_smooth``: untangle and smooth the selected planar meshes.

In the UI the core runs in a worker thread (NumPy only, no bpy) while a modal timer shows
progress; ESC cancels and leaves every mesh as it was. In background mode, and from
``EXEC_DEFAULT`` calls and the redo panel, the same work runs synchronously to the end.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import bpy
from bpy.props import BoolProperty, EnumProperty, StringProperty

from ..shared import modes
from ..shared.progress import printer
from ..shared.result import store_last_run
from ..ui import props
from ..ui.prefs import resolve_backend
from . import runner
from .reference_mesh import ReferenceSource

# The results of the last run, newest last (read by the tests and the CLI).
LAST_RESULTS: list[runner.ObjectResult] = []


def _annotations() -> dict[str, Any]:
    # SKIP_SAVE: Blender must not restore last-used values into a new call, or they would
    # count as set and hide later changes of the sidebar (scene) settings. The redo panel
    # still edits the running operator's own values.
    skip = {"SKIP_SAVE"}
    ann = props.param_annotations(skip)
    ann["backend"] = EnumProperty(name="Backend", items=props.BACKEND_ITEMS, default="PREFS",
                                  description="Compute backend", options=skip)
    ann["use_pinned"] = BoolProperty(
        name="Use Pinned", default=True, options=skip,
        description="Keep vertices of the eegt_pinned attribute or vertex group fixed")
    ann["project"] = BoolProperty(
        name="Project to Plane", default=False, options=skip,
        description="Project a slightly non-planar mesh onto its plane instead of refusing it")
    ann["reference_key"] = StringProperty(name="Reference Key", default="", options=skip,
                                          description=props.REFERENCE_KEY_HELP)
    ann["reference_object"] = StringProperty(name="Reference Object", default="", options=skip,
                                             description=props.REFERENCE_OBJECT_HELP)
    return ann


EXTRA_OPTIONS = ("backend", "use_pinned", "project", "reference_key", "reference_object")


class _Worker:
    """Runs ``compute`` (``runner.compute`` or another job's compute with the same
    signature) for every job in a thread; cancellable between iterations."""

    def __init__(self, jobs: list[Any], params: Any, backend: str, device: str | None,
                 compute: Callable[..., None] = runner.compute) -> None:
        self.jobs, self.params, self.backend, self.device = jobs, params, backend, device
        self.compute = compute
        self.cancel = False
        self.index = 0
        self.iteration = 0
        self.phase = ""
        self.n_inverted: int | None = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="eegt-worker", daemon=True)

    def _progress(self, iteration: int, phase: str, stats: Any) -> bool:
        self.iteration, self.phase = iteration, phase
        self.n_inverted = getattr(stats, "n_inverted", None)
        return not self.cancel

    def _run(self) -> None:
        try:
            for i, job in enumerate(self.jobs):
                self.index = i
                if self.cancel:
                    break
                self.compute(job, self.params, self.backend, self._progress, self.device)
        except BaseException as exc:  # reported on the main thread
            self.error = exc


class EEGTRunMixin:
    """The run machinery of an EEGT operator: scene defaults, the synchronous path
    (background, EXEC_DEFAULT, redo panel) and the modal one (worker thread, progress, ESC),
    one undo step, one report line per object.

    Subclasses give ``_prepare(context) -> (objects, jobs)`` (called in Object Mode),
    ``_finish(objects, jobs) -> set[str]`` (writes, Object Mode), ``_compute`` (a job's
    compute, run in the worker thread: no bpy) and ``_scene_options``: (scene property
    group, option names) pairs whose values fill the options the caller did not set.
    """

    _compute = staticmethod(runner.compute)
    _scene_options: tuple[tuple[str, tuple[str, ...]], ...] = ()
    _id_names: tuple[str, ...] = ()  # options the scene holds as an ID and the call as its name

    def _fill_from_scene(self, context: bpy.types.Context) -> None:
        for group, names in self._scene_options:
            settings = getattr(context.scene, group, None)
            if settings is None:
                continue
            for name in names:
                if not self.properties.is_property_set(name):
                    value = getattr(settings, name)
                    if name in self._id_names:
                        value = value.name if value is not None else ""
                    setattr(self, name, value)

    @staticmethod
    def _has_changes(jobs: list[Any]) -> bool:
        """Whether any job has something to write (else no mode switch is needed)."""
        return any(getattr(j, "new_co", None) is not None for j in jobs)

    # -- synchronous path (background, EXEC_DEFAULT, redo panel) ---------------------------
    def _setup(self, context: bpy.types.Context):
        """Parameters, backend and targets shared by both paths; None (reported) if invalid."""
        self._fill_from_scene(context)
        try:
            params = props.params_from(self)
        except ValueError as exc:
            self.report({"WARNING"}, str(exc))
            return None
        backend, device = resolve_backend(self.backend, context)
        self._targets = modes.target_objects(context)
        self._edit = modes.is_edit_mode(context)
        return params, backend, device

    def execute(self, context: bpy.types.Context) -> set[str]:
        setup = self._setup(context)
        if setup is None:
            return {"CANCELLED"}
        params, backend, device = setup
        verbose = bpy.app.background
        with modes.object_mode(context):
            objs, jobs = self._prepare(context)
            for job in jobs:
                progress = printer(job.object) if verbose else None
                self._compute(job, params, backend, progress, device)
            return self._finish(objs, jobs)

    # -- modal path (UI) ---------------------------------------------------------------------
    def invoke(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        if bpy.app.background or context.window is None:
            return self.execute(context)
        setup = self._setup(context)
        if setup is None:
            return {"CANCELLED"}
        params, backend, device = setup
        with modes.object_mode(context):
            self._objs, self._jobs = self._prepare(context)
        self._worker = _Worker(self._jobs, params, backend, device, self._compute)
        self._worker.thread.start()
        self._t0 = time.perf_counter()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.progress_begin(0, 1000)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _status(self, context: bpy.types.Context, text: str | None) -> None:
        ws = getattr(context, "workspace", None)
        if ws is not None:
            ws.status_text_set(text)
        if context.area is not None:
            context.area.header_text_set(text)

    def _cleanup(self, context: bpy.types.Context) -> None:
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        self._status(context, None)

    def modal(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        w = self._worker
        if event.type == "ESC":
            # answered at once: the worker stops at its next progress call (it writes no
            # Blender data, and its results are dropped with the jobs)
            w.cancel = True
            self._cleanup(context)
            self.report({"INFO"}, "EEGT cancelled: no mesh changed")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"RUNNING_MODAL"}
        if w.thread.is_alive():
            n = max(len(self._jobs), 1)
            job = self._jobs[min(w.index, n - 1)]
            inv = "" if w.n_inverted is None else f", {w.n_inverted} inverted"
            self._status(context, f"EEGT {job.object} ({w.index + 1}/{n}): {w.phase} iteration "
                                  f"{w.iteration}{inv} - Esc to cancel")
            context.window_manager.progress_update(int(1000 * w.index / n) + w.iteration % 100)
            return {"RUNNING_MODAL"}
        self._cleanup(context)
        if w.error is not None:
            self.report({"WARNING"}, f"EEGT internal error: {w.error!r}; no mesh changed")
            return {"CANCELLED"}
        if not self._has_changes(self._jobs):
            return self._finish(self._objs, self._jobs)
        with modes.object_mode(context):
            return self._finish(self._objs, self._jobs)


class MESH_OT_eegt_untangle_smooth(EEGTRunMixin, bpy.types.Operator):
    """Untangle inverted faces and smooth a planar mesh (EEGT). Boundary and pinned vertices stay; in Edit Mode only the selected faces move"""  # noqa: E501

    bl_idname = "mesh.eegt_untangle_smooth"
    bl_label = "Untangle & Smooth"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012
    __annotations__ = _annotations()
    _scene_options = (("eegt_settings", (*(f.name for f in props.param_fields()), *EXTRA_OPTIONS)),)
    _id_names = ("reference_object",)

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        if context.mode not in ("OBJECT", "EDIT_MESH"):
            cls.poll_message_set("Needs Object Mode or mesh Edit Mode")
            return False
        if not modes.target_objects(context):
            cls.poll_message_set("Select a mesh object")
            return False
        return True

    def draw(self, context: bpy.types.Context) -> None:
        """The redo panel: every option, the reference choice with search fields."""
        from ..ui.panel import draw_boundary_target

        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        draw_boundary_target(layout, self, context.active_object)
        skip = {*props.MAIN_PANEL_FIELDS, "reference_key", "reference_object"}
        for name in self.properties.bl_rna.properties.keys():
            if name not in skip and name != "rna_type":
                layout.prop(self, name)

    def _setup(self, context: bpy.types.Context):
        """The shared set-up, then the reference shapes when the target is 'reference'."""
        setup = super()._setup(context)
        self._reference = None
        if setup is not None and setup[0].target == "reference":
            self._reference = ReferenceSource(key=self.reference_key,
                                              object=self.reference_object)
        return setup

    def _prepare(
        self, context: bpy.types.Context
    ) -> tuple[list[bpy.types.Object], list[runner.Job]]:
        """Read every target mesh (call in Object Mode: Edit Mode data is flushed by then)."""
        objs = self._targets
        jobs = [runner.prepare(o, selected_only=self._edit, use_pinned=self.use_pinned,
                               project=self.project, reference=self._reference) for o in objs]
        return objs, jobs

    def _finish(self, objs: list[bpy.types.Object], jobs: list[runner.Job]) -> set[str]:
        """Write results back (call in Object Mode), report one line per object."""
        results = [runner.apply(o, j) for o, j in zip(objs, jobs, strict=True)]
        LAST_RESULTS[:] = results
        for obj, res in zip(objs, results, strict=True):
            store_last_run(obj, res)
            self.report({"INFO"} if res.ok else {"WARNING"}, res.line())
        if not any(r.written for r in results):
            return {"CANCELLED"}
        return {"FINISHED"}


classes = (MESH_OT_eegt_untangle_smooth,)


# Register in order, unregister in reverse (Blender's own helper).
register, unregister = bpy.utils.register_classes_factory(classes)
