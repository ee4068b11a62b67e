"""What a device program is built from: its source (the common header `common.cl` in front
of the file's text) and its options (the host's constants as `-D` defines, so that Python
and the kernels share one definition of each). No pyopencl here."""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .. import fpmath

__all__ = [
    "COMMON_FILE",
    "EEGT_FILE",
    "NCACHE",
    "NGON_MAXN",
    "build_error",
    "cl_defines",
    "eegt_options",
    "eegt_source",
    "fpmath_options",
    "kernel_file",
    "program_size",
    "program_source",
]

HERE = Path(__file__).parent
COMMON_FILE = HERE / "common.cl"  # in front of every program
EEGT_FILE = HERE / "eegt_kernels.cl"  # the EEGT iteration (core.eegt.engine_opencl)
NCACHE = 8  # nearest boundary nodes cached per face for the distance refresh
NGON_MAXN = 16  # private-array size of the generic n-gon kernels (bigger faces: own build)


def kernel_file(name: str) -> Path:
    """A kernel source of this package by file name."""
    return HERE / name


def program_source(path: Path) -> str:
    """The OpenCL C source of a program: the shared header (common.cl: fpmath, NumPy's
    pairwise sums), then the file's own text, its lines numbered as in the file (a build
    error names the file's line)."""
    return (f'#line 1 "{COMMON_FILE.name}"\n{COMMON_FILE.read_text()}\n'
            f'#line 1 "{path.name}"\n{path.read_text()}')


def cl_defines(values: Mapping[str, float]) -> list[str]:
    """Build options `-DNAME=value` that give the kernels the host's constants: integers in
    decimal, floats as hex floats (the exact double, no decimal round trip)."""
    out = []
    for name, v in values.items():
        if isinstance(v, (bool, int, np.integer)):
            out.append(f"-D{name}={int(v)}")
        elif np.isfinite(v):
            out.append(f"-D{name}=({float(v).hex()})")
        else:
            raise ValueError(f"{name} = {v}: not a finite constant")
    return out


def fpmath_options() -> list[str]:
    """Build options defining core.fpmath's constants, which every program is built with:
    the log / exp constants (hex floats: the kernels compute with the exact doubles the
    host's fpmath uses), power's fast-path codes and NumPy's summation cut points."""

    def hexes(values) -> str:
        return ",".join(float(v).hex() for v in values)

    scalars = {
        **fpmath.KERNEL_SCALARS,
        "PW_BLOCK": fpmath.PAIRWISE_BLOCK,
        "CHUNK": fpmath.REDUCE_CHUNK,
        **fpmath.POW_CODES,
    }
    return [
        f"-DFP_LOG_C={hexes(fpmath.LOG_COEFFS)}",
        f"-DFP_EXP_C={hexes(fpmath.EXP_COEFFS)}",
        *cl_defines(scalars),
    ]


def build_error(exc: Exception) -> str:
    """The compiler's first error line, without temporary file names (stable across runs)."""
    text = str(exc)
    for line in text.splitlines():
        if "error" not in line:
            continue
        m = re.search(r":(\d+):(\d+):\s*(?:error:\s*)?(.*)", line)  # [error: ]FILE:L:C: what
        return f"line {m[1]}:{m[2]}: {m[3].strip()}" if m else line.strip()
    return " ".join(text.split())[:200]


def program_size(max_face_size: int) -> int:
    """The MAXN the EEGT kernels are built with for faces of up to this many corners."""
    n = int(max_face_size)
    return NGON_MAXN if n <= NGON_MAXN else 1 << (n - 1).bit_length()


def eegt_source() -> str:
    """The OpenCL C source of the EEGT kernels."""
    return program_source(EEGT_FILE)


def eegt_options(maxn: int) -> list[str]:
    """The EEGT kernels' build options for faces of up to `maxn` corners."""
    return [f"-DMAXN={maxn}", f"-DNCACHE={NCACHE}", *fpmath_options()]
