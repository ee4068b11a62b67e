"""What a solver mesh write keeps or refuses before any run (docs/engineers.md): Gmsh 2
elements with more tags than physical and elementary refused at read (meshio would drop
them), SU2 index columns (points, elements, marker elements) written as the file numbers
them, SU2's MARKERTAG spelling kept, a Gmsh 4.1 file (without physical groups, or with an
entity in two) written back with only the moved coordinates changed, Abaqus element sets
carried to .msh as named physical groups (or the conversion refused with one line). Written
files are read with the independent parsers of tests/solver_parsers.py."""

from __future__ import annotations

import os

import numpy as np
import pytest
from eegt_blender.fileio import checked_write, solver_mesh
from eegt_blender.fileio.solver_mesh import SolverMeshError
from solver_meshes import channel_msh
from solver_parsers import parse_msh22, parse_su2

pytest.importorskip("meshio", reason="meshio is not installed")


def _gmsh_rectangle(path, version: str, binary: bool, partitions: int = 0,
                    curve_in_two_groups: bool = False):
    """A 2 x 1 rectangle meshed by Gmsh (physical 'domain'), optionally partitioned or with
    its bottom curve in two physical groups ('bottom', 'wall')."""
    gmsh = pytest.importorskip("gmsh", reason="the gmsh package is not installed")
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("r")
        occ = gmsh.model.occ
        rect = occ.addRectangle(0, 0, 0, 2, 1)
        occ.synchronize()
        gmsh.model.addPhysicalGroup(2, [rect], name="domain")
        if curve_in_two_groups:
            curves = [abs(t) for _, t in gmsh.model.getBoundary([(2, rect)], oriented=False)]
            bottom = min(curves, key=lambda c: occ.getCenterOfMass(1, c)[1])
            gmsh.model.addPhysicalGroup(1, [bottom], name="bottom")
            gmsh.model.addPhysicalGroup(1, [bottom], name="wall")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
        gmsh.model.mesh.generate(2)
        if partitions:
            gmsh.model.mesh.partition(partitions)
        gmsh.option.setNumber("Mesh.MshFileVersion", float(version))
        gmsh.option.setNumber("Mesh.Binary", int(binary))
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


# (a) Gmsh 2 extra element tags ----------------------------------------------------------

@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_gmsh2_partition_tags_are_refused_at_read_with_one_line(tmp_path, binary):
    src = _gmsh_rectangle(tmp_path / "part.msh", "2.2", binary, partitions=2)
    with pytest.raises(SolverMeshError) as exc:
        solver_mesh.read(str(src))
    msg = str(exc.value)
    assert "\n" not in msg and f"'{src}'" in msg
    assert "its elements carry 4 tags (physical, elementary and 2 more" in msg


def test_gmsh2_with_physical_and_elementary_tags_only_still_reads(tmp_path):
    src = _gmsh_rectangle(tmp_path / "plain.msh", "2.2", True)
    assert solver_mesh.read(str(src)).n_faces > 0


# (b) SU2 index columns --------------------------------------------------------------------

SU2_NUMBERED_FROM_ONE = """NDIME= 2
NELEM= 2
5 0 1 2 1
5 1 3 2 2
NPOIN= 4
0.0 0.0 1
1.0 0.0 2
0.0 1.0 3
1.0 1.0 4
NMARK= 1
MARKER_TAG= wall
MARKER_ELEMS= 2
3 0 1
3 1 3
"""


def test_su2_index_columns_are_written_as_the_file_numbers_them(tmp_path):
    src = tmp_path / "one.su2"
    src.write_text(SU2_NUMBERED_FROM_ONE)
    sm = solver_mesh.read(str(src))
    out = tmp_path / "out.su2"
    moved = np.array([False, False, False, True])
    checked_write.write(sm, str(out), sm.points3d() + 0.25, moved)
    text = out.read_text().splitlines()
    assert text[2:4] == ["5 0 1 2 1", "5 1 3 2 2"]
    assert text[5:9] == ["0.0 0.0 1", "1.0 0.0 2", "0.0 1.0 3", "1.25 1.25 4"]
    a, b = parse_su2(src, index=True), parse_su2(out, index=True)
    assert b["elems"] == a["elems"] and b["markers"] == a["markers"]


def test_su2_row_numbered_index_columns_stay_row_numbers(tmp_path):
    src = tmp_path / "zero.su2"
    src.write_text(SU2_NUMBERED_FROM_ONE.replace(" 1\n5 1 3 2 2", " 0\n5 1 3 2 1")
                   .replace("0.0 0.0 1\n1.0 0.0 2\n0.0 1.0 3\n1.0 1.0 4",
                            "0.0 0.0 0\n1.0 0.0 1\n0.0 1.0 2\n1.0 1.0 3"))
    sm = solver_mesh.read(str(src))
    assert sm.options["elem_ids"] is None and sm.options["point_ids"] is None
    out = tmp_path / "out.su2"
    solver_mesh.write(sm, str(out))
    assert out.read_text() == src.read_text()



def test_su2_markertag_spelling_reads_as_marker_tag_and_is_written_back_as_spelled(tmp_path):
    """SU2 reads a marker's name by position (SU2's TestCases deformation/naca4412 writes
    "MARKERTAG= farfield"): the marker is a group of its nodes, and the file comes back with
    its own spelling."""
    src = tmp_path / "tag.su2"
    src.write_text(SU2_NUMBERED_FROM_ONE.replace("MARKER_TAG=", "MARKERTAG="))
    sm = solver_mesh.read(str(src))
    assert "wall" in sm.group_names()
    assert np.flatnonzero(sm.group_nodes("wall")).tolist() == [0, 1, 3]
    out = tmp_path / "out.su2"
    solver_mesh.write(sm, str(out))
    assert out.read_text() == src.read_text()
    moved = np.array([False, False, True, False])
    checked_write.write(sm, str(out), sm.points3d() + 0.25, moved)
    assert "MARKERTAG= wall" in out.read_text().splitlines()


def test_su2_marker_records_keep_their_index_column(tmp_path):
    """Marker element records numbered as in SU2's TestCases naca4412 mesh ("3 1 338 0":
    SU2 reads the nodes and skips the rest) come back with their numbers; only the moved
    point's record changes."""
    src = tmp_path / "marked.su2"
    src.write_text(SU2_NUMBERED_FROM_ONE.replace("3 0 1\n3 1 3\n", "3 0 1 7\n3 1 3 8\n"))
    sm = solver_mesh.read(str(src))
    out = tmp_path / "out.su2"
    moved = np.array([False, False, True, False])
    checked_write.write(sm, str(out), sm.points3d() + 0.5, moved)
    a, b = src.read_text().splitlines(), out.read_text().splitlines()
    assert [k for k, (x, y) in enumerate(zip(a, b, strict=True)) if x != y] == [7]
    assert b[7] == "0.5 1.5 3" and b[-2:] == ["3 0 1 7", "3 1 3 8"]
    assert parse_su2(out)["markers"] == parse_su2(src)["markers"] == [
        ("wall", [(3, 0, 1, 7), (3, 1, 3, 8)])]


def test_su2_marker_with_an_index_column_on_some_records_only_is_refused_with_one_line(
        tmp_path):
    src = tmp_path / "half.su2"
    src.write_text(SU2_NUMBERED_FROM_ONE.replace("3 0 1\n3 1 3\n", "3 0 1 7\n3 1 3\n"))
    with pytest.raises(SolverMeshError) as exc:
        solver_mesh.read(str(src))
    msg = str(exc.value)
    assert "\n" not in msg and f"'{src}'" in msg
    assert "marker wall: some elements have an index column and some do not" in msg


# (d) Gmsh 4.1 without physical groups ------------------------------------------------------

@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_gmsh41_without_physical_groups_is_written_back_with_only_moved_coordinates_changed(
        tmp_path, binary):
    """What Gmsh saves when no physical group is defined (every element, untagged):
    meshio's 4.1 writer cannot write it ('gmsh:physical'); it is copied with the moved
    nodes' coordinates put in, every other byte the file's own."""
    src = channel_msh(tmp_path / "plain.msh", binary=binary, shift=0.0, groups=False)
    sm = solver_mesh.read(str(src))
    assert "gmsh:physical" not in sm.mesh.cell_data and sm.options["fmt_version"] == "4.1"
    moved = np.zeros(sm.n_points, dtype=bool)
    moved[[7, sm.n_points - 1]] = True
    pos = sm.points3d().copy()
    pos[moved, 0] += 0.125
    out = tmp_path / "out.msh"
    checked_write.write(sm, str(out), pos, moved)
    back = solver_mesh.read(str(out))
    assert np.array_equal(back.points3d(), pos) and back.options == sm.options
    assert [len(b.data) for b in back.mesh.cells] == [len(b.data) for b in sm.mesh.cells]
    a, b = src.read_bytes(), out.read_bytes()
    if binary:  # the same bytes but the two nodes' x
        assert len(a) == len(b)
        assert 0 < sum(x != y for x, y in zip(a, b)) <= 2 * 8
    else:  # the same lines but the two nodes' coordinate lines
        la, lb = a.splitlines(), b.splitlines()
        assert len(la) == len(lb)
        changed = [k for k, (x, y) in enumerate(zip(la, lb)) if x != y]
        assert len(changed) == 2
        assert [tuple(map(float, lb[k].split())) for k in changed] == [
            tuple(pos[i]) for i in np.flatnonzero(moved)]


def test_gmsh_vertex_cells_to_abaqus_are_refused_with_one_line_before_writing(tmp_path):
    """Gmsh saves its geometry points as vertex cells when no physical group is defined;
    meshio's Abaqus writer has no element for them (it raised KeyError 'vertex')."""
    src = channel_msh(tmp_path / "plain.msh", shift=0.0, groups=False)
    sm = solver_mesh.read(str(src))
    out = tmp_path / "out.inp"
    with pytest.raises(checked_write.WriteError) as exc:
        checked_write.write(sm, str(out))
    assert exc.value.reason == ("Abaqus (meshio's writer) has no element type for vertex "
                                "cells")
    assert sorted(os.listdir(tmp_path)) == ["plain.msh"]


def test_gmsh41_with_elements_partly_in_groups_is_refused_at_read_with_one_line(tmp_path):
    """Gmsh's 'save all elements' with physical groups: meshio cannot read the file (its
    own reason kept at the end of the line)."""
    src = channel_msh(tmp_path / "all.msh", shift=0.0, save_all=True)
    with pytest.raises(SolverMeshError) as exc:
        solver_mesh.read(str(src))
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"cannot read '{src}' as msh: some of its "
                                              "elements are in physical groups and some "
                                              "are not")
    assert "Incompatible cell data 'gmsh:physical'" in msg


@pytest.mark.parametrize(("element", "says"), [
    ("209 0 1 2 3 1", "line 3: element type 209 (a high-order element) is not one this "
                      "reads (3 line, 5 triangle, 9 quad, "),
    ("SEND_TO= 1", "line 3: 'SEND_TO' where an element was expected (a SEND_RECEIVE "
                   "marker: SU2 itself no longer reads them)"),
], ids=["high-order", "send-receive"])
def test_su2_records_that_are_not_elements_are_refused_with_what_they_are(tmp_path, element,
                                                                           says):
    """SU2's TestCases hold DG meshes of high-order elements (nPoly3: type 209) and old
    periodic SEND_RECEIVE markers: one line says which (was "not an SU2 element")."""
    src = tmp_path / "odd.su2"
    src.write_text(SU2_NUMBERED_FROM_ONE.replace("5 0 1 2 1\n", element + "\n"))
    with pytest.raises(SolverMeshError) as exc:
        solver_mesh.read(str(src))
    assert "\n" not in str(exc.value) and says in str(exc.value)


SU2_TAIL = """NPERIODIC= 1
PERIODIC_INDEX= 0
0.000000000000000e+00	0.000000000000000e+00	0.000000000000000e+00
FFD_NBOX= 1
FFD_TAG= BOX % a comment kept too
FFD_CORNER_POINTS= 4
-0.5	-0.5
1.5	-0.5
1.5	1.5
-0.5	1.5
"""


def test_su2_angle_offsets_and_sections_after_the_markers_are_written_back_as_they_are(
        tmp_path):
    """SU2's TestCases carry AOA_OFFSET / AOS_OFFSET after NDIME and periodic and FFD
    sections after the markers (they were refused): read, and written back unchanged
    around the moved point."""
    src = tmp_path / "ffd.su2"
    src.write_text(SU2_NUMBERED_FROM_ONE.replace("NDIME= 2\n", "NDIME= 2\nAOA_OFFSET= 2.5\n"
                                                 "AOS_OFFSET= 0\n") + SU2_TAIL)
    sm = solver_mesh.read(str(src))
    assert "wall" in sm.group_names() and sm.n_faces == 2
    out = tmp_path / "out.su2"
    moved = np.array([False, False, False, True])
    checked_write.write(sm, str(out), sm.points3d() + 0.25, moved)
    a, b = src.read_text().splitlines(), out.read_text().splitlines()
    assert len(a) == len(b)
    assert [k for k, (x, y) in enumerate(zip(a, b)) if x != y] == [10]
    assert b[:3] == ["NDIME= 2", "AOA_OFFSET= 2.5", "AOS_OFFSET= 0"]
    assert out.read_text().endswith(SU2_TAIL)


@pytest.mark.parametrize("where", ["before the markers", "in the header after elements"])
def test_su2_section_keywords_out_of_their_place_are_refused_with_one_line(tmp_path, where):
    src = tmp_path / "odd.su2"
    text = SU2_NUMBERED_FROM_ONE
    if where == "before the markers":
        text = text.replace("NMARK= 1\n", "NPERIODIC= 1\nNMARK= 1\n")
    else:
        text = text.replace("NPOIN= 4\n", "AOA_OFFSET= 1\nNPOIN= 4\n")
    src.write_text(text)
    with pytest.raises(SolverMeshError) as exc:
        solver_mesh.read(str(src))
    msg = str(exc.value)
    assert "\n" not in msg and "is not kept (single-zone meshes:" in msg
    assert "AOA_OFFSET, AOS_OFFSET before the elements; NPERIODIC, FFD_NBOX after the " \
           "markers" in msg

# groups a same-format write would lose ----------------------------------------------------

def test_gmsh41_entity_in_two_physical_groups_keeps_both_on_write(tmp_path):
    """meshio's 4.1 writer kept one physical group per entity (the run was refused); the
    file is now written back as it is, moved coordinates put in: both groups stay."""
    src = _gmsh_rectangle(tmp_path / "two.msh", "4.1", False, curve_in_two_groups=True)
    sm = solver_mesh.read(str(src))
    wall, bottom = sm.group_nodes("wall"), sm.group_nodes("bottom")
    assert np.array_equal(wall, bottom) and wall.sum() >= 2
    moved = np.zeros(sm.n_points, dtype=bool)
    moved[np.flatnonzero(~wall)[-1]] = True
    pos = sm.points3d() + 0.0625
    out = tmp_path / "out.msh"
    checked_write.write(sm, str(out), pos, moved)
    back = solver_mesh.read(str(out))
    assert np.array_equal(back.group_nodes("wall"), wall)
    assert np.array_equal(back.group_nodes("bottom"), bottom)
    a, b = src.read_bytes().splitlines(), out.read_bytes().splitlines()
    assert len(a) == len(b) and sum(x != y for x, y in zip(a, b)) == 1


# (c) Abaqus element sets to .msh ----------------------------------------------------------

INP = """*NODE
1, 0.0, 0.0
2, 1.0, 0.0
3, 2.0, 0.0
4, 0.0, 1.0
5, 1.0, 1.0
6, 2.0, 1.0
*ELEMENT, TYPE=CPS3, ELSET=left
1, 1, 2, 5
2, 1, 5, 4
*ELEMENT, TYPE=CPS3, ELSET=right
3, 2, 3, 6
4, 2, 6, 5
"""


def test_abaqus_element_sets_become_named_physical_groups_in_msh(tmp_path):
    src = tmp_path / "plate.inp"
    src.write_text(INP)
    sm = solver_mesh.read(str(src))
    assert solver_mesh.can_write(sm, "msh") is None
    out = tmp_path / "plate.msh"
    checked_write.write(sm, str(out))
    p = parse_msh22(out)
    assert p["names"] == {(2, 1): "left", (2, 2): "right"}
    assert [e[1][0] for e in p["elements"]] == [1, 1, 2, 2]  # physical tag of each triangle
    back = solver_mesh.read(str(out))
    for name in ("left", "right"):
        assert np.array_equal(back.group_nodes(name), sm.group_nodes(name))


@pytest.mark.parametrize(("extra", "why"), [
    ("*NSET, NSET=clamped\n1, 4\n",
     "its node sets ('clamped') have no place in .msh (write .inp, or remove them)"),
    ("*ELSET, ELSET=all\n1, 2, 3, 4\n",
     "its element sets 'all' and 'left' share cells: a Gmsh element has one physical group"),
])
def test_abaqus_sets_msh_cannot_hold_are_refused_before_writing(tmp_path, extra, why):
    src = tmp_path / "plate.inp"
    src.write_text(INP + extra)
    sm = solver_mesh.read(str(src))
    got = solver_mesh.can_write(sm, "msh", str(tmp_path / "o.msh"))
    assert got == f"cannot write '{tmp_path / 'o.msh'}' as msh: {why}"
    with pytest.raises(checked_write.WriteError) as exc:
        checked_write.write(sm, str(tmp_path / "o.msh"))
    assert exc.value.reason == why
    assert sorted(os.listdir(tmp_path)) == ["plate.inp"]
