"""bench.public_roundtrip's outcome of one file: a Gmsh 4.1 file without physical groups
(ASCII and binary) round trips; an SU2 file of several zones is refused with its line."""

from __future__ import annotations

import pytest
from solver_meshes import channel_msh

from bench import public_roundtrip as pr

pytest.importorskip("meshio", reason="meshio is not installed")


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_gmsh41_file_without_groups_round_trips(tmp_path, binary):
    src = channel_msh(tmp_path / "c.msh", binary=binary, shift=0.0, groups=False)
    assert pr.round_trip(str(src)) == "round trip"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.msh"]


def test_su2_file_of_several_zones_is_counted_as_refused_with_its_line(tmp_path):
    src = tmp_path / "zones.su2"
    src.write_text("NZONE= 2\nIZONE= 1\nNDIME= 2\n")
    assert pr.round_trip(str(src)) == ("refused: line 1: 'NZONE' is not kept (single-zone "
                                       "meshes: NDIME, NELEM, NPOIN, ")
