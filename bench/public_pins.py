"""The public repositories whose files the checks and benchmarks read, each pinned at one
commit as (owner/name, commit), and how a file is read from a bare snapshot of one
(``MIRROR/OWNER+NAME/repo``, a git directory as the fetch tools or ``git clone --bare``
leave it): `bench.repair_meshes` (SU2's meshes of the repair benchmark),
`bench.public_roundtrip` (the bulk round trips) and ``scripts/fetch_public_meshes.py`` (the
files of the public-mesh tests) take them from here. Standard library only: the fetch
script runs without NumPy."""

from __future__ import annotations

import os
import subprocess

__all__ = ["DEFAULT_MIRROR", "GMSH", "MESHIO_SDIST", "MMG", "SFEPY", "SKFEM", "SKFEM_VTU",
           "SU2_TESTCASES", "SU2_TUTORIALS", "from_snapshot", "snapshot"]

DEFAULT_MIRROR = "/work/.mirror"  # where the fetch tools leave their bare snapshots

SU2_TUTORIALS = ("su2code/Tutorials", "d7991cb74e9e12a08463c579add6a9bf73713628")
SU2_TESTCASES = ("su2code/TestCases", "cdb13a34d7cdda7c518ae07e6728091db88a7e07")
GMSH = ("live-clones/gmsh", "fa207ce84b468654a2153f77c8da039688093736")  # gmsh's mirror
SKFEM = ("kinnala/scikit-fem", "365167e295a06ca708a5e066bcbe11051b34f3a3")
SKFEM_VTU = ("kinnala/scikit-fem", "f799d23c7b03ddad1d879a30ba68543fd3f25e49")
SFEPY = ("sfepy/sfepy", "3f01a19fad86d14c1d54706372fe591f8f7bf46c")
MMG = ("MmgTools/mmg", "8ed2259164fa4c90be6301d247ecb1db7bd61228")
MESHIO_SDIST = ("nschloe/meshio", "sdist-5.3.5")  # LFS in git: from the source distribution


def snapshot(mirror: str | os.PathLike, repo: str) -> str:
    """The git directory of the bare snapshot of `repo` (owner/name) under `mirror`."""
    return os.path.join(mirror, repo.replace("/", "+"), "repo")


def from_snapshot(mirror: str | os.PathLike, pin: tuple[str, str], path: str) -> bytes | None:
    """The bytes of `path` at the commit of `pin` in its snapshot under `mirror` (git show);
    None when there is no snapshot or it has no such file there."""
    git_dir = snapshot(mirror, pin[0])
    if not os.path.isdir(git_dir):
        return None
    done = subprocess.run(["git", f"--git-dir={git_dir}", "show", f"{pin[1]}:{path}"],
                          capture_output=True, check=False)
    return done.stdout if done.returncode == 0 else None
