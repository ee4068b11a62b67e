"""Benchmarks, demo and pictures (not part of the extension zip)."""
