# SPDX-License-Identifier: GPL-3.0-or-later
"""The batch flags of the ``eegt`` command, when a command line is a batch, and the
single-file flags handed on to every worker.

The batch parser is the single-file parser with INPUT taking many values and these flags
added, so every single-file flag (present or future) is accepted in a batch and handed on
unchanged.
"""

from __future__ import annotations

import argparse
import os
from typing import Any

from .inputs import FORMATS, has_magic

# dest -> its flag; every flag that only a batch has
BATCH_FLAGS = {"jobs": "--jobs", "timeout": "--timeout", "skip_existing": "--skip-existing",
               "recursive": "--recursive", "suffix": "--suffix", "format": "--format",
               "dask": "--dask", "files_per_worker": "--files-per-worker"}
# single-file flags a batch sets itself for each worker
PER_FILE = ("input", "output", "report", "help")


def add_batch_arguments(p: argparse.ArgumentParser) -> None:
    """Turn the single-file parser `p` into the batch parser (in place)."""
    for action in p._actions:
        if action.dest == "input":
            action.nargs = "+"
            action.help = ("input files (.blend, .obj, .ply, .stl), folders or quoted glob "
                           "patterns ('meshes/**/*.obj'); many run as a batch")
        elif action.dest == "output":
            action.help = ("output file for one input, or output folder (OUTDIR) for many: "
                           "each output keeps its input's path relative to the folder or "
                           "pattern it came from; an output that is its input only with "
                           "--in-place")
        elif action.dest == "report":
            action.help = ("write a JSON report here (a batch also writes a CSV beside it; "
                           "default OUTDIR/eegt_report.json)")
    g = p.add_argument_group("batch (many inputs, an output folder, or any flag below)")
    g.add_argument("-j", "--jobs", type=int, default=None, metavar="N",
                   help="worker processes, each a separate blender -b (default: one per core)")
    g.add_argument("--files-per-worker", type=int, default=None, metavar="K",
                   help="files one worker Blender runs in turn before a fresh one replaces it "
                        "(default 1: a fresh Blender per file; more saves its start-up, a "
                        "crash or timeout still ends only the current file)")
    g.add_argument("--timeout", type=float, default=None, metavar="S",
                   help="seconds per file before its worker is killed (reported 'timeout')")
    g.add_argument("--skip-existing", action="store_true",
                   help="skip inputs whose output exists and is not older (resume a batch)")
    g.add_argument("--recursive", action="store_true",
                   help="search input folders' subfolders too")
    g.add_argument("--suffix", default="", metavar="TEXT",
                   help="added to each output's name before its extension (e.g. _fixed)")
    g.add_argument("--format", choices=FORMATS, default=None,
                   help="output type (default: the input's)")
    g.add_argument("--dask", metavar="ADDRESS", default=None,
                   help="run the files on a Dask cluster (tcp://HOST:8786), or local:N for a "
                        "LocalCluster of N workers (needs dask and distributed)")


def batch_flag_in(argv: list[str]) -> bool:
    """Whether a batch-only flag (or its abbreviation) appears in `argv`."""
    for tok in argv:
        if tok == "--":
            return False
        name = tok.split("=", 1)[0]
        if name == "-j" or (name.startswith("-j") and name[2:].isdigit()):
            return True
        if len(name) > 3 and name.startswith("--") and \
                any(f.startswith(name) for f in BATCH_FLAGS.values()):
            return True
    return False


def is_batch(ns: argparse.Namespace) -> bool:
    """Many inputs, a folder or a glob pattern, an output folder, or a batch flag."""
    if len(ns.input) != 1 or any(_given(getattr(ns, d)) for d in BATCH_FLAGS):
        return True
    inp = ns.input[0]
    if os.path.isdir(inp) or (has_magic(inp) and not os.path.lexists(inp)):
        return True
    out = ns.output
    return bool(out) and (os.path.isdir(out) or out.endswith(("/", os.sep)))


def _given(value: Any) -> bool:
    return value is not None and value is not False and value != ""


class _Unset:
    """Marks a flag absent from the command line in the raw parse (copies are itself)."""

    def __copy__(self) -> _Unset:
        return self

    def __deepcopy__(self, memo: Any) -> _Unset:
        return self


UNSET = _Unset()
_LISTS = (argparse._AppendAction, argparse._AppendConstAction, argparse._CountAction)


def passthrough(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """The single-file flags given in `argv`, as the text they were given in (so a flag
    whose type parses its text is handed on exactly), for the single-file parser of every
    worker; batch flags and the per-file ones (input, output, report) are left out. `argv`
    must already parse with `parser`."""
    saved = [(a, a.type, a.choices, a.default) for a in parser._actions]
    try:
        for a in parser._actions:  # read every value as its raw text
            a.type, a.choices = None, None
            if a.option_strings:
                a.default = None if isinstance(a, _LISTS) else UNSET
        raw = parser.parse_intermixed_args(argv)
    finally:
        for a, type_, choices, default in saved:
            a.type, a.choices, a.default = type_, choices, default
    out: list[str] = []
    for a in parser._actions:
        if not a.option_strings or a.dest in PER_FILE or a.dest in BATCH_FLAGS:
            continue
        value = getattr(raw, a.dest, UNSET)
        if value is UNSET or value is None:
            continue
        longs = [s for s in a.option_strings if s.startswith("--")]
        out += _tokens(a, longs[0] if longs else a.option_strings[0], value)
    return out


def _tokens(a: argparse.Action, flag: str, value: Any) -> list[str]:
    if isinstance(a, argparse.BooleanOptionalAction):
        return [flag if value else "--no-" + flag[2:]]
    if isinstance(a, argparse._StoreConstAction):  # store_true / store_false too
        return [flag]
    if isinstance(a, argparse._CountAction):
        return [flag] * int(value)
    if isinstance(a, argparse._AppendConstAction):
        return [flag] * len(value)
    if isinstance(a, argparse._AppendAction):
        return [f"{flag}={v}" for v in value]
    if isinstance(a, argparse._StoreAction) and a.nargs in (None, "?"):
        return [flag] if value is a.const and a.nargs == "?" else [f"{flag}={value}"]
    if isinstance(a, argparse._StoreAction):
        return [flag, *(str(v) for v in value)]
    raise TypeError(f"eegt: cannot hand the flag {flag} ({type(a).__name__}) on to workers")
