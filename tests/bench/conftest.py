"""Tests of the benchmark scripts in bench/ (not of the core or the extension): every test in
this folder is marked ``bench`` (``make test-bench`` runs them alone; ``make test``,
``test-fast`` and ``test-core`` run them with the rest). A test that only uses a bench mesh
generator as its data stays with the code it tests."""

from __future__ import annotations

from pathlib import Path

import pytest


def pytest_collection_modifyitems(items):
    here = Path(__file__).parent
    for item in items:
        if Path(str(item.fspath)).is_relative_to(here):
            item.add_marker(pytest.mark.bench)
