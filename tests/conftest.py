"""Shared by every test folder: tests/ on ``sys.path``, so ``import meshdata`` (the one mesh
loader, tests/meshdata.py) works from tests/core, tests/opencl, tests/blender and tests/batch
whatever pytest's import mode."""

from __future__ import annotations

import sys
from pathlib import Path

TESTS = str(Path(__file__).resolve().parent)
if TESTS not in sys.path:
    sys.path.insert(0, TESTS)

import checkout_package  # noqa: E402 (tests/ on the path first)

checkout_package.register()  # eegt_blender.batch, eegt_blender.fileio
