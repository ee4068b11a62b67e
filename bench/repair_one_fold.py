"""A small fold in a large mesh (docs/repair.md, "Time beyond the region"): a grid of
n x n anisotropic quads (cells 100 times wider than tall, a boundary-layer aspect) with one
node pushed up across three rows and the node above it across one, boundary fixed,
repaired by region "folds" with target "keep". What a repair costs beyond its region: the
passes over the whole mesh. Reports the median and the fastest of `--runs` runs.

Run: `python -m bench.repair_one_fold` (1M quads), `--n 300 --runs 3`.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from core import EEGTParams, untangle_and_smooth
from core.mesh.faces import as_faceset
from core.metrics.face_quality import inverted_corners


def one_fold(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points, quads, fixed) of the n x n grid with its fold near the centre."""
    m = n + 1
    xs, ys = np.meshgrid(np.arange(m, dtype=float), np.arange(m, dtype=float) * 0.01)
    p = np.column_stack([xs.ravel(), ys.ravel()])
    idx = np.arange(m * m).reshape(m, m)
    quads = np.column_stack([idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(),
                             idx[1:, 1:].ravel(), idx[1:, :-1].ravel()])
    c = n // 2
    p[idx[c, c], 1] += 0.035  # across three rows
    p[idx[c + 1, c], 1] += 0.012  # and the node above it across one
    fixed = np.zeros(m * m, dtype=bool)
    fixed[idx[0]] = fixed[idx[-1]] = fixed[idx[:, 0]] = fixed[idx[:, -1]] = True
    return p, quads, fixed


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="cells per side (n x n quads)")
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args(argv)
    p, quads, fixed = one_fold(args.n)
    folded = int(inverted_corners(p, as_faceset(quads, len(p))).sum())
    params = EEGTParams(target="keep", region="folds")
    secs = []
    for _ in range(max(args.runs, 1)):
        t0 = time.perf_counter()
        res = untangle_and_smooth(p, quads, fixed=fixed, params=params)
        secs.append(time.perf_counter() - t0)
    stay = ~res.moved
    kept = bool(np.array_equal(res.points[stay], p[stay]))
    print(f"{len(quads)} quads, {folded} folded: {res.status}, {res.after.n_inverted} inverted, "
          f"{int(res.moved.sum())} nodes moved, the others bit-identical: {kept}; "
          f"{np.median(secs):.2f} s median, {min(secs):.2f} s fastest of {len(secs)}")
    print(res.message)
    return 0 if res.after.n_inverted == 0 and kept else 3


if __name__ == "__main__":
    raise SystemExit(main())
