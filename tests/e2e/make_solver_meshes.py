"""Solver mesh inputs for the e2e tests, made on the host (the repository's .venv has the
gmsh package; the Blender root has no network and no gmsh): run by run_e2e.sh as
``python make_solver_meshes.py DIR``. Writes DIR/channel.msh (Gmsh 4.1, a channel around a
cylinder whose nodes were moved so the faces next to it fold over; tests/solver_meshes.py)
and DIR/truncated.msh (its first half)."""
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: solver_meshes
from solver_meshes import channel_msh


def main(folder: str) -> None:
    os.makedirs(folder, exist_ok=True)
    src = channel_msh(Path(folder) / "channel.msh", shift=0.15)
    data = src.read_bytes()
    (Path(folder) / "truncated.msh").write_bytes(data[:len(data) // 2])
    print(f"solver meshes in {folder}: channel.msh ({len(data)} bytes), truncated.msh")


if __name__ == "__main__":
    main(sys.argv[1])
