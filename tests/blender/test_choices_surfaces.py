"""Every surface lists the core's choices and bounds (core/choices.py): the scene settings and
the operators' properties, the add-on preferences, the UV settings, the command's argument
parser and the core's own checks. A surface that drifts from the core fails here."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .conftest import MODULE


def f32(x: float) -> float:
    """A value as a Blender float property holds it."""
    return float(np.float32(x))


def enum_ids(rna_prop) -> list[str]:
    return [item.identifier for item in rna_prop.enum_items]


def parser_actions(ext) -> dict[str, object]:
    parser = ext.operators.command.parser.build_parser()
    return {a.dest: a for a in parser._actions}


def check_param_properties(ext, props, where: str) -> None:
    """The EEGTParams properties of one property owner match the core: enumeration ids,
    defaults, hard min / max and soft max."""
    ch, params = ext.core.choices, ext.core.EEGTParams()
    for f in dataclasses.fields(params):
        prop, default = props[f.name], getattr(params, f.name)
        rule = ch.PARAMETERS.get(f.name)
        if isinstance(default, str):
            assert enum_ids(prop) == list(ch.ids(rule)), (where, f.name)
            assert prop.default == default, (where, f.name)
            continue
        if isinstance(default, bool):
            continue
        low = rule.ui_min if rule.low_open else rule.low
        soft_max = rule.soft_max
        if isinstance(default, int):
            assert (prop.default, prop.hard_min) == (default, low), (where, f.name)
            assert prop.soft_max == (2**31 - 1 if soft_max is None else soft_max), (where, f.name)
            continue
        assert prop.default == f32(default), (where, f.name)
        assert prop.hard_min == f32(low), (where, f.name)
        assert prop.hard_max == f32(3.4e38 if rule.high is None else rule.high), (where, f.name)
        assert prop.soft_max == f32(soft_max), (where, f.name)


def test_every_surface_lists_the_core_choices_and_bounds(bpy, ext):
    ch = ext.core.choices
    backends = [c.id.upper() for c in ch.BACKEND]
    # the core's own lists and checks
    assert ext.core.eegt.backends.BACKENDS == ch.ids(ch.BACKEND)
    assert ext.core.params.UNTANGLE_METHODS == ch.ids(ch.UNTANGLE)
    assert ext.core.params.BOUNDARY_MODES == ch.ids(ch.BOUNDARY)
    assert ext.core.params.TARGETS == ch.ids(ch.TARGET)
    assert ext.core.uv.uv_untangle.SCOPES == ch.ids(ch.UV_SCOPE)
    assert ext.operators.uv.uv_runner.TARGETS == ch.ids(ch.UV_TARGET)
    params = ext.core.EEGTParams()
    assert set(ch.PARAMETERS) <= {f.name for f in dataclasses.fields(params)}
    for name, rule in ch.PARAMETERS.items():
        if isinstance(rule, ch.Bound):
            kind = type(getattr(params, name))
            ends = [rule.low] + ([] if rule.high is None else [rule.high])
            below = rule.low - 1 if kind is int else math.nextafter(rule.low, -math.inf)
            for ok in ends if not rule.low_open else ends[1:]:
                params.with_(**{name: kind(ok)})
            try:
                params.with_(**{name: kind(below)})
            except ValueError as exc:
                assert f"invalid parameter: {name} must be" in str(exc)
            else:
                raise AssertionError(f"core accepts {name} = {below}")
        else:
            for c in rule:
                params.with_(**{name: c.id})
            try:
                params.with_(**{name: "no-such-choice"})
            except ValueError:
                pass
            else:
                raise AssertionError(f"core accepts {name} = 'no-such-choice'")
    # scene settings and the two run operators' redo-panel properties
    scene_props = bpy.context.scene.eegt_settings.bl_rna.properties
    check_param_properties(ext, scene_props, "scene")
    assert enum_ids(scene_props["backend"]) == ["PREFS", *backends]
    for op in (bpy.ops.mesh.eegt_untangle_smooth, bpy.ops.uv.eegt_untangle_smooth):
        op_props = op.get_rna_type().properties
        check_param_properties(ext, op_props, op.idname_py())
        assert enum_ids(op_props["backend"]) == ["PREFS", *backends]
    # add-on preferences (their own order, the same ids)
    prefs = bpy.context.preferences.addons[MODULE].preferences.bl_rna.properties
    assert sorted(enum_ids(prefs["default_backend"])) == sorted(backends)
    # UV settings
    uv_props = bpy.context.scene.eegt_uv_settings.bl_rna.properties
    assert enum_ids(uv_props["target_shape"]) == list(ch.ids(ch.UV_TARGET))
    assert uv_props["target_shape"].default == ch.UV_TARGET[0].id
    assert enum_ids(uv_props["scope"]) == [c.id.upper() for c in ch.UV_SCOPE]
    assert uv_props["scope"].default == ch.UV_SCOPE[0].id.upper()
    # the command's flags
    actions = parser_actions(ext)
    assert list(actions["backend"].choices) == list(ch.ids(ch.BACKEND))
    assert list(actions["uv_scope"].choices) == list(ch.ids(ch.UV_SCOPE))
    assert actions["uv_scope"].default == ch.UV_SCOPE[0].id
    for f in dataclasses.fields(params):
        action, default = actions[f.name], getattr(params, f.name)
        rule = ch.PARAMETERS.get(f.name)
        expected = None if isinstance(rule, ch.Bound) or rule is None else list(ch.ids(rule))
        assert (list(action.choices) if action.choices else None) == expected, f.name
        assert action.default is None and f"(default {default})" in action.help, f.name
