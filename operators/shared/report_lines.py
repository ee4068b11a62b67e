# SPDX-License-Identifier: GPL-3.0-or-later
"""How a run's stats read in its report lines, derived from the stats schema
(``fileio/run_stats.py``: each kind's stats, their keys, report words and types).

A count reads as it is and a float with 3 decimals: ``inverted 3 -> 0, q_min 0.000 -> 0.412``
in a result's line (``stat_changes``), ``Inverted: 3 -> 0`` in the sidebar (``stat_change``
with the stat's label), ``inverted 3, q_min 0.000, q_avg 0.512`` in a progress line and
``3 inverted, q_min 0.000`` in the quality report (``stat_values``). No bpy here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ...fileio.run_stats import Kind, Stat


def stat_change(stat: Stat, before: Any, after: Any, name: str | None = None) -> str:
    """``NAME BEFORE -> AFTER`` of one stat; ``name`` defaults to its report word."""
    name = stat.report_word if name is None else name
    if stat.integer:
        return f"{name} {before} -> {after}"
    return f"{name} {before:.3f} -> {after:.3f}"


def stat_changes(kind: Kind, before: Mapping[str, Any] | None,
                 after: Mapping[str, Any] | None) -> str:
    """Every stat of ``kind`` from its ``before`` block to its ``after`` block, in schema
    order (a missing count reads None, a missing float 0)."""
    b, a = before or {}, after or {}
    return ", ".join(stat_change(s, b.get(s.key), a.get(s.key)) if s.integer else
                     stat_change(s, b.get(s.key, 0), a.get(s.key, 0)) for s in kind.stats)


def stat_values(kind: Kind, values: Any, *, counts_first: bool = False) -> str:
    """Every stat of ``kind`` in ``values`` (a stats dict, or an object with the keys as
    attributes, as the core's progress stats), in schema order; a missing count reads ``?``,
    a missing float nan. ``counts_first``: a count before its word (``3 inverted``)."""
    def get(key: str, default: Any) -> Any:
        if isinstance(values, Mapping):
            return values.get(key, default)
        return getattr(values, key, default)

    parts = []
    for s in kind.stats:
        if not s.integer:
            parts.append(f"{s.report_word} {get(s.key, float('nan')):.3f}")
        elif counts_first:
            parts.append(f"{get(s.key, '?')} {s.report_word}")
        else:
            parts.append(f"{s.report_word} {get(s.key, '?')}")
    return ", ".join(parts)
