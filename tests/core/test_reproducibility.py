"""Same input, same bits on every x86-64 CPU: the NumPy backend run with NumPy's SIMD dispatch
restricted (as on a CPU without AVX-512, and on a baseline SSE3-only one) and OpenBLAS on
other kernels gives points bit-identical to the unrestricted run on the shared meshes."""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]

# default parameters on every shared mesh; the paper's mode on three (EEGT only)
CHILD = r"""
import hashlib, json, sys
import numpy as np
sys.path[:0] = [sys.argv[1], sys.argv[1] + "/tests"]
from core import EEGTParams, untangle_and_smooth, untangle_and_smooth_3d
from meshdata import load
out = {}
cases = [(n, "default") for n in ("quad_hole", "tri_two_holes", "mixed_quad_tri",
         "polygon_voronoi", "tilted_plane", "naca_deform", "two_holes_twist")]
cases += [(n, "paper") for n in ("quad_hole", "mixed_quad_tri", "tilted_plane")]
for name, mode in cases:
    p, fs = load(name)
    prm = EEGTParams.paper() if mode == "paper" else EEGTParams()
    if np.ptp(p[:, 2]) > 0:
        r = untangle_and_smooth_3d(p, fs, params=prm)
    else:
        r = untangle_and_smooth(p[:, :2], fs, params=prm)
    digest = hashlib.sha256(np.ascontiguousarray(r.points).tobytes()).hexdigest()
    out[f"{name}/{mode}"] = [digest, r.status, r.global_iterations, r.after.q_min]
print(json.dumps(out))
"""


def _numpy_cpu() -> tuple[list[str], dict[str, bool]]:
    try:
        from numpy._core import _multiarray_umath as mu  # NumPy 2
    except ImportError:
        from numpy.core import _multiarray_umath as mu  # NumPy 1.26
    return list(mu.__cpu_dispatch__), dict(mu.__cpu_features__)


def _run(env_extra: dict[str, str], python: str = sys.executable) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE")}
    env.update(env_extra)
    done = subprocess.run([python, "-c", CHILD, str(ROOT)], env=env,
                          capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@functools.cache
def _reference() -> dict:
    """This interpreter's results with its NumPy unrestricted."""
    return _run({})


@pytest.mark.slow
def test_shared_meshes_bit_identical_without_avx512_and_on_baseline_simd() -> None:
    dispatch, found = _numpy_cpu()
    have = [f for f in dispatch if found.get(f)]
    if not have:
        pytest.skip("this NumPy dispatches no SIMD extension on this CPU: nothing to restrict")
    reference = _reference()
    assert all(v[1] == "untangled" for v in reference.values()), reference
    no_avx512 = [f for f in have if f.startswith("AVX512")]
    variants = {"baseline": {"NPY_DISABLE_CPU_FEATURES": " ".join(have),
                             "OPENBLAS_CORETYPE": "Prescott"}}
    if no_avx512:  # what an AVX2 machine (e.g. AMD Zen 1-3, Intel Haswell) runs
        variants["no AVX-512"] = {"NPY_DISABLE_CPU_FEATURES": " ".join(no_avx512),
                                  "OPENBLAS_CORETYPE": "Haswell"}
    for label, env in variants.items():
        got = _run(env)
        differ = sorted(k for k in reference if got[k] != reference[k])
        assert not differ, f"{label}: {differ}: {[(reference[k], got[k]) for k in differ]}"


NUMPY2_PYTHON = "EEGT_NUMPY2_PYTHON"  # an interpreter with NumPy >= 2.3 (`make numpy2`)


def _numpy_version(python: str) -> tuple[int, int]:
    done = subprocess.run([python, "-c", "import numpy; print(numpy.__version__)"],
                          capture_output=True, text=True, timeout=120, check=True)
    major, minor = done.stdout.strip().split(".")[:2]
    return int(major), int(minor)


@pytest.mark.slow
def test_shared_meshes_bit_identical_under_numpy_2_3_and_later() -> None:
    """NumPy 2.3 sums a long array as one pairwise tree where NumPy 1 and 2.2 add chunks in
    order; the core sums through fpmath.add_reduce, so both give the same points."""
    other = os.environ.get(NUMPY2_PYTHON) or str(ROOT / "build" / "numpy2" / "bin" / "python")
    if not Path(other).exists():
        pytest.skip(f"no NumPy >= 2.3 interpreter ({NUMPY2_PYTHON} unset, `make numpy2` "
                    "builds build/numpy2; `make test` does)")
    mine, theirs = _numpy_version(sys.executable), _numpy_version(other)
    assert theirs >= (2, 3), f"{other} has NumPy {theirs}, not >= 2.3"
    if mine >= (2, 3):
        pytest.skip(f"this interpreter's NumPy {mine} sums like the other's: nothing to compare")
    reference = _reference()
    got = _run({}, python=other)
    differ = sorted(k for k in reference if got[k] != reference[k])
    assert not differ, f"NumPy {theirs}: {[(k, reference[k], got[k]) for k in differ]}"


def code_only(text: str) -> list[str]:
    """The lines of Python source ``text`` with its strings (docstrings included) and
    comments blanked out: what runs, at its columns. An f-string's expressions stay (its
    literal text too before Python 3.12, which tokenizes an f-string as one string)."""
    import io
    import tokenize

    lines = [list(line) for line in text.splitlines()]
    prose = {tokenize.STRING, tokenize.COMMENT, getattr(tokenize, "FSTRING_MIDDLE", -1)}
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type not in prose or (tok.type == tokenize.STRING
                                     and "f" in tok.string.split(tok.string[-1])[0].lower()):
            continue
        (r0, c0), (r1, c1) = tok.start, tok.end
        for r in range(r0, r1 + 1):
            row = lines[r - 1]
            row[c0 if r == r0 else 0 : c1 if r == r1 else len(row)] = " " * (
                (c1 if r == r1 else len(row)) - (c0 if r == r0 else 0))
    return ["".join(row) for row in lines]


def test_code_only_blanks_strings_and_comments_not_code() -> None:
    src = 'x = a @ b  # c @ d\n"""doc: np.log(x)\ny @ z"""\nf"{np.exp(t)} @ u"\nw = q ** p\n'
    out = code_only(src)
    assert out[0].rstrip() == "x = a @ b" and out[1].strip() == out[2].strip() == ""
    assert "np.exp(t)" in out[3] and out[4] == "w = q ** p"


def test_core_never_calls_cpu_dispatched_math() -> None:
    """Static guard: no NumPy transcendental (dispatched by CPU feature) and no BLAS product
    inside core/'s code (its docstrings and comments may name them); core.fpmath provides
    the portable versions."""
    import re

    banned = re.compile(r"np\.(log|log2|log10|log1p|exp|exp2|expm1|power|tan|arctan2|arctan|"
                        r"hypot|cbrt|dot|matmul|einsum|inner|vdot|linalg)\b|\s@\s|[\w)\]]\s*\*\*\s*[a-z(]")
    hits = []
    for path in sorted((ROOT / "core").rglob("*.py")):
        text = path.read_text()
        for no, (line, code) in enumerate(zip(text.splitlines(), code_only(text)), 1):
            if banned.search(code):
                hits.append(f"{path.name}:{no}: {line.strip()}")
    assert not hits, "\n".join(hits)


def test_fpmath_matches_libm_within_a_few_ulp() -> None:
    from core import fpmath

    rng = np.random.default_rng(7)
    x = np.concatenate([np.exp(rng.uniform(-700, 700, 20000)), rng.uniform(0.5, 2, 20000)])
    ulp = np.abs(fpmath.log(x) - np.log(x)) / np.spacing(np.abs(np.log(x)) + 1e-300)
    assert ulp.max() <= 4
    y = rng.uniform(-700, 700, 20000)
    assert (np.abs(fpmath.exp(y) - np.exp(y)) / np.spacing(np.exp(y))).max() <= 4
    z = rng.uniform(1e-3, 1e3, 20000)
    rel = np.abs(fpmath.power(z, 1.7) - z**1.7) / z**1.7
    assert rel.max() < 1e-14
    assert np.array_equal(fpmath.power(z, 2.0), z * z)  # NumPy's own fast path, exactly
    assert np.array_equal(fpmath.power(z, 0.5), np.sqrt(z))
    assert fpmath.regular_corner(3) == (0.5, 0.5 * np.sqrt(3.0))
    assert fpmath.regular_corner(4) == (0.0, 1.0)
    for n in (5, 7, 8, 12, 50):
        c, s = fpmath.regular_corner(n)
        a = (n - 2) * np.pi / n
        assert abs(c - np.cos(a)) < 1e-15 and abs(s - np.sin(a)) < 1e-15
        assert abs(fpmath.tan_pi_over(n) - np.tan(np.pi / n)) < 1e-15 * np.tan(np.pi / n) * 4
    specials = fpmath.exp(np.array([0.0, 800.0, -800.0, np.nan]))
    assert specials[0] == 1.0 and specials[1] == np.inf and specials[2] == 0.0
    assert np.isnan(specials[3])
