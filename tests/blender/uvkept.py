"""Helper of the UV tests with pins (corners kept as given, core.metrics.kept)."""

from __future__ import annotations

import numpy as np

from .uvtools import loop_faces


def pin_one_inverted_face(ext, obj, groups, bad, inside) -> tuple[int, np.ndarray]:
    """Pin every corner of the first inverted face off the border that stays inverted once
    pinned (a concave one with every corner pinned is kept as given: valid); (face, pinned
    loops)."""
    me = obj.data
    lf = loop_faces(obj)
    layer = me.uv_layers.active
    if hasattr(layer, "pin_ensure"):
        layer.pin_ensure()
    for face in np.flatnonzero(bad & inside):
        pins = np.isin(groups, groups[lf == face])
        layer.pin.foreach_set("value", pins)
        if ext.operators.uv.ops_uv.analyze_uv(obj, True).masks["INVERTED"][face]:
            return int(face), pins
    raise AssertionError("no inverted face stays inverted once pinned")

