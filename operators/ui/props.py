# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender properties generated from the fields of ``core.EEGTParams``.

The scene settings, the operator's redo panel and the command-line flags all come from
``dataclasses.fields(EEGTParams)``, so a new core parameter shows up everywhere by itself.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from ...core import MEASURES, EEGTParams

# Choices of string parameters (dataclass fields carry no choice list).
STRING_CHOICES: dict[str, tuple[tuple[str, str, str], ...]] = {
    "untangle": (
        ("auto", "Auto", "Global under 20 000 faces, else EEGT + Local"),
        ("global", "Global", "Foldover-free optimization of the whole mesh removes inverted "
         "faces (most robust)"),
        ("eegt+local", "EEGT + Local", "EEGT while it makes progress, the optimization only "
         "around the folds it leaves (large meshes: fastest)"),
        ("eegt+global", "EEGT + Global", "EEGT first, the optimization when EEGT stalls"),
        ("eegt", "EEGT Only", "The paper's EEGT untangling only"),
    ),
    "scaling": (
        ("edge", "Edge", "Shrink keeps the mean edge length (paper)"),
        ("area", "Area", "Shrink keeps the mean area"),
    ),
    "boundary": (
        ("fixed", "Fixed", "Boundary vertices stay where they are (paper)"),
        ("slide", "Slide", "Boundary vertices slide along the input boundary and never leave "
         "it; corners sharper than the Feature Angle, pinned and non-manifold vertices stay"),
        ("free", "Free", "Boundary vertices move freely; only pinned and non-manifold vertices "
         "stay"),
    ),
    "target": (
        ("regular", "Regular", "Pull every face towards the regular polygon (paper)"),
        ("reference", "Reference", "Pull every face towards its own shape in a reference of "
         "the same topology (a shape key or an object): keeps grading and anisotropy"),
    ),
}

LABELS: dict[str, str] = {
    "a": "Stretch Factor a",
    "eta": "Quality Exponent",
    "c": "Distance Exponent",
    "inverted_weight": "Inverted Weight",
    "tol": "Tolerance",
    "tol_min": "Worst-Face Tolerance",
    "max_untangle_iterations": "Max Untangle Iterations",
    "max_smooth_iterations": "Max Smooth Iterations",
    "distance_refresh": "Distance Refresh",
    "scaling": "Scaling",
    "untangle": "Untangle With",
    "stall_iterations": "Stall Iterations",
    "polish_iterations": "Polish Iterations",
    "boundary": "Boundary",
    "feature_angle": "Feature Angle",
    "target": "Target Shape",
}

# Fields the main panel draws itself (with the reference choice), not the Parameters list.
MAIN_PANEL_FIELDS = ("boundary", "feature_angle", "target")

# Lower bounds matching EEGTParams.__post_init__ (soft_max keeps the sliders usable).
BOUNDS: dict[str, dict[str, float]] = {
    "a": {"min": 1e-6, "soft_max": 1.0},
    "eta": {"min": 0.0, "soft_max": 8.0},
    "c": {"min": 0.0, "soft_max": 8.0},
    "inverted_weight": {"min": 1e-6, "soft_max": 50.0},
    "tol": {"min": 0.0, "soft_max": 0.1},
    "tol_min": {"min": 0.0, "soft_max": 0.1},
    "max_untangle_iterations": {"min": 0, "soft_max": 20000},
    "stall_iterations": {"min": 1, "soft_max": 1000},
    "polish_iterations": {"min": 0, "soft_max": 5000},
    "max_smooth_iterations": {"min": 0, "soft_max": 5000},
    "distance_refresh": {"min": 1, "soft_max": 100},
    "feature_angle": {"min": 0.0, "max": 180.0, "soft_max": 180.0},
}

BACKEND_ITEMS: tuple[tuple[str, str, str], ...] = (
    ("PREFS", "Default", "Use the default backend of the add-on preferences"),
    ("NUMPY", "NumPy", "Reference CPU backend (always available)"),
    ("OPENCL", "OpenCL", "OpenCL device (NumPy when pyopencl or a device is missing)"),
    ("AUTO", "Auto", "OpenCL where it is faster (small meshes: its global stage only), else NumPy"),
)


# Analyze Quality's measures (core.measures): identifier, label, tooltip.
MEASURE_ITEMS: tuple[tuple[str, str, str], ...] = tuple(
    (m.name, m.label, m.description) for m in MEASURES.values())


def measure_property(**kw: Any) -> Any:
    """The quality measure choice (Analyze Quality and the scene setting)."""
    return EnumProperty(name="Measure", items=MEASURE_ITEMS, default="mean_ratio",
                        description="Element quality measure to compute, store as a face "
                                    "attribute and show as the heat map", **kw)


REFERENCE_KEY_HELP = ("Target Reference: the shape key whose face shapes are the targets "
                      "(empty: the Basis key when another key is being edited)")
REFERENCE_OBJECT_HELP = ("Target Reference: a mesh object of the same topology whose face "
                         "shapes are the targets (instead of a shape key)")


def _is_mesh(_self: Any, obj: Any) -> bool:
    return obj.type == "MESH"


def param_fields() -> list[dataclasses.Field]:
    """The EEGTParams fields, in declaration order."""
    return list(dataclasses.fields(EEGTParams))


def field_label(name: str) -> str:
    """Human label of a parameter (falls back to the field name)."""
    return LABELS.get(name, name.replace("_", " ").title())


def field_help(f: dataclasses.Field) -> str:
    """Tooltip of a parameter: the field's ``help`` metadata."""
    return str(f.metadata.get("help", "")).rstrip(".") or field_label(f.name)


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:  # pragma: no cover - not used today
        return f.default_factory()
    return getattr(EEGTParams(), f.name)


def blender_property(f: dataclasses.Field, options: set[str] | None = None) -> Any:
    """A bpy property definition for one EEGTParams field (type taken from its default)."""
    default = _default(f)
    name, desc = field_label(f.name), field_help(f)
    bounds = BOUNDS.get(f.name, {})
    opt = {"options": options} if options is not None else {}
    if isinstance(default, bool):
        return BoolProperty(name=name, description=desc, default=default, **opt)
    if isinstance(default, int):
        return IntProperty(name=name, description=desc, default=default, **opt,
                           min=int(bounds.get("min", 0)),
                           soft_max=int(bounds.get("soft_max", 2**31 - 1)))
    if isinstance(default, float):
        return FloatProperty(name=name, description=desc, default=default, **opt,
                             min=bounds.get("min", -3.4e38), max=bounds.get("max", 3.4e38),
                             soft_max=bounds.get("soft_max", 3.4e38),
                             precision=4 if default and abs(default) < 0.01 else 3)
    if isinstance(default, str) and f.name in STRING_CHOICES:
        return EnumProperty(name=name, description=desc, items=STRING_CHOICES[f.name],
                            default=default, **opt)
    return StringProperty(name=name, description=desc, default=str(default), **opt)


def param_annotations(options: set[str] | None = None) -> dict[str, Any]:
    """Annotations (name -> bpy property) for every EEGTParams field."""
    return {f.name: blender_property(f, options) for f in param_fields()}


def params_from(owner: Any) -> EEGTParams:
    """EEGTParams from an operator's or a property group's parameter properties."""
    return EEGTParams(**{f.name: getattr(owner, f.name) for f in param_fields()})


def _settings_class() -> type:
    annotations = param_annotations()
    annotations["quality_measure"] = measure_property()
    annotations["backend"] = EnumProperty(
        name="Backend", description="Compute backend", items=BACKEND_ITEMS, default="PREFS")
    annotations["use_pinned"] = BoolProperty(
        name="Use Pinned", default=True,
        description="Keep vertices of the eegt_pinned attribute or vertex group fixed")
    annotations["project"] = BoolProperty(
        name="Project to Plane", default=False,
        description="Project a slightly non-planar mesh onto its plane instead of refusing it")
    annotations["reference_key"] = StringProperty(name="Reference Key", default="",
                                                  description=REFERENCE_KEY_HELP)
    annotations["reference_object"] = bpy.props.PointerProperty(
        name="Reference Object", type=bpy.types.Object, poll=_is_mesh,
        description=REFERENCE_OBJECT_HELP)
    return type("EEGT_PG_settings", (bpy.types.PropertyGroup,), {
        "__annotations__": annotations,
        "__doc__": "EEGT parameters of this scene (defaults for the operator)",
    })


EEGT_PG_settings = _settings_class()


class EEGT_PG_last_run(bpy.types.PropertyGroup):
    """Statistics of the last EEGT run on an object (shown in the sidebar)."""

    has_run: BoolProperty(default=False)  # type: ignore[valid-type]
    status: StringProperty(default="")  # type: ignore[valid-type]
    message: StringProperty(default="")  # type: ignore[valid-type]
    backend: StringProperty(default="")  # type: ignore[valid-type]
    inverted_before: IntProperty(default=0)  # type: ignore[valid-type]
    inverted_after: IntProperty(default=0)  # type: ignore[valid-type]
    q_min_before: FloatProperty(default=0.0)  # type: ignore[valid-type]
    q_min_after: FloatProperty(default=0.0)  # type: ignore[valid-type]
    q_avg_before: FloatProperty(default=0.0)  # type: ignore[valid-type]
    q_avg_after: FloatProperty(default=0.0)  # type: ignore[valid-type]
    untangle_iterations: IntProperty(default=0)  # type: ignore[valid-type]
    smooth_iterations: IntProperty(default=0)  # type: ignore[valid-type]
    global_iterations: IntProperty(default=0)  # type: ignore[valid-type]
    seconds: FloatProperty(default=0.0)  # type: ignore[valid-type]


classes = (EEGT_PG_settings, EEGT_PG_last_run)


def register() -> None:
    """Register the property groups and attach them to Scene and Object."""
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.eegt_settings = bpy.props.PointerProperty(type=EEGT_PG_settings)
    bpy.types.Object.eegt_last_run = bpy.props.PointerProperty(type=EEGT_PG_last_run)


def unregister() -> None:
    """Remove what :func:`register` added."""
    del bpy.types.Object.eegt_last_run
    del bpy.types.Scene.eegt_settings
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
