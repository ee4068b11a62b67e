"""The checkout as the package the extension is installed as (``eegt_blender``): batch/ and
fileio/ import each other as siblings inside it (relative imports need a parent package),
so tests and test-file makers import them as ``eegt_blender.batch`` and
``eegt_blender.fileio``. The package's own __init__ imports no bpy (it registers the
operators only when Blender calls register())."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

PACKAGE = "eegt_blender"
ROOT = Path(__file__).resolve().parents[1]


def register() -> None:
    """Make ``eegt_blender`` importable as this checkout (once per process)."""
    if PACKAGE in sys.modules:
        return
    spec = importlib.util.spec_from_file_location(
        PACKAGE, ROOT / "__init__.py", submodule_search_locations=[str(ROOT)])
    package = importlib.util.module_from_spec(spec)
    sys.modules[PACKAGE] = package
    spec.loader.exec_module(package)
