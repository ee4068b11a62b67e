"""bench.measures_histogram: its table and picture on a small bundled mesh."""

import argparse

import numpy as np
import pytest
from meshdata import load2d

from bench.measures_histogram import _names, draw, run_mesh, table
from core import MEASURE_NAMES, quality


def test_quad_hole_table_and_png(tmp_path):
    r = run_mesh("quad_hole")
    p, f = load2d("quad_hole")
    assert r["status"] == "untangled"
    for m in MEASURE_NAMES:
        assert np.array_equal(r["values"]["before"][m], quality(p, f, measure=m))
    assert (r["values"]["after"]["scaled_jacobian"] > 0).all()
    text = table([r]).splitlines()
    assert len(text) == 2 + len(MEASURE_NAMES)
    # 23 inverted faces in the input, none after: all below the mean ratio's 0.5
    mean_ratio = next(t for t in text if "Mean Ratio" in t)
    assert "| 0 -> " in mean_ratio and " of 140 |" in mean_ratio
    png = tmp_path / "h.png"
    draw([r], ["min_angle", "aspect_ratio"], png)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def test_unknown_measure_name_is_refused():
    with pytest.raises(argparse.ArgumentTypeError, match="unknown name 'bogus'"):
        _names("min_angle,bogus", MEASURE_NAMES)
