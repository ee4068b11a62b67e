"""Solver mesh files for the tests, made by Gmsh (the ``gmsh`` package) and meshio, never
written by hand: a channel with a cylinder and its physical groups, tangled by moving the
cylinder; the same mesh in every solver format; Mesquite's VTK file, read in place
(third-party, not bundled: docs/testing.md)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

MESQUITE = Path(os.environ.get("EEGT_MESQUITE", "/work/shared/meshes/mesquite")) / \
    "hole_in_square_tanglap.vtk"
GROUPS = ("walls", "inlet", "outlet", "cylinder", "fluid")
CYLINDER = (1.0, 0.5, 0.2)  # centre x, y and radius
# What Gmsh (4.15) makes of `channel_msh`'s defaults (size 0.1, triangles): 537 nodes and 961
# triangles in the one surface group "fluid", whatever the shift (it moves nodes only).
CHANNEL_NODES, CHANNEL_TRIANGLES = 537, 961


def mesquite_vtk() -> Path:
    """Mesquite's tangled quad mesh (a `fixed` point array); skips when it is absent."""
    if not MESQUITE.is_file():
        pytest.skip(f"Mesquite's test mesh {MESQUITE} is absent (set EEGT_MESQUITE to its "
                    "folder)")
    return MESQUITE


def channel_msh(path: Path | str, version: str = "4.1", binary: bool = False,
                shift: float = 0.08, size: float = 0.1, quads: bool = False,
                groups: bool = True, save_all: bool = False) -> Path:
    """A 4 x 1 channel around a cylinder meshed by Gmsh, physical groups walls, inlet,
    outlet, cylinder (lines) and fluid (the surface); the cylinder's nodes moved `shift`
    in x after meshing (the faces next to it fold over). groups=False: no physical groups
    (Gmsh then saves every element, untagged); save_all: Gmsh's Mesh.SaveAll (every
    element, also those in no group)."""
    gmsh = pytest.importorskip("gmsh", reason="the gmsh package is not installed")
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("channel")
        occ = gmsh.model.occ
        rect = occ.addRectangle(0, 0, 0, 4, 1)
        disk = occ.addDisk(*CYLINDER[:2], 0, CYLINDER[2], CYLINDER[2])
        out, _ = occ.cut([(2, rect)], [(2, disk)])
        occ.synchronize()
        surface = out[0][1]
        curves = {}
        for _, tag in gmsh.model.getBoundary(out, oriented=False):
            x, y, _ = occ.getCenterOfMass(1, tag)
            name = ("cylinder" if abs(x - CYLINDER[0]) < 1e-6 and abs(y - CYLINDER[1]) < 1e-6
                    else "inlet" if x < 1e-6 else "outlet" if x > 4 - 1e-6 else "walls")
            curves.setdefault(name, []).append(abs(tag))
        if groups:
            for name in GROUPS[:4]:
                gmsh.model.addPhysicalGroup(1, curves[name], name=name)
            gmsh.model.addPhysicalGroup(2, [surface], name="fluid")
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.SaveAll", int(save_all))
        if quads:
            gmsh.option.setNumber("Mesh.RecombineAll", 1)
        gmsh.model.mesh.generate(2)
        tags, coords, _ = gmsh.model.mesh.getNodes(1, curves["cylinder"][0],
                                                   includeBoundary=True)
        for tag, xyz in zip(tags, np.asarray(coords).reshape(-1, 3)):
            gmsh.model.mesh.setNode(int(tag), [xyz[0] + shift, xyz[1], xyz[2]], [])
        gmsh.option.setNumber("Mesh.MshFileVersion", float(version))
        gmsh.option.setNumber("Mesh.Binary", int(binary))
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return Path(path)


def every_format(msh: Path, folder: Path) -> dict[str, Path]:
    """The Gmsh mesh converted by meshio into every other format, with each format's own
    tag arrays (medit:ref, su2:tag) and 2D points where the format is 2D; name -> path."""
    import meshio
    from checkout_package import register

    register()
    from eegt_blender.fileio.solver_mesh import write_mesh

    m = meshio.read(msh)
    phys = [np.asarray(a, dtype=np.int64) for a in m.cell_data["gmsh:physical"]]
    out = {}
    for name, kw in (("vtk", {}), ("vtk_ascii", {"binary": False, "fmt_version": "4.2"}),
                     ("vtu", {}), ("vtu_ascii", {"binary": False, "compression": None}),
                     ("inp", None), ("mesh", None), ("su2", None)):
        fmt = name.split("_")[0]
        path = folder / f"{msh.stem}_{name}.{fmt}"
        if fmt == "mesh":
            mesh = meshio.Mesh(m.points[:, :2].copy(), m.cells, cell_data={"medit:ref": phys},
                               point_data={"medit:ref": np.arange(len(m.points)) % 3})
        elif fmt == "su2":
            mesh = meshio.Mesh(m.points[:, :2].copy(), m.cells, cell_data={"su2:tag": phys})
        elif fmt == "inp":
            mesh = meshio.Mesh(m.points, m.cells, point_sets={"left": np.flatnonzero(
                m.points[:, 0] < 1e-9)})
        else:
            mesh = meshio.Mesh(m.points, m.cells, cell_data={"gmsh:physical": phys},
                               point_data={"fixed": (m.points[:, 0] < 0.5).astype(np.int32),
                                           "temperature": m.points[:, 0] * 3.0})
        if kw is None:
            write_mesh(mesh, str(path))
        else:
            getattr(meshio, fmt).write(str(path), mesh, **kw)
        out[name] = path
    return out
