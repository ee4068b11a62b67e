# SPDX-License-Identifier: GPL-3.0-or-later
"""What the ``eegt`` command promises its callers, shared by the single-file run and the
batch: the exit codes, the one-line :class:`UsageError` (exit 2), the file types it reads and
writes, and the check that a path can be written before any work starts."""

from __future__ import annotations

import os

from ...batch.inputs import MESH_EXTENSIONS, USE_TYPES

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_FAILED = 0, 1, 2, 3
# Read and written: .blend, Blender's importers' types and the solver meshes (a solver mesh
# output needs a solver mesh input: see solver_run.py).
INPUT_EXTENSIONS = OUTPUT_EXTENSIONS = MESH_EXTENSIONS


class UsageError(Exception):
    """A command-line or input problem: one line, exit code 2 (0 for --help). `unwritable`:
    the path this error says cannot be written (the report is then not tried again)."""

    def __init__(self, message: str, code: int = EXIT_USAGE,
                 unwritable: str | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.unwritable = unwritable


def unsupported(kind: str, ext: str) -> UsageError:
    """The one-line error for an input or output of a type the command cannot handle."""
    return UsageError(f"eegt: unsupported {kind} type '{ext}' ({USE_TYPES})")


def check_writable(path: str, what: str) -> None:
    """`path` can be created or overwritten: open it for appending (which changes nothing
    in an existing file) and remove it again if it is new."""
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise UsageError(f"eegt: cannot write {what} '{path}': is a directory",
                         unwritable=path)
    if not os.path.isdir(folder):
        raise UsageError(f"eegt: cannot write {what} '{path}': no folder {folder}",
                         unwritable=path)
    existed = os.path.exists(path)
    try:  # non-blocking: a FIFO without a reader fails here instead of hanging
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NONBLOCK, 0o666))
        if not existed:
            os.remove(path)
    except OSError as exc:
        raise UsageError(f"eegt: cannot write {what} '{path}': {why(exc)}",
                         unwritable=path) from None


def why(exc: OSError) -> str:
    """An OSError as a short lower-case reason ("permission denied")."""
    return (exc.strerror or str(exc)).lower()
