# SPDX-License-Identifier: GPL-3.0-or-later
"""Which files a batch works on, where each one's output goes, and which are up to date.

Patterns are expanded here rather than by the shell, so that a quoted ``"meshes/**/*.obj"``
means the same on every shell and OS. Folders and glob matches keep only mesh files (the
types the single-file command reads) and never hidden ones (the command's own temporary
files start with a dot); a file named explicitly is always taken, so that a wrong one is
reported rather than silently dropped.
"""

from __future__ import annotations

import glob
import os
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from ..fileio.solver_formats import SOLVER_EXTENSIONS, SOLVER_FORMATS

# Every file type the command reads and writes: Blender's own, then the solver meshes.
MESH_EXTENSIONS = (".blend", ".obj", ".ply", ".stl", *SOLVER_EXTENSIONS)
# The hint of an "unsupported ... type" message (the single-file command's too).
USE_TYPES = "use " + ", ".join(MESH_EXTENSIONS[:-1]) + " or " + MESH_EXTENSIONS[-1]
FORMATS = ("obj", "ply", "stl", "blend", *SOLVER_FORMATS)
_MAGIC = re.compile(r"[*?[]")
_TYPES = "/".join(MESH_EXTENSIONS)
# The single-file command's temporary names: ".NAME.eegt-tmp-PID.EXT" (a .blend is first
# written by Blender to that name plus "@").
_TEMPORARY = re.compile(r"^\..+\.eegt-tmp-(\d+)(\.[A-Za-z0-9]+)?@?$")


class PlanError(ValueError):
    """A problem with the batch as a whole (one line, exit code 2)."""


@dataclass(frozen=True)
class Source:
    """One input file: its path, the relative path its output keeps under OUTDIR, and why it
    cannot be run at all (missing, unsupported type), if so."""

    path: str
    rel: str
    problem: str | None = None


def has_magic(text: str) -> bool:
    """Whether `text` is a glob pattern (``*``, ``?`` or ``[``)."""
    return _MAGIC.search(text) is not None


def is_mesh_name(name: str) -> bool:
    """A visible file name with one of the mesh extensions (any case)."""
    return not name.startswith(".") and os.path.splitext(name)[1].lower() in MESH_EXTENSIONS


def expand(patterns: Sequence[str], recursive: bool = False,
           exclude: Iterable[str] = ()) -> tuple[list[Source], list[str]]:
    """The input files named by files, folders and glob patterns, in the order given (sorted
    within a folder or pattern, each file once), and a note for every pattern or folder that
    gave none. ``**`` in a pattern matches any depth; folders are searched below their top
    level only with `recursive`. Nothing inside an `exclude` folder (the output folder) is an
    input, except a file named explicitly, unless that folder is itself one of the folders
    named (its files are then their own outputs)."""
    named = {_real(p) for p in patterns if os.path.isdir(p)}
    excluded = [r for r in (_real(p) for p in exclude) if r not in named]
    found: list[Source] = []
    notes: list[str] = []
    for pattern in patterns:
        if os.path.isdir(pattern):
            files = _folder(pattern, recursive, excluded)
            found += [Source(f, os.path.relpath(f, pattern)) for f in files]
            if not files:
                notes.append(_empty_folder_note(pattern, recursive))
        elif os.path.lexists(pattern):
            found.append(_explicit(pattern))
        elif has_magic(pattern):
            sources = _glob(pattern, recursive, excluded)
            found += sources
            if not sources:
                notes.append(f"eegt: '{pattern}' matched no {_TYPES} files")
        else:
            found.append(Source(pattern, os.path.basename(pattern),
                                f"eegt: cannot read input '{pattern}': no such file"))
    seen: set[str] = set()
    unique = []
    for src in found:
        key = _real(src.path)
        if key not in seen:
            seen.add(key)
            unique.append(src)
    return unique, notes


def _real(path: str) -> str:
    return os.path.normcase(os.path.realpath(path))


def _inside(path: str, folders: list[str]) -> bool:
    real = _real(path)
    return any(real == f or real.startswith(f.rstrip(os.sep) + os.sep) for f in folders)


def _folder(root: str, recursive: bool, excluded: list[str]) -> list[str]:
    """Mesh files in `root` (and below it with `recursive`), sorted, hidden ones skipped;
    symbolic links to folders are not followed (no cycles)."""
    files = []
    for folder, subfolders, names in os.walk(root):
        subfolders[:] = sorted(d for d in subfolders if recursive and not d.startswith(".")
                               and not _inside(os.path.join(folder, d), excluded))
        files += [os.path.join(folder, n) for n in sorted(names)
                  if is_mesh_name(n) and os.path.isfile(os.path.join(folder, n))]
    return files


def _empty_folder_note(folder: str, recursive: bool) -> str:
    note = f"eegt: folder '{folder}' has no {_TYPES} files"
    if not recursive and any(e.is_dir() and not e.name.startswith(".")
                             for e in os.scandir(folder)):
        note += " (--recursive searches its subfolders)"
    return note


def _explicit(path: str) -> Source:
    """A file named on the command line: taken whatever it is, unless its type cannot be
    read (the message is the single-file command's)."""
    ext = os.path.splitext(path)[1].lower()
    if not os.path.exists(path):  # a broken symbolic link
        return Source(path, os.path.basename(path),
                      f"eegt: cannot read input '{path}': no such file")
    if ext not in MESH_EXTENSIONS:
        return Source(path, os.path.basename(path),
                      f"eegt: unsupported input type '{ext or os.path.basename(path)}' "
                      f"({USE_TYPES})")
    return Source(path, os.path.basename(path))


def glob_base(pattern: str) -> str:
    """The folder part of a pattern before its first wildcard: outputs keep the path of each
    match relative to it."""
    base = pattern
    while has_magic(base):
        base = os.path.dirname(base)
    return base or os.curdir


def _glob(pattern: str, recursive: bool, excluded: list[str]) -> list[Source]:
    base = glob_base(pattern)
    sources = []
    for match in sorted(glob.glob(pattern, recursive=True)):
        if _inside(match, excluded):
            continue
        if os.path.isdir(match):
            sources += [Source(f, os.path.relpath(f, base))
                        for f in _folder(match, recursive, excluded)]
        elif is_mesh_name(os.path.basename(match)) and os.path.isfile(match):
            sources.append(Source(match, os.path.relpath(match, base)))
    return sources


def output_path(src: Source, outdir: str, suffix: str = "", fmt: str | None = None) -> str:
    """OUTDIR/<relative path of the input><suffix>.<format or the input's extension>."""
    stem, ext = os.path.splitext(src.rel)
    return os.path.normpath(os.path.join(outdir, stem + suffix + ("." + fmt if fmt else ext)))


def same_file(a: str, b: str) -> bool:
    """Whether paths `a` and `b` name one file: the same file when both exist (through
    symbolic or hard links, any spelling of the path), else the same resolved path (a link
    to a file not there yet)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return _real(a) == _real(b)


def replaces_input(input_path: str, output: str | None, in_place: bool = False,
                   instead: str | None = None) -> str | None:
    """The one rule for an output that is its own input, in the single-file command and
    in every file of a batch: refused (this one-line reason, exit 2) unless --in-place asks
    for it; None when `output` may be written. `instead`: the batch's wording of what
    else to give."""
    if in_place or output is None or not same_file(input_path, output):
        return None
    if instead is None:
        return (f"eegt: -o '{output}' is the input file itself: give --in-place to replace "
                "it, or another output")
    return (f"eegt: the output of '{input_path}' would replace it: give --in-place to "
            f"replace it, or {instead}")


def check_outputs(sources: Sequence[Source], outputs: Sequence[str | None],
                  in_place: bool = False) -> None:
    """Raise PlanError when two inputs would write the same output or an output would
    replace its own input without `in_place`."""
    first: dict[str, str] = {}
    for src, out in zip(sources, outputs, strict=True):
        if out is None or src.problem:
            continue
        why = replaces_input(src.path, out, in_place,
                             "another -o folder, a --suffix or a --format")
        if why:
            raise PlanError(why)
        key = _real(out)
        if key in first:
            raise PlanError(f"eegt: '{first[key]}' and '{src.path}' would both write "
                            f"'{out}' (use --suffix, or inputs from one folder)")
        first[key] = src.path


def up_to_date(input_path: str, output: str | None) -> bool:
    """Whether `output` exists and is not older than `input_path` (what --skip-existing
    skips); never when the output is the input itself (--in-place)."""
    if output is None or same_file(input_path, output):
        return False
    try:
        return os.stat(output).st_mtime_ns >= os.stat(input_path).st_mtime_ns
    except OSError:
        return False


def pid_alive(pid: int) -> bool:
    """Whether a process with this id runs on this machine. A zombie does not: a worker
    whose batch was killed hard is re-parented, and where nothing reaps it (PID 1 of many
    containers) it stays a zombie that still answers a signal check."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return not _is_zombie(pid)


def _is_zombie(pid: int) -> bool:
    """Whether /proc says the process has exited and waits to be reaped (False where there
    is no /proc)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            stat = fh.read()
    except OSError:
        return False
    state = stat[stat.rfind(b")") + 1:].split()
    return bool(state) and state[0] in (b"Z", b"X")


def stale_temporaries(folders: Iterable[str],
                      alive: Callable[[int], bool] = pid_alive) -> list[str]:
    """Temporary files of single-file runs whose process is gone (a run killed hard, with
    no chance to clean up) in these folders; never a finished output."""
    stale = []
    for folder in sorted(set(folders)):
        try:
            names = sorted(os.listdir(folder))
        except OSError:
            continue
        for name in names:
            m = _TEMPORARY.match(name)
            if m and not alive(int(m.group(1))):
                stale.append(os.path.join(folder, name))
    return stale
