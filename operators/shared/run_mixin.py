# SPDX-License-Identifier: GPL-3.0-or-later
"""The run machinery of the EEGT operators (mesh and UV Untangle & Smooth): scene defaults,
the synchronous path and the modal one, one undo step, one report line per object.

In the UI the job's compute runs in a worker thread (NumPy only, no bpy) while a modal timer
shows progress; ESC cancels and leaves every mesh as it was. In background mode, and from
``EXEC_DEFAULT`` calls and the redo panel, the same work runs synchronously to the end.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import bpy

from ..ui import props
from ..ui.prefs import resolve_backend
from . import modes
from .progress import Progress, printer
from .result import RunResult, store_last_run


class _Worker:
    """Runs ``compute`` (a job's compute: ``runner.compute``, ``uv_runner.compute``) for
    every job in a thread; cancellable between iterations."""

    def __init__(self, jobs: list[Any], params: Any, backend: str, device: str | None,
                 compute: Callable[..., None]) -> None:
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
    ``_finish(objects, jobs) -> set[str]`` (writes, Object Mode; ``_report_results`` keeps
    and reports its results), ``_compute`` (a job's compute, run in the worker thread: no
    bpy) and ``_scene_options``: (scene property group, option names) pairs whose values
    fill the options the caller did not set.
    """

    @staticmethod
    def _compute(job: Any, params: Any, backend: str, progress: Progress | None,
                 device: str | None) -> None:
        """A job's compute (each operator gives its own, e.g. ``runner.compute``)."""
        raise NotImplementedError

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

    def _report_results(self, objs: list[bpy.types.Object], results: list[RunResult]) -> None:
        """Keep each object's last run and report its line (a warning when not ok)."""
        for obj, res in zip(objs, results, strict=True):
            store_last_run(obj, res)
            self.report({"INFO"} if res.ok else {"WARNING"}, res.line())

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
