# SPDX-License-Identifier: GPL-3.0-or-later
"""Solver mesh writes that never destroy (docs/engineers.md): the mesh goes to a hidden
temporary file beside the target (``.NAME.eegt-tmp-PID.EXT``), is read back whole and
checked (as many points, as many cells of every type; in the same format, every group with
the same nodes), and only then replaces the target
with ``os.replace``. A failed write removes the temporary file and leaves an existing
target byte-identical; its `SolverMeshError` is one line naming the target, never the
temporary file.

No bpy and no core: the command and *File > Export > Solver mesh* both write through here.
"""

from __future__ import annotations

import os

import numpy as np

from . import solver_mesh
from .solver_formats import solver_format
from .solver_mesh import SolverMesh, SolverMeshError


class WriteError(SolverMeshError):
    """A solver mesh that could not be written to `path`, and why (`reason`, one line)."""

    def __init__(self, path: str, reason: str) -> None:
        super().__init__(f"cannot write '{path}': {reason}")
        self.path, self.reason = path, reason


def tmp_path(path: str) -> str:
    """A hidden temporary name beside `path` (beside its target when it is a symbolic link,
    which then keeps pointing at the new file), with the same extension (exporters insist
    on it): ``.NAME.eegt-tmp-PID.EXT``, the pattern a resumed batch clears."""
    real = os.path.realpath(path)
    name = os.path.basename(real)
    return os.path.join(os.path.dirname(real),
                        f".{name}.eegt-tmp-{os.getpid()}{os.path.splitext(name)[1]}")


def discard(path: str | None) -> None:
    """Remove a temporary file if it is there."""
    if path and os.path.lexists(path):
        os.remove(path)


def _reason(exc: BaseException, tmp: str, path: str) -> str:
    """One line of an error, the temporary file's name replaced by the target's."""
    lines = str(exc).strip().splitlines()
    text = lines[0] if lines else type(exc).__name__
    if isinstance(exc, OSError) and exc.strerror:
        text = exc.strerror.lower()
    text = text.replace(tmp, path).replace(os.path.basename(tmp), os.path.basename(path))
    if text.startswith(f"cannot write '{path}' as ") and ": " in text:
        text = text.split(": ", 1)[1]  # the writer's own words, the path said once
    return text


def _totals(mesh: object) -> dict[str, int]:
    out: dict[str, int] = {}
    for b in mesh.cells:  # type: ignore[attr-defined]
        out[b.type] = out.get(b.type, 0) + len(b.data)
    return out


def stage(sm: SolverMesh, path: str, positions: np.ndarray | None = None,
          moved: np.ndarray | None = None) -> tuple[str, SolverMesh]:
    """Write `sm` (its `moved` nodes at `positions`) to a temporary file beside `path` in
    the format of `path`'s extension, read it back and check it: (the temporary file, the
    mesh read back). WriteError "cannot write 'PATH': reason" (the temporary file
    removed) when the writer refuses or the file does not read back whole; `path` itself is
    never touched here."""
    if solver_format(path) is None:
        raise WriteError(path, "not a solver mesh path")
    tmp = tmp_path(path)
    try:
        solver_mesh.write(sm, tmp, positions, moved)
        try:
            back = solver_mesh.read(tmp, solver_format(path))
        except SolverMeshError as exc:
            why = str(exc).split(": ", 1)[-1]
            raise SolverMeshError(f"the written file does not read back ({why})") from None
        if back.n_points != sm.n_points:
            raise SolverMeshError(f"the written file has {back.n_points} of {sm.n_points} "
                                  "points")
        if _totals(back.mesh) != _totals(sm.mesh):
            want, have = _totals(sm.mesh), _totals(back.mesh)
            lost = sorted(k for k in set(want) | set(have) if want.get(k) != have.get(k))
            raise SolverMeshError("the written file does not hold every cell (it changes "
                                  + ", ".join(f"{k}: {want.get(k, 0)} -> {have.get(k, 0)}"
                                              for k in lost) + ")")
        why = solver_mesh.groups_changed(sm, back)
        if why:
            raise SolverMeshError(why)
    except BaseException as exc:  # meshio calls sys.exit on some files it cannot parse
        discard(tmp)
        if isinstance(exc, KeyboardInterrupt):
            raise
        raise WriteError(path, _reason(exc, tmp, path)) from None
    return tmp, back


def replace(tmp: str, path: str) -> None:
    """Put a staged file in place (atomic on one file system); OSError as it is, the
    temporary file removed."""
    try:
        os.replace(tmp, os.path.realpath(path))
    except OSError:
        discard(tmp)
        raise


def write(sm: SolverMesh, path: str, positions: np.ndarray | None = None,
          moved: np.ndarray | None = None) -> SolverMesh:
    """`stage` then `replace`: the mesh read back from the written `path`."""
    tmp, back = stage(sm, path, positions, moved)
    try:
        replace(tmp, path)
    except OSError as exc:
        raise WriteError(path, _reason(exc, tmp, path)) from None
    back.path = path
    return back
