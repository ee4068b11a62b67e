# SPDX-License-Identifier: GPL-3.0-or-later
"""Quality measures of a run for the batch command's report (``eegt --metrics``).

No bpy here: it works on a computed ``runner.Job`` and its ``ObjectResult``.
"""

from __future__ import annotations

import argparse
from typing import Any

from ...core import MEASURE_NAMES, summaries
from ..mesh import runner


def parse_names(text: str) -> tuple[str, ...]:
    """``all`` or a comma list of measure names, as an argparse type (unknown names are
    an argparse error naming the valid ones)."""
    words = [w.strip() for w in text.split(",") if w.strip()]
    if words == ["all"]:
        return MEASURE_NAMES
    bad = [w for w in words if w not in MEASURE_NAMES]
    if bad or not words:
        raise argparse.ArgumentTypeError(
            f"unknown measure '{bad[0] if bad else text}' (use all or a comma list of: "
            f"{', '.join(MEASURE_NAMES)})")
    return tuple(dict.fromkeys(words))  # in the given order, each once


def run_metrics(job: Any, result: Any, names: tuple[str, ...]) -> dict[str, Any] | None:
    """measure -> {"before": summary, "after": summary} of one object's run, the summaries
    as ``core.MeasureSummary.as_dict``; "after" is the mesh as it was left (the input when
    nothing was written). None when the object was refused before it was measured."""
    if job.error is not None or job.points2d is None:
        return None
    before = summaries(job.points2d, job.faces, names)
    after = before
    if result.written and job.new_co is not None:
        pts = runner.written_2d(job, job.new_co)
        after = summaries(pts, job.faces, names)
    return {n: {"before": before[n].as_dict(), "after": after[n].as_dict()} for n in names}
