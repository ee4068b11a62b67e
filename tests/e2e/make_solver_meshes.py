"""Solver mesh inputs for the e2e tests, made on the host (the repository's .venv has the
gmsh package; the Blender root has no network and no gmsh): run by run_e2e.sh as
``python make_solver_meshes.py DIR``. Writes DIR/channel.msh (Gmsh 4.1, a channel around a
cylinder whose nodes were moved so the faces next to it fold over; tests/solver_meshes.py)
DIR/truncated.msh (its first half) and the same channel in every other format meshio writes
(DIR/channel_vtk.vtk, channel_vtk_ascii.vtk, channel_vtu.vtu, channel_vtu_ascii.vtu,
channel_inp.inp, channel_mesh.mesh, channel_su2.su2; tests/solver_meshes.every_format)."""
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: core
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: solver_meshes
from solver_meshes import channel_msh, every_format


def main(folder: str) -> None:
    os.makedirs(folder, exist_ok=True)
    src = channel_msh(Path(folder) / "channel.msh", shift=0.15)
    data = src.read_bytes()
    (Path(folder) / "truncated.msh").write_bytes(data[:len(data) // 2])
    others = every_format(src, Path(folder))
    print(f"solver meshes in {folder}: channel.msh ({len(data)} bytes), truncated.msh, "
          + ", ".join(p.name for p in others.values()))


if __name__ == "__main__":
    main(sys.argv[1])
