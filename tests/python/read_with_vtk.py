"""Reads mesh files with VTK's own readers (the library ParaView is built
on) and prints what they found as one JSON object per file, for the Rust
tests to check the writers:

    python3 tests/python/read_with_vtk.py FILE...

`.vtu` goes through vtkXMLUnstructuredGridReader (plain or zlib-compressed),
`.vtk` through vtkUnstructuredGridReader. Per file: points, tetrahedra (VTK
cell type 10), and per point or cell array its components, tuples and
largest vector length. A file VTK reports an error on makes the script fail.
"""

import json
import sys

from vtkmodules.vtkCommonCore import vtkCommand
from vtkmodules.vtkIOLegacy import vtkUnstructuredGridReader
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

VTK_TETRA = 10


class Errors:
    """Collects VTK's error events (VTK prints and carries on otherwise)."""

    def __init__(self):
        self.messages = []

    def __call__(self, caller, event, data=None):
        self.messages.append(str(data) if data is not None else event)


Errors.__call__.CallDataType = "string0"


def describe(path):
    if path.endswith(".vtu"):
        reader = vtkXMLUnstructuredGridReader()
    else:
        reader = vtkUnstructuredGridReader()
        # By default the legacy reader keeps only the first VECTORS and
        # SCALARS section; a file may hold several.
        reader.ReadAllVectorsOn()
        reader.ReadAllScalarsOn()
    errors = Errors()
    reader.AddObserver(vtkCommand.ErrorEvent, errors)
    reader.SetFileName(path)
    reader.Update()
    grid = reader.GetOutput()
    if errors.messages or grid is None or grid.GetNumberOfPoints() == 0:
        raise SystemExit(f"{path}: VTK could not read it: {errors.messages}")
    tets = sum(1 for c in range(grid.GetNumberOfCells()) if grid.GetCellType(c) == VTK_TETRA)

    def arrays(data):
        out = {}
        for i in range(data.GetNumberOfArrays()):
            a = data.GetArray(i)
            entry = {"components": a.GetNumberOfComponents(), "tuples": a.GetNumberOfTuples()}
            if a.GetNumberOfComponents() == 3:
                entry["max_norm"] = a.GetMaxNorm()
            else:
                lo, hi = a.GetRange()
                entry["range"] = [lo, hi]
            out[a.GetName()] = entry
        return out

    return {
        "file": path,
        "points": grid.GetNumberOfPoints(),
        "tetrahedra": tets,
        "point_data": arrays(grid.GetPointData()),
        "cell_data": arrays(grid.GetCellData()),
    }


if __name__ == "__main__":
    print(json.dumps([describe(p) for p in sys.argv[1:]]))
