"""Histograms of quality measures before and after untangling (docs/measures.md, README).

Untangles bundled meshes with the default parameters (NumPy core), prints a markdown table
of every measure's min / mean / max and count beyond its threshold before -> after, and
draws one PNG: a row per mesh, a column per chosen measure, the input's histogram and the
result's on shared bins, with the threshold marked.

Run: `python -m bench.measures_histogram [--meshes naca_deform,tri_two_holes]
[--measures min_angle,scaled_jacobian] [--out docs/measures_histogram.png]`.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from core import MEASURE_NAMES, MEASURES, summarize, untangle_and_smooth
from core.mesh.obj_io import read_obj
from core.metrics.face_quality import quality

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"


def _names(text: str, valid: tuple[str, ...] | None = None) -> list[str]:
    names = [w.strip() for w in text.split(",") if w.strip()]
    bad = [n for n in names if valid is not None and n not in valid]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"unknown name {bad[0] if bad else text!r}")
    return names


def run_mesh(name: str) -> dict:
    """Input and untangled points of tests/data/NAME.obj with every measure's values."""
    v, faces = read_obj(DATA / f"{name}.obj")
    before = v[:, :2].copy()
    t0 = time.perf_counter()
    res = untangle_and_smooth(before, faces)
    seconds = time.perf_counter() - t0
    values = {state: {m: quality(p, faces, measure=m) for m in MEASURE_NAMES}
              for state, p in (("before", before), ("after", res.points))}
    return {"name": name, "faces": faces, "values": values, "status": res.status,
            "seconds": seconds}


def table(runs: list[dict]) -> str:
    """Markdown: per mesh and measure, min / mean / max and the count beyond, before ->
    after."""
    rows = ["| mesh | measure | threshold | min | mean | max | beyond |",
            "|---|---|---|---|---|---|---|"]
    for r in runs:
        for m in MEASURE_NAMES:
            b, a = (summarize(m, r["values"][s][m], r["faces"].counts)
                    for s in ("before", "after"))
            word = "<" if b.higher_is_better else ">"
            thr = ", ".join(f"{word} {t:g}" for t in b.thresholds.values())
            rows.append(
                f"| {r['name']} | {MEASURES[m].label} | {thr} | {b.min:.3g} -> {a.min:.3g} | "
                f"{b.mean:.3g} -> {a.mean:.3g} | {b.max:.3g} -> {a.max:.3g} | "
                f"{b.n_beyond} -> {a.n_beyond} of {b.n_faces} |")
    return "\n".join(rows)


def _bins(measure: str, data: np.ndarray) -> tuple[np.ndarray, bool]:
    """Shared bins for both states; logarithmic for the aspect ratio (>= 1, long tail)."""
    if measure == "aspect_ratio":
        hi = min(float(data.max()), 1e4)
        return np.geomspace(1.0, max(hi, 10.0), 61), True
    lo, hi = float(data.min()), float(data.max())
    if hi <= lo:
        hi = lo + 1.0
    return np.linspace(lo, hi, 61), False


def draw(runs: list[dict], measures: list[str], path: Path) -> None:
    fig, axes = plt.subplots(len(runs), len(measures), figsize=(4.6 * len(measures),
                                                                 3.2 * len(runs)),
                             dpi=110, squeeze=False)
    for row, r in zip(axes, runs):
        for ax, m in zip(row, measures):
            b, a = r["values"]["before"][m], r["values"]["after"][m]
            bins, log = _bins(m, np.concatenate([b, a]))
            n = r["faces"].counts
            sb, sa = summarize(m, b, n), summarize(m, a, n)
            word = "below" if sb.higher_is_better else "above"
            ax.hist(np.clip(b, bins[0], bins[-1]), bins=bins, color="#d62728", alpha=0.45,
                    label=f"input: {sb.n_beyond} {word}")
            ax.hist(np.clip(a, bins[0], bins[-1]), bins=bins, color="#2ca02c", alpha=0.6,
                    label=f"result: {sa.n_beyond} {word}")
            for t in sb.thresholds.values():
                ax.axvline(t, color="k", linestyle="--", linewidth=1)
            if log:
                ax.set_xscale("log")
            ax.set_yscale("log")
            unit = f" ({MEASURES[m].unit})" if MEASURES[m].unit else ""
            ax.set_title(f"{r['name']}: {MEASURES[m].label}{unit}", fontsize=9)
            ax.set_ylabel("faces", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.legend(fontsize=7, loc="upper left" if sb.higher_is_better else "upper right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", type=_names, default=["naca_deform", "tri_two_holes"],
                    help="comma list of tests/data mesh names")
    ap.add_argument("--measures", type=lambda t: _names(t, MEASURE_NAMES),
                    default=["min_angle", "scaled_jacobian"],
                    help="comma list of measures to draw (" + ", ".join(MEASURE_NAMES) + ")")
    ap.add_argument("--out", default=str(ROOT / "docs" / "measures_histogram.png"))
    args = ap.parse_args()
    runs = []
    for name in args.meshes:
        r = run_mesh(name)
        print(f"{name}: {r['status']} in {r['seconds']:.2f} s", flush=True)
        runs.append(r)
    print(table(runs))
    draw(runs, args.measures, Path(args.out))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
