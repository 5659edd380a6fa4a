#!/usr/bin/env python3
"""Writes the interop test meshes of sim-server/tests/data/meshes/ from the
Gmsh reference ellipsoid (ellipsoid_v22.msh, 2182 tetrahedra) with meshio,
the converter most labs use, in the formats its users and ParaView produce:

- ellipsoid_v22bin.msh   binary MSH 2.2 (meshio gmsh22, binary)
- ellipsoid_zlib.vtu     VTU, inline base64, zlib-compressed (meshio's default)
- ellipsoid_bin51.vtk    binary legacy VTK 5.1, OFFSETS/CONNECTIVITY (meshio's default)
- ellipsoid_bin42.vtk    binary legacy VTK 4.2, classic CELLS
- ellipsoid_xml.vtk      the VTU above under a .vtk name (as SOFA's Bunny.vtk)
- ellipsoid_v1.msh       MSH 1 ($NOD/$ELM, the format of SOFA's liver.msh),
                         written here from the same nodes and elements
- ellipsoid_zlib_appended.vtu  VTU with appended raw zlib blocks (VTK's own
                         XML writer's default layout), written here by the
                         VTK file-format specification

Run from the repository root: python3 scripts/make-interop-fixtures.py
"""
import base64
import struct
import zlib
from pathlib import Path

import meshio
import numpy as np

D = Path("sim-server/tests/data/meshes")
m = meshio.read(D / "ellipsoid_v22.msh")

meshio.write(D / "ellipsoid_v22bin.msh", m, file_format="gmsh22", binary=True)
meshio.write(D / "ellipsoid_zlib.vtu", m, binary=True, compression="zlib")
meshio.write(D / "ellipsoid_bin51.vtk", m, binary=True)
meshio.write(D / "ellipsoid_bin42.vtk", m, file_format="vtk42", binary=True)
(D / "ellipsoid_xml.vtk").write_bytes((D / "ellipsoid_zlib.vtu").read_bytes())

# MSH 1: `tag type physical elementary count nodes...`, triangles first.
phys = m.cell_data["gmsh:physical"]
geom = m.cell_data["gmsh:geometrical"]
gtype = {"triangle": 2, "tetra": 4}
lines = ["$NOD", str(len(m.points))]
lines += [f"{i + 1} {x!r} {y!r} {z!r}" for i, (x, y, z) in enumerate(m.points.tolist())]
lines += ["$ENDNOD", "$ELM", str(sum(len(b.data) for b in m.cells))]
tag = 1
for b, p, g in zip(m.cells, phys, geom):
    for conn, pp, gg in zip(b.data, p, g):
        nodes = " ".join(str(v + 1) for v in conn)
        lines.append(f"{tag} {gtype[b.type]} {pp} {gg} {len(conn)} {nodes}")
        tag += 1
lines += ["$ENDELM", ""]
(D / "ellipsoid_v1.msh").write_text("\n".join(lines))


# Appended raw zlib VTU, UInt64 headers, 32 KiB blocks.
def packed(a: np.ndarray, block=32768) -> bytes:
    raw = a.tobytes()
    chunks = [raw[i:i + block] for i in range(0, len(raw), block)] or [b""]
    comp = [zlib.compress(c) for c in chunks]
    head = [len(chunks), block, len(chunks[-1])] + [len(c) for c in comp]
    return struct.pack(f"<{len(head)}Q", *head) + b"".join(comp)


tets = m.cells_dict["tetra"].astype(np.int64)
arrays = [
    ("Points", "Float64", 3, m.points.astype(np.float64), "Points"),
    ("connectivity", "Int64", 1, tets.ravel(), "Cells"),
    ("offsets", "Int64", 1, np.arange(4, 4 * len(tets) + 1, 4, dtype=np.int64), "Cells"),
    ("types", "UInt8", 1, np.full(len(tets), 10, dtype=np.uint8), "Cells"),
    ("gmsh:physical", "Int32", 1, m.cell_data_dict["gmsh:physical"]["tetra"].astype(np.int32), "CellData"),
]
blob = b""
xml = {"Points": [], "Cells": [], "CellData": []}
for name, ty, comps, data, where in arrays:
    xml[where].append(
        f'<DataArray type="{ty}" Name="{name}" NumberOfComponents="{comps}" '
        f'format="appended" offset="{len(blob)}"/>'
    )
    blob += packed(np.ascontiguousarray(data))
text = (
    '<?xml version="1.0"?>\n'
    '<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" '
    'header_type="UInt64" compressor="vtkZLibDataCompressor">\n'
    f'<UnstructuredGrid>\n<Piece NumberOfPoints="{len(m.points)}" NumberOfCells="{len(tets)}">\n'
    "<Points>\n" + "\n".join(xml["Points"]) + "\n</Points>\n"
    "<Cells>\n" + "\n".join(xml["Cells"]) + "\n</Cells>\n"
    "<CellData>\n" + "\n".join(xml["CellData"]) + "\n</CellData>\n"
    "</Piece>\n</UnstructuredGrid>\n"
    '<AppendedData encoding="raw">\n_'
)
(D / "ellipsoid_zlib_appended.vtu").write_bytes(
    text.encode() + blob + b"\n</AppendedData>\n</VTKFile>\n"
)
for f in sorted(D.glob("ellipsoid_*")):
    print(f, f.stat().st_size)
