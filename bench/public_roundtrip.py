"""Public solver files read, written back with nodes moved, and read again (docs/engineers.md,
"Checked on public files"): what users bring, in bulk.

Two sets, each from a bare snapshot of its repository (``--mirror``, default /work/.mirror,
``OWNER+NAME/repo`` as the fetch tools leave them), at a pinned commit:

- ``su2``: every ``.su2`` file of SU2's regression tests (su2code/TestCases) under 20 MB;
- ``gmsh``: Gmsh's own 2D benchmarks (live-clones/gmsh ``benchmarks/2d/*.geo``), meshed by
  the gmsh module in a process of its own per file (a file that does not mesh in 60 s is
  counted so) and saved as Gmsh 4.1 ASCII, 4.1 binary and 2.2 ASCII.

Each file is read (`fileio.solver_mesh.read`), written in its own format with every 7th node
moved by 1e-3 in x (`fileio.checked_write.write`) and read back: a round trip is every cell
block, every moved node at its new place and every other node as it was.
Prints the count of each outcome (read and round trip, refused at read with the first words
of its one line, write refused, differs) and, with ``--list``, each file's.

Run: ``python -m bench.public_roundtrip [--set su2 gmsh] [--mirror DIR] [--list]``.
"""

from __future__ import annotations

import argparse
import collections
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench.public_pins import DEFAULT_MIRROR, GMSH, SU2_TESTCASES, from_snapshot, snapshot

MAX_BYTES = 20_000_000
GMSH_SAVES = (("4.1", 0, "4.1 ascii"), ("4.1", 1, "4.1 binary"), ("2.2", 0, "2.2 ascii"))

_MESH_ONE = """
import sys, gmsh
SAVES = SAVES_HERE
geo, out = sys.argv[1], sys.argv[2]
gmsh.initialize(["-noenv"], readConfigFiles=False)
gmsh.option.setNumber("General.Terminal", 0)
gmsh.open(geo)
gmsh.model.mesh.generate(2)
for version, binary, name in SAVES:
    gmsh.option.setNumber("Mesh.MshFileVersion", float(version))
    gmsh.option.setNumber("Mesh.Binary", binary)
    gmsh.write(out + "." + name.replace(" ", "_") + ".msh")
gmsh.finalize()
""".replace("SAVES_HERE", repr(GMSH_SAVES))


def _ls_tree(mirror: Path, pin: tuple[str, str], *options: str) -> str:
    """`git ls-tree -r` of the commit of `pin` in its snapshot under `mirror`."""
    return subprocess.run(["git", "--git-dir", snapshot(mirror, pin[0]), "ls-tree", "-r",
                           *options, pin[1]], capture_output=True, check=True).stdout.decode()


def _listed(mirror: Path, pin: tuple[str, str], name: str) -> bytes:
    """The bytes of a file `_ls_tree` listed; RuntimeError when its snapshot cannot show it
    (a broken snapshot, not a file to leave out)."""
    data = from_snapshot(mirror, pin, name)
    if data is None:
        raise RuntimeError(f"{pin[0]} at {pin[1]}: git show {name} failed")
    return data


def round_trip(path: str) -> str:
    """The outcome for one file: 'round trip', 'refused: ...', 'write refused: ...' or
    'differs'."""
    from fileio import checked_write, solver_mesh

    try:
        sm = solver_mesh.read(path)
    except solver_mesh.SolverMeshError as exc:
        return "refused: " + str(exc).split(": ", 1)[-1][:70]
    moved = np.zeros(sm.n_points, dtype=bool)
    moved[::7] = True
    pos = sm.points3d().copy()
    pos[moved, 0] += 1e-3
    out = path + ".out" + os.path.splitext(path)[1]
    try:
        checked_write.write(sm, out, pos, moved)
    except checked_write.WriteError as exc:
        return "write refused: " + exc.reason[:70]
    a, b = sm.mesh, solver_mesh.read(out).mesh
    os.remove(out)
    pa, pb = np.asarray(a.points), np.asarray(b.points)
    same = (pa.shape == pb.shape and np.array_equal(pa[~moved], pb[~moved])
            and np.array_equal(pb[moved][:, :2], pos[moved][:, :2])
            and [(c.type, len(c.data)) for c in a.cells] == [(c.type, len(c.data))
                                                             for c in b.cells]
            and all(np.array_equal(x.data, y.data) for x, y in zip(a.cells, b.cells,
                                                                   strict=True)))
    return "round trip" if same else "differs"


def su2_files(mirror: Path, folder: Path) -> list[tuple[str, str]]:
    """(name, local path) of SU2's TestCases .su2 files under MAX_BYTES (not the links)."""
    out = []
    for line in _ls_tree(mirror, SU2_TESTCASES, "-l").splitlines():
        meta, name = line.split("\t", 1)
        size = meta.split()[3]
        if not name.endswith(".su2") or not size.isdigit() or int(size) > MAX_BYTES:
            continue
        data = _listed(mirror, SU2_TESTCASES, name)
        if b"NDIME" not in data:  # a link to another test's mesh
            continue
        local = folder / name.replace("/", "+")
        local.write_bytes(data)
        out.append((name, str(local)))
    return out


def gmsh_files(mirror: Path, folder: Path) -> tuple[list[tuple[str, str]], list[str]]:
    """((name, local path) of every save of every meshed benchmark, the .geo files that
    did not mesh)."""
    names = [n for n in _ls_tree(mirror, GMSH, "--name-only").split()
             if n.startswith("benchmarks/2d/") and n.endswith(".geo")]
    script = folder / "mesh_one.py"
    script.write_text(_MESH_ONE)
    out, failed = [], []
    for name in names:
        geo = folder / Path(name).name
        geo.write_bytes(_listed(mirror, GMSH, name))
        stem = str(folder / Path(name).stem)
        try:
            done = subprocess.run([sys.executable, str(script), geo.name, stem], cwd=folder,
                                  capture_output=True, timeout=60).returncode == 0
        except subprocess.TimeoutExpired:
            done = False
        files = [(f"{name} ({save})", f"{stem}.{save.replace(' ', '_')}.msh")
                 for _, _, save in GMSH_SAVES]
        if not done or not all(os.path.isfile(p) for _, p in files):
            failed.append(name)
            continue
        out += files
    return out, failed


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", nargs="+", choices=("su2", "gmsh"), default=["su2", "gmsh"])
    ap.add_argument("--mirror", type=Path, default=Path(DEFAULT_MIRROR))
    ap.add_argument("--list", action="store_true", help="each file's outcome too")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="eegt-public-") as tmp:
        folder = Path(tmp)
        for which in args.set:
            if which == "su2":
                files, failed = su2_files(args.mirror, folder), []
            else:
                files, failed = gmsh_files(args.mirror, folder)
            counts: collections.Counter[str] = collections.Counter()
            for name, path in files:
                outcome = round_trip(path)
                group = name.rsplit("(", 1)[-1].rstrip(")") + ": " if which == "gmsh" else ""
                counts[group + outcome] += 1
                if args.list:
                    print(f"{name}: {outcome}")
            print(f"## {which}: {len(files)} files" + (f" ({len(failed)} .geo files did "
                                                      "not mesh)" if failed else ""))
            for outcome, n in sorted(counts.items()):
                print(f"{n:5d}  {outcome}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
