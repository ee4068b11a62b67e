# SPDX-License-Identifier: GPL-3.0-or-later
"""``mesh.eegt_untangle_smooth``: untangle and smooth the selected planar meshes.

The run itself (worker thread and progress in the UI, ESC, the synchronous path in
background mode, from ``EXEC_DEFAULT`` calls and the redo panel) is ``EEGTRunMixin``'s
(``operators/shared/run_mixin.py``); this operator reads, computes and writes meshes.
"""

from __future__ import annotations

from typing import Any

import bpy
from bpy.props import BoolProperty, EnumProperty, StringProperty

from ..shared import modes
from ..shared.run_mixin import EEGTRunMixin
from ..ui import props
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


class MESH_OT_eegt_untangle_smooth(EEGTRunMixin, bpy.types.Operator):
    """Untangle inverted faces and smooth a planar mesh (EEGT). Boundary and pinned vertices stay; in Edit Mode only the selected faces move"""  # noqa: E501

    bl_idname = "mesh.eegt_untangle_smooth"
    bl_label = "Untangle & Smooth"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012
    __annotations__ = _annotations()
    _compute = staticmethod(runner.compute)
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
        self._report_results(objs, results)
        if not any(r.written for r in results):
            return {"CANCELLED"}
        return {"FINISHED"}


classes = (MESH_OT_eegt_untangle_smooth,)


# Register in order, unregister in reverse (Blender's own helper).
register, unregister = bpy.utils.register_classes_factory(classes)
