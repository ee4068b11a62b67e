# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender properties generated from the fields of ``core.EEGTParams``.

The scene settings, the operator's redo panel and the command-line flags all come from
``dataclasses.fields(EEGTParams)``, so a new core parameter shows up everywhere by itself.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from ...core import MEASURES, EEGTParams
from ...core.choices import BACKEND, PARAMETERS, Bound, Enumeration
from ...fileio.run_stats import MESH, Kind


def enum_items(choices: Enumeration, upper: bool = False) -> tuple[tuple[str, str, str], ...]:
    """EnumProperty items of a core enumeration (identifiers upper case with ``upper``)."""
    return tuple((c.id.upper() if upper else c.id, c.label, c.description) for c in choices)


# Choices of string parameters (the core's enumerations).
STRING_CHOICES: dict[str, tuple[tuple[str, str, str], ...]] = {
    name: enum_items(rule) for name, rule in PARAMETERS.items() if not isinstance(rule, Bound)}

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
    "region": "Region",
}

# Fields the main panel draws itself (with the reference choice), not the Parameters list.
MAIN_PANEL_FIELDS = ("boundary", "feature_angle", "target", "region")



def bounds(name: str) -> dict[str, float]:
    """A numeric parameter's min / max / soft_max for its property (core's bound)."""
    rule = PARAMETERS.get(name)
    if not isinstance(rule, Bound):
        return {}
    out = {"min": rule.ui_min if rule.low_open else rule.low}
    if rule.high is not None:
        out["max"] = rule.high
    if rule.soft_max is not None:
        out["soft_max"] = rule.soft_max
    return out


BACKEND_ITEMS: tuple[tuple[str, str, str], ...] = (
    ("PREFS", "Default", "Use the default backend of the add-on preferences"),
    *enum_items(BACKEND, upper=True),
)


# Analyze Quality's measures (core.metrics.measures): identifier, label, tooltip.
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


def draw_param_fields(layout, settings, skip: tuple[str, ...] = ()) -> None:
    """Draw every parameter of ``settings`` but those in ``skip`` into a panel's layout, as
    the sidebars' Parameters sub-panels show them."""
    layout.use_property_split = True
    layout.use_property_decorate = False
    for f in param_fields():
        if f.name not in skip:
            layout.prop(settings, f.name)


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
    limits = bounds(f.name)
    opt = {"options": options} if options is not None else {}
    if isinstance(default, bool):
        return BoolProperty(name=name, description=desc, default=default, **opt)
    if isinstance(default, int):
        return IntProperty(name=name, description=desc, default=default, **opt,
                           min=int(limits.get("min", 0)),
                           soft_max=int(limits.get("soft_max", 2**31 - 1)))
    if isinstance(default, float):
        return FloatProperty(name=name, description=desc, default=default, **opt,
                             min=limits.get("min", -3.4e38), max=limits.get("max", 3.4e38),
                             soft_max=limits.get("soft_max", 3.4e38),
                             precision=4 if default and abs(default) < 0.01 else 3)
    if isinstance(default, str) and f.name in STRING_CHOICES:
        return EnumProperty(name=name, description=desc, items=STRING_CHOICES[f.name],
                            default=default, **opt)
    return StringProperty(name=name, description=desc, default=str(default), **opt)


def param_annotations(options: set[str] | None = None) -> dict[str, Any]:
    """Annotations (name -> bpy property) for every EEGTParams field."""
    return {f.name: blender_property(f, options) for f in param_fields()}


def as_typed(value: Any) -> Any:
    """A property's value as the user typed it: Blender keeps a FloatProperty as float32
    (0.2 reads back 0.20000000298023224), so a float becomes the shortest decimal that
    float32 holds as that value (0.2), the number the sidebar shows and the command takes."""
    if isinstance(value, float):
        return float(str(np.float32(value)))
    return value


def params_from(owner: Any) -> EEGTParams:
    """EEGTParams from an operator's or a property group's parameter properties, floats as
    typed (`as_typed`): the operators run the same parameters as the command and the core."""
    return EEGTParams(**{f.name: as_typed(getattr(owner, f.name)) for f in param_fields()})


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


def last_run_class(name: str, doc: str, kind: Kind, extra: dict[str, Any]) -> type:
    """A property group keeping an object's last run of one kind: whether it ran, its
    status, message and seconds, each stat of the kind (``fileio/run_stats.py``) before and
    after (an int for a count, else a float) and the kind's ``extra`` properties."""
    annotations: dict[str, Any] = {"has_run": BoolProperty(default=False),
                                   "status": StringProperty(default=""),
                                   "message": StringProperty(default=""), **extra}
    for stat in kind.stats:
        for when in ("before", "after"):
            annotations[f"{stat.name}_{when}"] = (IntProperty(default=0) if stat.integer
                                                  else FloatProperty(default=0.0))
    annotations["seconds"] = FloatProperty(default=0.0)
    return type(name, (bpy.types.PropertyGroup,), {"__annotations__": annotations,
                                                    "__doc__": doc})


EEGT_PG_last_run = last_run_class(
    "EEGT_PG_last_run", "Statistics of the last EEGT run on an object (shown in the sidebar)",
    MESH, {"backend": StringProperty(default=""),
           "untangle_iterations": IntProperty(default=0),
           "smooth_iterations": IntProperty(default=0),
           "global_iterations": IntProperty(default=0)})


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
