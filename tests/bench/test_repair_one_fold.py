"""bench.repair_one_fold on a 40 x 40 grid: the fold is repaired, only nodes near it move."""

import numpy as np

from bench import repair_one_fold as rof
from core import EEGTParams, mesh_stats, untangle_and_smooth


def test_one_fold_grid_folds_four_quads_and_the_repair_moves_only_nodes_near_it(capsys):
    p, quads, fixed = rof.one_fold(40)
    assert mesh_stats(p, quads).n_inverted == 4
    res = untangle_and_smooth(p, quads, fixed=fixed,
                              params=EEGTParams(target="keep", region="folds"))
    assert res.after.n_inverted == 0
    moved = np.flatnonzero(res.moved)
    centre = p[41 * 20 + 20]
    assert 0 < moved.size < 100 and np.all(np.abs(p[moved, 0] - centre[0]) <= 6)
    assert np.array_equal(res.points[~res.moved], p[~res.moved])
    assert rof.main(["--n", "40", "--runs", "2"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("1600 quads, 4 folded: untangled, 0 inverted, ")
    assert "the others bit-identical: True" in out and "fastest of 2" in out
