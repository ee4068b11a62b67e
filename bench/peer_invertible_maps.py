"""The peer untangler side by side: the 2D program of ssloy/invertible-maps (`untangle2d`,
foldover-free L-BFGS on a regularized distortion energy, boundary nodes locked).

The program is not part of this repository: build it outside (docs/corpus.md says
how) and name it with EEGT_PEER_UNTANGLER=/path/to/untangle2d. Without it, `run_peer`
raises PeerMissing with a one-line reason and the benchmarks skip the peer's column.

Input format (Wavefront OBJ read by the peer's mesh library): `v x y 0` is the rest shape
(each face's target shape; we give the valid mesh the case was made from), `vt u v` the
tangled positions to untangle, faces `f i/i j/j k/k`. It takes triangles only: quads are cut
along their 0-2 diagonal for it, and its result is measured on the original faces. It runs
with OMP_NUM_THREADS=1 (single thread, like our NumPy backend).
"""

from __future__ import annotations

import os
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core import FaceSet, Stats, mesh_stats

ENV = "EEGT_PEER_UNTANGLER"
THREADS = 1

__all__ = ["ENV", "PeerMissing", "PeerResult", "peer_binary", "run_peer", "triangles_of"]


class PeerMissing(RuntimeError):
    """The peer's binary is not built or not named."""


@dataclass(frozen=True)
class PeerResult:
    points: np.ndarray
    stats: Stats  # our metric on the original faces
    seconds: float  # wall time of the peer's process (reading and writing files included)
    solve_seconds: float | None  # the peer's own timing of its solve, when it printed one
    success: bool  # the peer's own verdict


def peer_binary() -> Path:
    """The untangler named by EEGT_PEER_UNTANGLER; PeerMissing when unset or not a file."""
    name = os.environ.get(ENV, "")
    if not name:
        raise PeerMissing(f"peer skipped: set {ENV} to the built untangle2d of ssloy/invertible-maps")
    path = Path(name)
    if not (path.is_file() and os.access(path, os.X_OK)):
        raise PeerMissing(f"peer skipped: {ENV}={name} is not an executable file")
    return path


def triangles_of(faces: FaceSet) -> np.ndarray:
    """(T, 3) triangles of the faces: triangles as they are, every other polygon fanned from
    its first corner."""
    out = []
    for g in faces.groups:
        rows = g.nodes.T  # (count, n)
        for k in range(1, g.n - 1):
            out.append(rows[:, [0, k, k + 1]])
    return np.concatenate(out).astype(np.int64)


def write_input(path: Path, rest: np.ndarray, tangled: np.ndarray, tris: np.ndarray) -> None:
    with path.open("w") as f:
        np.savetxt(f, np.column_stack([rest, np.zeros(len(rest))]), fmt="v %.17g %.17g %.17g")
        np.savetxt(f, tangled, fmt="vt %.17g %.17g")
        t = tris + 1
        np.savetxt(f, np.column_stack([t[:, 0], t[:, 0], t[:, 1], t[:, 1], t[:, 2], t[:, 2]]),
                   fmt="f %d/%d %d/%d %d/%d")


def read_points(path: Path, n: int) -> np.ndarray:
    rows = [line.split()[1:3] for line in path.read_text().splitlines() if line.startswith("v ")]
    pts = np.array(rows, dtype=np.float64)
    if pts.shape != (n, 2):
        raise RuntimeError(f"peer wrote {pts.shape[0]} nodes, expected {n}")
    return pts


def run_peer(points: np.ndarray, faces: FaceSet, reference: np.ndarray,
             timeout: float = 3600.0) -> PeerResult:
    """Untangle `points` with the peer (rest shape `reference`), measured with our metric."""
    exe = peer_binary()
    with tempfile.TemporaryDirectory(prefix="eegt_peer_") as tmp:
        src, dst = Path(tmp) / "in.obj", Path(tmp) / "out.obj"
        write_input(src, reference, points, triangles_of(faces))
        env = {**os.environ, "OMP_NUM_THREADS": str(THREADS)}
        t0 = time.perf_counter()
        proc = subprocess.run([str(exe), str(src), str(dst)], capture_output=True, text=True,
                              env=env, timeout=timeout, check=False)
        wall = time.perf_counter() - t0
        if proc.returncode != 0 or not dst.exists():
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
            raise RuntimeError(f"peer failed (exit {proc.returncode}): {tail[0]}")
        out = read_points(dst, points.shape[0])
    solve = None
    for line in proc.stderr.splitlines():
        if "running time:" in line:
            solve = float(line.split("running time:")[1].split()[0])
    return PeerResult(out, mesh_stats(out, faces), wall, solve, "SUCCESS" in proc.stderr)
