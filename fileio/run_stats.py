# SPDX-License-Identifier: GPL-3.0-or-later
"""The typed stats block of a run result, per kind of run, described once.

A run result (``operators/shared/result.py``) has a ``before`` and an ``after`` stats dict; their
keys depend on the kind of run: ``mesh`` (core ``Stats`` of the mesh's faces) or ``uv``
(``core.uv.uv_untangle.UVMeasures`` of the UV faces). This description is what the result's
sidebar store and panel section (``operators/shared/result.py``), the report lines of a run
(``operators/shared/report_lines.py``) and the batch summary (a file's totals and its CSV
columns, ``batch/summary.py``) read. Plain data: no bpy, no NumPy (the
batch package imports it outside Blender).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

COMBINES = ("sum", "min", "max", "mean")


@dataclass(frozen=True)
class Stat:
    """One value of a stats block."""

    key: str  # its key in the before / after dict of a run result
    name: str  # the stem of its last-run properties (NAME_before, NAME_after)
    label: str  # its name in the sidebar
    combine: str  # how the objects of one file add up: sum | min | max | mean (face-weighted)
    integer: bool = False  # a count (else a float, written with 6 decimals in the CSV)
    word: str = ""  # its name in a report line, when not its name

    @property
    def report_word(self) -> str:
        """Its name in a report line."""
        return self.word or self.name


@dataclass(frozen=True)
class Kind:
    """The stats block of one kind of run."""

    name: str  # "mesh" | "uv": the "kind" of a result's JSON entry
    stats: tuple[Stat, ...]
    column_prefix: str = ""  # the stem of its CSV columns: PREFIX + stat.name

    def columns(self) -> tuple[str, ...]:
        """Its CSV columns: each stat before, then after."""
        return tuple(f"{self.column_prefix}{s.name}_{when}" for s in self.stats
                     for when in ("before", "after"))

    def combine(self, blocks: list[dict[str, Any] | None],
                faces: list[int]) -> dict[str, Any] | None:
        """One file's stats from its objects' blocks (None where an object has none):
        counts added up, extremes kept, means weighted by face count (an unweighted mean
        when no object has a face)."""
        pairs = [(b, n) for b, n in zip(blocks, faces) if b]
        if not pairs:
            return None
        out: dict[str, Any] = {}
        for s in self.stats:
            values = [(b[s.key], n) for b, n in pairs if b.get(s.key) is not None]
            if not values:
                out[s.key] = None
            elif s.combine == "sum":
                out[s.key] = sum(int(v) if s.integer else float(v) for v, _ in values)
            elif s.combine in ("min", "max"):
                pick = min if s.combine == "min" else max
                out[s.key] = pick(int(v) if s.integer else float(v) for v, _ in values)
            else:
                weight = sum(n for _, n in values)
                out[s.key] = float(sum(float(v) * n for v, n in values) / weight if weight
                                   else sum(float(v) for v, _ in values) / len(values))
        return out


MESH = Kind("mesh", (
    Stat("n_inverted", "inverted", "Inverted", "sum", integer=True),
    Stat("q_min", "q_min", "q min", "min"),
    Stat("q_avg", "q_avg", "q avg", "mean"),
))
UV = Kind("uv", (
    Stat("flipped", "flipped", "Flipped", "sum", integer=True),
    Stat("inverted", "inverted", "Inverted", "sum", integer=True),
    Stat("overlapping", "overlapping", "Overlapping", "sum", integer=True),
    Stat("distortion_mean", "distortion_mean", "Distortion mean", "mean",
         word="distortion mean"),
    Stat("distortion_worst", "distortion_worst", "Distortion worst", "min", word="worst"),
), column_prefix="uv_")
KINDS: dict[str, Kind] = {k.name: k for k in (MESH, UV)}


def kind_of(entry: dict[str, Any]) -> str | None:
    """The kind of a per-object JSON entry: its "kind", else (an entry written before
    results had one) the kind whose stats keys its before / after block has."""
    kind = entry.get("kind")
    if kind in KINDS:
        return kind
    block = entry.get("before") or entry.get("after") or {}
    for k in KINDS.values():
        if all(s.key in block for s in k.stats):
            return k.name
    return None


def kind_of_objects(objects: Iterable[dict[str, Any]]) -> str | None:
    """The kind of a file's per-object entries (a file is run as one kind)."""
    kinds = {kind_of(o) for o in objects} - {None}
    return kinds.pop() if len(kinds) == 1 else ("mixed" if kinds else None)
