#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Put real public solver meshes under ``build/public_meshes/`` (git-ignored) for
``tests/fileio/test_public_meshes.py`` (docs/engineers.md, *Checked on public files*).

The files are third-party data: they are never committed here. Each one is named by its
repository, the commit it is taken at and its path, and checked against the first 16 hex
digits of its SHA-256. Where it comes from, in this order:

* a local bare snapshot of the repository (``--mirror DIR``: ``DIR/OWNER+NAME/repo``, a git
  directory as a mirror tool or ``git clone --bare`` leaves it), read with ``git show``;
* else GitHub's raw file server at that commit (network);
* meshio's test meshes are Git LFS objects in its repository: they are taken from meshio's
  source distribution (``pip download meshio==5.3.5 --no-deps --no-binary :all:``, unpacked
  into ``build/meshio_sdist``, which the fidelity tests read too).

``build/public_meshes/manifest.json`` lists what was put there (the test reads it). A file
that cannot be had is reported and left out (exit 1 when any is missing); one whose bytes
differ from the recorded digest is refused.

    python scripts/fetch_public_meshes.py [--mirror /work/.mirror] [--offline]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tarfile
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from bench.public_pins import (  # noqa: E402  (the repository's root is on the path first)
    DEFAULT_MIRROR,
    GMSH,
    MESHIO_SDIST,
    MMG,
    SFEPY,
    SKFEM,
    SKFEM_VTU,
    SU2_TESTCASES,
    SU2_TUTORIALS,
    from_snapshot,
)

OUT = os.path.join(ROOT, "build", "public_meshes")
SDIST = os.path.join(ROOT, "build", "meshio_sdist")
MESHIO = "meshio==5.3.5"
MESHIO_TESTS = os.path.join(SDIST, "meshio-5.3.5", "tests", "meshes")


# (repository, commit), path in it, first 16 hex digits of the file's SHA-256
MESHES: tuple[tuple[tuple[str, str], str, str], ...] = (
    # SU2: the SU2 tutorials' 2D meshes, SU2's test cases, meshio's SU2 test meshes
    (SU2_TUTORIALS, "design/Inviscid_2D_Unconstrained_NACA0012/mesh_NACA0012_inv.su2",
     "9094b51c2628d3bb"),
    (SU2_TUTORIALS, "compressible_flow/Laminar_Flat_Plate/mesh_flatplate_65x65.su2",
     "69975ba91eabff9c"),
    (SU2_TUTORIALS, "incompressible_flow/Inc_Inviscid_Hydrofoil/mesh_NACA0012_5deg_6814.su2",
     "26d0d1dcfdfb2643"),
    (SU2_TUTORIALS, "multiphysics/steady_fsi/mesh_cantilever.su2", "a7518b950ad4cc95"),
    (SU2_TUTORIALS, "multiphysics/contact_resistance_cht/solid_mesh_1.su2",
     "4460a7c6b2b38a60"),
    (SU2_TUTORIALS, "compressible_flow/NICFD_nozzle/NICFD_nozzle.su2", "3c729e4a1af90eab"),
    (SU2_TUTORIALS, "design/Multi_Objective_Shape_Design/mesh_wedge_inv_FFD.su2",
     "92c76e67659d6d9f"),
    # SU2's regression test meshes (bench.repair_bench --testcases: held out)
    (SU2_TESTCASES, "aeroelastic/mesh_NACA64A010_hybrid_inv.su2", "697a5eb5ffdec554"),
    (SU2_TESTCASES, "harmonic_balance/hb_rans_preconditioning/n64a010_turb.su2",
     "279a08566f5d6f92"),
    (SU2_TESTCASES, "disc_adj_rans/cylinder/mesh_cylinder.su2", "67769badbccc20a3"),
    (SU2_TESTCASES, "deformation/naca4412/mesh_NACA4412_turb.su2", "5c2a91605b5d0d9a"),
    (MESHIO_SDIST, "tests/meshes/su2/square.su2", "58c56bef6d32ae93"),
    (MESHIO_SDIST, "tests/meshes/su2/mixgrid.su2", "762370a2dec30b52"),
    # Gmsh: gmsh's own benchmarks, scikit-fem's and SfePy's example meshes, meshio's
    (GMSH, "benchmarks/2d/hybrid_part.msh", "35acf3337940d9a5"),
    (GMSH, "benchmarks/misc/partitions.msh", "8b1356f1659c7641"),
    (GMSH, "benchmarks/misc/multimodel23.msh", "117d6e3518a19fbd"),
    (GMSH, "benchmarks/misc/interpolation_scheme2.msh", "c2dd19dc70b544fa"),
    (GMSH, "benchmarks/misc/adaptive_tri6.msh", "0c65f639d758db51"),
    (GMSH, "benchmarks/3d/CubeAniso2D.msh", "3abe006517ed2dc0"),
    (SKFEM, "docs/examples/meshes/annulus.msh", "c06964236280c8e0"),
    (SKFEM, "docs/examples/meshes/mixedtriquad.msh", "2c7f7c41e054ef14"),
    (SKFEM, "docs/examples/meshes/interface.msh", "964fa297113ca094"),
    (SKFEM, "docs/examples/meshes/internal.msh", "15614b8879540d6c"),
    (SKFEM, "docs/examples/meshes/tagged_gmsh4.msh", "46ad41959c74baf5"),
    (SKFEM, "docs/examples/meshes/oriented_squares.msh", "d51c5b6f64f3a48b"),
    (SFEPY, "meshes/various_formats/msh_tri.msh", "03358320d6d26616"),
    (MMG, "libexamples/mmg3d/io_generic_and_get_adja/cube.msh", "06deaf15feb48044"),
    (MESHIO_SDIST, "tests/meshes/msh/insulated-2.2.msh", "e948c04847537cff"),
    (MESHIO_SDIST, "tests/meshes/msh/insulated-4.1.msh", "4cc31fc8b786fbdd"),
    # VTU
    (SKFEM_VTU, "docs/examples/meshes/backward-facing_step.vtu", "d81f19133e2a25be"),
    (MMG, "libexamples/mmg3d/io_generic_and_get_adja/cube.vtu", "f5b8d69d2db46d01"),
    (MESHIO_SDIST, "tests/meshes/vtu/00_raw_binary.vtu", "4c49eba5ad1431d7"),
    (MESHIO_SDIST, "tests/meshes/vtu/02_raw_compressed.vtu", "2b6b8e8fabfdf364"),
    # VTK legacy
    (SFEPY, "meshes/2d/acoustic_wg_mid.vtk", "72e7072a53c35843"),
    (SFEPY, "meshes/2d/helmholtz_apartment.vtk", "7be1d51cea9d8eb9"),
    (SFEPY, "meshes/2d/special/circles_in_square.vtk", "69b8ad7814edd3e3"),
    (SFEPY, "meshes/various_formats/small2d.vtk", "84fa5d46fafa22c3"),
    (SKFEM, "docs/examples/meshes/troublesome_mesh.vtk", "decdca357c650dda"),
    (MESHIO_SDIST, "tests/meshes/vtk/00_image.vtk", "088c98f2273a967f"),
    (MESHIO_SDIST, "tests/meshes/vtk/04_rectilinear.vtk", "d7b4369b6482f398"),
    (MESHIO_SDIST, "tests/meshes/vtk/gh-935.vtk", "49d09f61cd621a26"),
    (MESHIO_SDIST, "tests/meshes/vtk/rbc_001.vtk", "99194a222a634a6d"),
    # Abaqus
    (SFEPY, "meshes/various_formats/abaqus_quad.inp", "aaf8a2b1aceceee7"),
    (SFEPY, "meshes/various_formats/abaqus_quad_tri.inp", "06fdd8a5fde9b677"),
    (SFEPY, "meshes/various_formats/abaqus_tri.inp", "3268f2e08826a188"),
    (SFEPY, "meshes/various_formats/abaqus_hex.inp", "ea75a8eaad613c29"),
    (MESHIO_SDIST, "tests/meshes/abaqus/UUea.inp", "0263bf32e6bd93bb"),
    (MESHIO_SDIST, "tests/meshes/abaqus/element_elset.inp", "f6f96eed6f4ceb11"),
    (MESHIO_SDIST, "tests/meshes/abaqus/nle1xf3c.inp", "2d8bc83d571066e1"),
    # Medit
    (SFEPY, "meshes/2d/its2D.mesh", "6c05a46cf4820914"),
    (SFEPY, "meshes/2d/rectangle_tri.mesh", "d261dc6dec5656c1"),
    (SFEPY, "meshes/2d/special/square_triquad.mesh", "f7e0611af85ae5cd"),
    (SFEPY, "meshes/2d/special/two_rectangles.mesh", "3748417607e6075c"),
    (SFEPY, "meshes/2d/special/hanging_nodes.mesh", "0e8bcaffad66b80e"),
    (MMG, "libexamples/mmg2d/adaptation_example1/dom.mesh", "cec83dface543e44"),
    (MMG, "libexamples/mmg2d/IsosurfDiscretization_lsOnly/multi-mat.mesh",
     "dfbb645226a313bb"),
    (MMG, "libexamples/mmg2d/adaptation_example0/example0_a/init.mesh", "214d85b04e459c35"),
    (MESHIO_SDIST, "tests/meshes/medit/cube86.mesh", "3ecbf7b48edc448f"),
)


def local_name(repo: str, path: str) -> str:
    """Where a file goes under build/public_meshes (relative): OWNER+NAME/PATH."""
    return os.path.join(repo.replace("/", "+"), path)


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def _from_mirror(mirror: str | None, repo: str, commit: str, path: str) -> bytes | None:
    return from_snapshot(mirror, (repo, commit), path) if mirror else None


def _from_github(repo: str, commit: str, path: str) -> bytes | None:
    url = f"https://raw.githubusercontent.com/{repo}/{commit}/{path}"
    try:
        with urllib.request.urlopen(url, timeout=60) as resp:
            return resp.read()
    except OSError:
        return None


def _meshio_sdist(offline: bool) -> bool:
    """meshio's source distribution unpacked in build/meshio_sdist (downloaded with pip
    when it is not there and the network may be used)."""
    if os.path.isdir(MESHIO_TESTS):
        return True
    if offline:
        return False
    os.makedirs(SDIST, exist_ok=True)
    done = subprocess.run([sys.executable, "-m", "pip", "download", MESHIO, "--no-deps",
                           "--no-binary", ":all:", "-d", SDIST], capture_output=True)
    tars = [f for f in os.listdir(SDIST) if f.endswith(".tar.gz")]
    if done.returncode or not tars:
        return False
    with tarfile.open(os.path.join(SDIST, tars[0])) as tar:
        tar.extractall(SDIST, filter="data")
    return os.path.isdir(MESHIO_TESTS)


def fetch(mirror: str | None, offline: bool, out: str = OUT) -> tuple[list[dict], list[str]]:
    """Put every file of MESHES under `out`: (the manifest's entries, what is missing)."""
    entries, missing = [], []
    have_sdist = None
    for (repo, commit), path, digest in MESHES:
        if commit.startswith("sdist-"):
            have_sdist = _meshio_sdist(offline) if have_sdist is None else have_sdist
            src = os.path.join(MESHIO_TESTS, os.path.relpath(path, "tests/meshes"))
            data = open(src, "rb").read() if have_sdist and os.path.isfile(src) else None
        else:
            data = _from_mirror(mirror, repo, commit, path)
            if data is None and not offline:
                data = _from_github(repo, commit, path)
        name = local_name(repo, path)
        if data is None:
            missing.append(f"{repo}@{commit[:12]}:{path} (not found)")
            continue
        if _digest(data) != digest:
            missing.append(f"{repo}@{commit[:12]}:{path} (SHA-256 {_digest(data)}, expected "
                           f"{digest})")
            continue
        target = os.path.join(out, name)
        os.makedirs(os.path.dirname(target), exist_ok=True)
        with open(target, "wb") as fh:
            fh.write(data)
        entries.append({"file": name, "repo": repo, "commit": commit, "path": path,
                        "sha256_16": digest})
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "manifest.json"), "w", encoding="utf-8") as fh:
        json.dump(entries, fh, indent=1)
    return entries, missing


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mirror", default=os.environ.get("EEGT_MESH_MIRROR", DEFAULT_MIRROR),
                    help="folder of bare repository snapshots (OWNER+NAME/repo)")
    ap.add_argument("--offline", action="store_true", help="no network: mirror and sdist only")
    ap.add_argument("--out", default=OUT)
    ns = ap.parse_args(argv)
    entries, missing = fetch(ns.mirror, ns.offline, ns.out)
    print(f"{len(entries)} of {len(MESHES)} public meshes in {ns.out}")
    for line in missing:
        print(f"missing: {line}", file=sys.stderr)
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
