"""Small independent readers of written solver meshes (SU2, Gmsh 2.2 ASCII), written from
the formats' documentation and never sharing code with meshio or fileio/: the tests check
what the command and fileio write with these, not with the library that wrote it."""

from __future__ import annotations

from pathlib import Path

SU2_CORNERS = {3: 2, 5: 3, 9: 4, 10: 4, 12: 8, 13: 6, 14: 5}


def parse_su2(path: Path, index: bool = False) -> dict:
    """NDIME, element records (without their index; with it as the last item when `index`),
    point records (floats, without index) and markers [(name, element records)] of an SU2
    file, plainly."""
    lines = [ln.split("%")[0].strip() for ln in Path(path).read_text().splitlines()]
    lines = [ln for ln in lines if ln]
    out: dict = {"elems": [], "points": [], "markers": []}
    i = 0
    while i < len(lines):
        key, _, val = lines[i].partition("=")
        key, val = key.strip(), val.strip()
        i += 1
        if key == "NDIME":
            out["ndime"] = int(val)
        elif key == "NELEM":
            n = int(val)
            for ln in lines[i:i + n]:
                w = [int(x) for x in ln.split()]
                nn = SU2_CORNERS[w[0]]
                out["elems"].append(tuple(w[:1 + nn] + (w[1 + nn:] if index else [])))
            i += n
        elif key == "NPOIN":
            n = int(val.split()[0])
            d = out["ndime"]
            out["points"] = [tuple(float(x) for x in ln.split()[:d]) for ln in lines[i:i + n]]
            i += n
        elif key in ("MARKER_TAG", "MARKERTAG"):  # SU2 reads the name by position
            out["markers"].append((val, []))
        elif key == "MARKER_ELEMS":
            n = int(val)
            out["markers"][-1][1].extend(tuple(int(x) for x in ln.split())
                                         for ln in lines[i:i + n])
            i += n
    return out


def parse_msh22(path: Path) -> dict:
    """Sections, physical names {(dim, tag): name}, nodes {id: xyz}, elements
    [(type, tags, nodes)], periodic pairs and NodeData {name: values} of a Gmsh 2.2 ASCII
    file, plainly."""
    lines = Path(path).read_text().splitlines()
    out: dict = {"sections": [], "names": {}, "nodes": {}, "elements": [], "periodic": [],
                 "nodedata": {}}
    i = 0
    while i < len(lines):
        head = lines[i].strip()
        i += 1
        if not head.startswith("$") or head.startswith("$End"):
            continue
        sec = head[1:]
        end = lines.index(f"$End{sec}", i)
        out["sections"].append(sec)
        body = lines[i:end]
        if sec == "MeshFormat":
            out["format"] = body[0].split()[:2]
        elif sec == "PhysicalNames":
            for ln in body[1:]:
                d, t, name = ln.split(maxsplit=2)
                out["names"][(int(d), int(t))] = name.strip('"')
        elif sec == "Nodes":
            for ln in body[1:]:
                w = ln.split()
                out["nodes"][int(w[0])] = tuple(float(x) for x in w[1:4])
        elif sec == "Elements":
            for ln in body[1:]:
                w = [int(x) for x in ln.split()]
                nt = w[2]
                out["elements"].append((w[1], tuple(w[3:3 + nt]), tuple(w[3 + nt:])))
        elif sec == "Periodic":
            for ln in body[1:]:
                w = ln.split()
                if len(w) == 2 and not w[0].startswith("Affine"):
                    out["periodic"].append((int(w[0]), int(w[1])))
        elif sec == "NodeData":
            ns = int(body[0])
            j = 1 + ns
            j += 1 + int(body[j])
            rows = body[j + 1 + int(body[j]):]
            out["nodedata"][body[1].strip('"')] = {int(r.split()[0]): float(r.split()[1])
                                                   for r in rows}
        i = end + 1
    return out
