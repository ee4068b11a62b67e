"""Shared by every test folder: tests/ on ``sys.path``, so ``import meshdata`` (the one mesh
loader, tests/meshdata.py) works from tests/core, tests/opencl, tests/blender and tests/batch
whatever pytest's import mode."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

TESTS = str(Path(__file__).resolve().parent)
if TESTS not in sys.path:
    sys.path.insert(0, TESTS)

# The checkout as the package the extension is installed as: batch/ and fileio/ import each
# other as siblings inside it (relative imports need a parent package), so their tests import
# them as `eegt_blender.batch` and `eegt_blender.fileio`. The package's own __init__ imports
# no bpy (it registers the operators only when Blender calls register()).
PACKAGE = "eegt_blender"
if PACKAGE not in sys.modules:
    _root = Path(__file__).resolve().parents[1]
    _spec = importlib.util.spec_from_file_location(
        PACKAGE, _root / "__init__.py", submodule_search_locations=[str(_root)])
    _package = importlib.util.module_from_spec(_spec)
    sys.modules[PACKAGE] = _package
    _spec.loader.exec_module(_package)
