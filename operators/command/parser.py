# SPDX-License-Identifier: GPL-3.0-or-later
"""The single-file command's argument parser (the batch adds its flags to it)."""

from __future__ import annotations

import argparse
from typing import Any

from ...core import EEGTParams
from ...core.choices import BACKEND, UV_SCOPE, UV_TARGET, ids
from ...fileio.solver_formats import SOLVER_EXTENSIONS
from ..ui import props
from . import metrics
from .usage import EXIT_OK, EXIT_USAGE, INPUT_EXTENSIONS, UsageError

_TYPES = "/".join(INPUT_EXTENSIONS)


class _Parser(argparse.ArgumentParser):
    """argparse that raises instead of calling sys.exit (Blender must keep running)."""

    def exit(self, status: int = 0, message: str | None = None) -> None:  # type: ignore[override]
        raise UsageError((message or "").strip(), EXIT_USAGE if status else EXIT_OK)

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(f"{self.prog}: error: {message}")


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser; one flag per EEGTParams field."""
    p = _Parser(prog="blender -b -c eegt",
                description="Untangle and smooth planar meshes (EEGT) in a .blend, OBJ, PLY "
                            "or STL file or a solver mesh (" + ", ".join(SOLVER_EXTENSIONS) +
                            "). Exit codes: 0 all valid, 3 some mesh failed, "
                            "2 bad arguments or input, 1 internal error.")
    p.add_argument("input", help=f"input {_TYPES} file (a .blend: all its mesh objects)")
    p.add_argument("-o", "--output", help=f"output {_TYPES} (nothing is written without it); "
                                          "the input file itself only with --in-place")
    p.add_argument("--in-place", action="store_true",
                   help="write the result over the input file (without -o, or with -o naming "
                        "it): it is replaced whole once the result is saved and checked")
    p.add_argument("--object", action="append", default=[], metavar="NAME",
                   help="only this mesh object (repeatable)")
    p.add_argument("--backend", choices=ids(BACKEND), default=None,
                   help="compute backend (default: the add-on preference, else numpy)")
    p.add_argument("--device", metavar="SPEC", default=None,
                   help="OpenCL device: 'platform:device' indices or part of its name "
                        "(default: the add-on preference, else automatic)")
    p.add_argument("--paper", action="store_true",
                   help="start from the paper's parameters instead of the defaults")
    group = p.add_argument_group("EEGT parameters")
    defaults = EEGTParams()
    for f in props.param_fields():
        default = getattr(defaults, f.name)
        kw: dict[str, Any] = {"dest": f.name, "default": None,
                              "help": f"{props.field_help(f)} (default {default})"}
        if isinstance(default, bool):
            kw["action"] = argparse.BooleanOptionalAction
        elif isinstance(default, int):
            kw["type"] = int
        elif isinstance(default, float):
            kw["type"] = float
        if f.name in props.STRING_CHOICES:
            kw["choices"] = [c[0] for c in props.STRING_CHOICES[f.name]]
        group.add_argument(_flag(f.name), **kw)
    p.add_argument("--no-pinned", action="store_true",
                   help="ignore the eegt_pinned attribute / vertex group (with --uv: the "
                        "UV pins)")
    p.add_argument("--uv", nargs="?", const="", default=None, metavar="MAP",
                   help="untangle and smooth the UV map MAP (default: the active one) of "
                        "every chosen object instead of its vertex positions; objects "
                        "without it are skipped")
    p.add_argument("--uv-scope", choices=ids(UV_SCOPE), default=UV_SCOPE[0].id,
                   help="with --uv: move only tangled faces and the faces around them "
                        "(tangles, default) or every face (selection)")
    p.add_argument("--uv-target", choices=ids(UV_TARGET), default=UV_TARGET[0].id,
                   help="with --uv: the shape each UV face is pulled towards: " +
                        ", ".join(f"{c.id} ({c.label})" for c in UV_TARGET) +
                        f" (default {UV_TARGET[0].id})")
    p.add_argument("--project", action="store_true",
                   help="project slightly non-planar meshes onto their plane")
    p.add_argument("--reference", metavar="OBJ", default=None,
                   help="target 'reference': an OBJ file of the same topology (same vertex "
                        "order and faces) whose face shapes are the targets (implies --target "
                        "reference)")
    p.add_argument("--reference-key", metavar="NAME", default=None,
                   help="target 'reference': the shape key whose face shapes are the targets "
                        "(implies --target reference; default with --target reference: the "
                        "Basis key when another key is active)")
    p.add_argument("--report", metavar="JSON", help="write a JSON report here")
    p.add_argument("--metrics", type=metrics.parse_names, metavar="LIST", default=(),
                   help="add the before/after min/mean/max and count beyond the threshold of "
                        "these quality measures to each object's report entry: all, or a "
                        "comma list of " + ", ".join(metrics.MEASURE_NAMES))
    p.add_argument("--no-write-on-fail", action="store_true",
                   help="leave a mesh unchanged when it could not be untangled")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    _solver_arguments(p)
    return p


def _solver_arguments(p: argparse.ArgumentParser) -> None:
    """The solver mesh flags (docs/engineers.md; checked and used by solver_run.py)."""
    g = p.add_argument_group("solver meshes (" + ", ".join(SOLVER_EXTENSIONS) + ")")
    g.add_argument("--pin-field", metavar="NAME", default=None,
                   help="pin the nodes where this point-data array is non-zero")
    g.add_argument("--fixed-groups", metavar="G1,G2", default=None,
                   help="physical groups (names or tags) whose nodes stay where they are")
    g.add_argument("--slide-groups", metavar="G1,G2", default=None,
                   help="physical groups (names or tags) whose boundary nodes slide along "
                        "the boundary; the rest of the boundary follows --boundary")
