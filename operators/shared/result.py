# SPDX-License-Identifier: GPL-3.0-or-later
"""One run result for mesh and UV runs: the fields both have, a typed stats block per kind
(``fileio/run_stats.py``: the keys of ``before`` / ``after``), the one last-run store on the
object and the one sidebar section that shows it.

``runner.ObjectResult`` (kind "mesh") and ``uv_runner.UVObjectResult`` (kind "uv") add their
own fields and their report line (its stats part from ``report_lines.py``). No bpy import
here: the store and the panel section only set and read properties of the object and draw
into a given layout.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

from ...fileio.run_stats import KINDS, Kind
from .report_lines import stat_change, stat_changes

OK_STATUSES = ("valid", "untangled")
# The property group (props.py / uv_props.py) that keeps an object's last run, per kind.
LAST_RUN_PROPERTY = {"mesh": "eegt_last_run", "uv": "eegt_last_uv_run"}
# Result fields a last-run group keeps when it has a property of that name.
_LAST_RUN_FIELDS = ("status", "backend", "uv_map", "untangle_iterations", "smooth_iterations",
                    "global_iterations", "seconds")


@dataclass
class RunResult:
    """Outcome of one object's run, for reports, the sidebar and the JSON report."""

    KIND: ClassVar[str] = ""  # a key of run_stats.KINDS: what ``before`` / ``after`` hold

    object: str
    mesh: str = ""
    status: str = "error"  # valid | untangled | failed | cancelled | error
    message: str = ""
    written: bool = False
    before: dict[str, Any] | None = None  # the stats block (run_stats.KINDS[KIND])
    after: dict[str, Any] | None = None
    untangle_iterations: int = 0
    global_iterations: int = 0
    smooth_iterations: int = 0
    seconds: float = 0.0
    backend: str = ""
    n_faces: int = 0
    n_free: int = 0
    notes: list[str] = field(default_factory=list)

    @classmethod
    def stats_kind(cls) -> Kind:
        """The description of this kind's stats block."""
        return KINDS[cls.KIND]

    @property
    def ok(self) -> bool:
        """True when the run ended with no inverted face."""
        return self.status in OK_STATUSES

    def line(self) -> str:  # pragma: no cover - each kind words its own
        raise NotImplementedError

    def stats_text(self) -> str:
        """The stats part of the report line: each stat of the kind, before -> after."""
        return stat_changes(self.stats_kind(), self.before, self.after)

    def unchanged_line(self, name: str) -> str | None:
        """The report line of a run that changed nothing (an error or a cancel), else None;
        every kind words these two alike."""
        if self.status == "error":
            return f"{name}: not changed: {self.message}"
        if self.status == "cancelled":
            return f"{name}: cancelled, not changed"
        return None

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the per-object entry of the CLI report): "kind", then every
        field in declaration order."""
        out: dict[str, Any] = {"kind": self.KIND}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "seconds":
                value = round(value, 6)
            elif f.name == "notes":
                value = list(value)
            out[f.name] = value
        return out


def store_last_run(obj: Any, result: RunResult) -> None:
    """Keep a run's outcome on the object (its kind's property group), for the sidebar:
    status, report line, the stats block before and after, and the result's fields the
    group has a property for."""
    lr = getattr(obj, LAST_RUN_PROPERTY[result.KIND], None)
    if lr is None:
        return
    lr.has_run = True
    lr.message = result.line()
    for name in _LAST_RUN_FIELDS:
        if hasattr(lr, name) and hasattr(result, name):
            setattr(lr, name, getattr(result, name))
    b, a = result.before or {}, result.after or {}
    for s in result.stats_kind().stats:
        cast = int if s.integer else float
        setattr(lr, f"{s.name}_before", cast(b.get(s.key, 0)))
        setattr(lr, f"{s.name}_after", cast(a.get(s.key, 0)))


def draw_last_run(layout: Any, obj: Any, kind: str, title: str) -> None:
    """The sidebar section of the active object's last run of ``kind``: its status, each
    stat of the kind before -> after, iterations (where kept), time and backend."""
    lr = getattr(obj, LAST_RUN_PROPERTY[kind], None) if obj is not None else None
    if lr is None or not lr.has_run:
        what = "UV run" if kind == "uv" else "run"
        layout.label(text=f"No {what} on the active object yet")
        return
    col = layout.column(align=True)
    col.label(text=f"{title}: {lr.status}")
    if lr.status in ("error", "cancelled"):
        col.label(text=lr.message)
        return
    for s in KINDS[kind].stats:
        b, a = getattr(lr, f"{s.name}_before"), getattr(lr, f"{s.name}_after")
        col.label(text=stat_change(s, b, a, f"{s.label}:"))
    if hasattr(lr, "untangle_iterations"):
        its = f"{lr.untangle_iterations} + {lr.smooth_iterations}"
        if lr.global_iterations:
            its = f"{lr.untangle_iterations} + {lr.global_iterations} + {lr.smooth_iterations}"
        col.label(text=f"Iterations: {its}")
    backend = getattr(lr, "backend", "")
    col.label(text=f"{lr.seconds:.2f} s, {backend}" if backend else f"{lr.seconds:.2f} s")
