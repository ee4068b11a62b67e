"""A solver wrapper for the NumPy / OpenCL twin tests: every call's result, kept in order."""

from __future__ import annotations


class Recorder:
    """Wraps a solver and keeps every call's result."""

    def __init__(self, run):
        self.run, self.results = run, []

    def __call__(self, *args, **kw):
        out = self.run(*args, **kw)
        self.results.append((out[0].copy(), out[1]))
        return out
