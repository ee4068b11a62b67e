# SPDX-License-Identifier: GPL-3.0-or-later
"""The JSON report of the batch command (one dict, filled as the run goes)."""

from __future__ import annotations

import platform
from typing import Any

import bpy


def extension_version() -> str:
    """Version of this extension from its manifest (empty if unreadable)."""
    import os
    import tomllib
    path = os.path.join(os.path.dirname(os.path.dirname(__file__)), "blender_manifest.toml")
    try:
        with open(path, "rb") as fh:
            return str(tomllib.load(fh).get("version", ""))
    except (OSError, ValueError):
        return ""


def new_report(argv: list[str]) -> dict[str, Any]:
    """A fresh report with the run's context; the CLI fills in the rest."""
    return {
        "tool": "eegt_blender",
        "version": extension_version(),
        "blender_version": bpy.app.version_string,
        "python": platform.python_version(),
        "argv": list(argv),
        "input": None,
        "output": None,
        "written": False,
        "params": None,
        "backend_requested": None,
        "objects": [],
        "skipped": [],  # mesh objects left alone: {"object": name, "reason": "no faces"}
        "error": None,
        "exit_code": None,
    }
