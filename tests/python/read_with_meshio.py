"""Reads mesh files with meshio (an independent reader) and prints what it
found as one JSON object per file, for the Rust tests to check the writers:

    python3 tests/python/read_with_meshio.py FILE...

Per file: points, tetrahedra, triangles, and per point or cell array its shape, the
largest vector length and the first vector (vectors) and whether it is a permutation of
0..n-1 (integer arrays). A file meshio refuses makes the script fail.
"""

import json
import sys

import meshio
import numpy as np


def describe(path):
    m = meshio.read(path)
    def count(kind):
        return int(sum(len(b.data) for b in m.cells if b.type == kind))

    out = {
        "file": path,
        "points": int(len(m.points)),
        "tetrahedra": count("tetra"),
        "triangles": count("triangle"),
    }

    def arrays(data):
        d = {}
        for name, a in data.items():
            a = np.asarray(a)
            entry = {"shape": list(a.shape), "dtype": str(a.dtype)}
            if a.ndim == 2 and a.shape[1] == 3:
                entry["max_norm"] = float(np.linalg.norm(a, axis=1).max())
                entry["first"] = [float(x) for x in a[0]]
            if np.issubdtype(a.dtype, np.integer):
                flat = a.reshape(-1)
                entry["permutation"] = bool(
                    np.array_equal(np.sort(flat), np.arange(len(flat)))
                )
                entry["increasing"] = bool(np.all(np.diff(flat) > 0))
            d[name] = entry
        return d

    out["point_data"] = arrays(m.point_data)
    # meshio keeps cell data per cell block: the tetra block's arrays.
    tetra_blocks = {
        k: [v for v, b in zip(vals, m.cells) if b.type == "tetra"]
        for k, vals in m.cell_data.items()
    }
    out["cell_data"] = arrays(
        {k: np.concatenate(v) for k, v in tetra_blocks.items() if v}
    )
    return out


if __name__ == "__main__":
    print(json.dumps([describe(p) for p in sys.argv[1:]]))
