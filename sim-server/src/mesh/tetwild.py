# `sim-server mesh`'s worker: surfaces in, fTetWild's tetrahedra out.
#
# Run by sim-server (src/mesh/tetrahedralize.rs) as `python3 -c SCRIPT JSON`;
# the JSON holds the inputs and options. Reads each surface (meshio for STL,
# OBJ, PLY and legacy VTK; VTK's reader for VTP), reports the surface's
# faults (boundary edges grouped into holes, with their centres; non-manifold
# edges, with their end points), runs fTetWild (Hu et al. 2020, "Fast
# Tetrahedral Meshing in the Wild", through pytetwild's compiled wrapper,
# loaded without its pyvista front end) and writes the tetrahedra with
# meshio. The last line of stdout is a JSON report.
import importlib.machinery
import importlib.util
import glob
import json
import os
import site
import sys
import time

import numpy as np

# Tetrahedra per regular one of the ideal edge in fTetWild's optimised meshes
# with the envelope below (measured: 1.4 on a 25k-vertex organ at 15 mm, 1.5
# on spheres).
K_TETS = 1.5


def fail(kind, message, **extra):
    print(json.dumps({"error": kind, "message": message, **extra}))
    sys.exit(2)


def load_tetwild():
    dirs = site.getsitepackages() + [site.getusersitepackages()]
    for d in dirs:
        hits = glob.glob(os.path.join(d, "pytetwild", "PyfTetWildWrapper*.so"))
        if hits:
            loader = importlib.machinery.ExtensionFileLoader("PyfTetWildWrapper", hits[0])
            spec = importlib.util.spec_from_file_location("PyfTetWildWrapper", hits[0], loader=loader)
            module = importlib.util.module_from_spec(spec)
            loader.exec_module(module)
            return module
    fail("missing", "fTetWild (the pytetwild wheel) is not installed: run scripts/setup.sh "
         "or `python3 -m pip install --no-deps pytetwild==0.4.2`")


def read_surface(path):
    ext = os.path.splitext(path)[1].lower()
    if ext == ".vtp":
        try:
            from vtkmodules.vtkIOXML import vtkXMLPolyDataReader
            from vtkmodules.vtkFiltersCore import vtkTriangleFilter
            from vtkmodules.util.numpy_support import vtk_to_numpy
        except ImportError:
            fail("input", "reading VTP needs VTK's Python package (scripts/setup.sh installs it)", path=path)
        r = vtkXMLPolyDataReader()
        r.SetFileName(path)
        r.Update()
        t = vtkTriangleFilter()
        t.SetInputConnection(r.GetOutputPort())
        t.Update()
        poly = t.GetOutput()
        if poly.GetNumberOfPoints() == 0:
            fail("input", "no points in the file", path=path)
        pts = vtk_to_numpy(poly.GetPoints().GetData()).astype(np.float64)
        cells = vtk_to_numpy(poly.GetPolys().GetConnectivityArray()).reshape(-1, 3)
        return pts, cells.astype(np.int64)
    import meshio
    try:
        m = meshio.read(path)
    except Exception as e:  # meshio raises many kinds; say which file
        fail("input", f"cannot read it as a surface: {e}", path=path)
    tris = [c.data for c in m.cells if c.type == "triangle"]
    quads = [c.data for c in m.cells if c.type == "quad"]
    for q in quads:
        tris.append(np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]]))
    if not tris:
        fail("input", "no triangles in the file (a surface of triangles or quads is needed)", path=path)
    return np.asarray(m.points[:, :3], dtype=np.float64), np.concatenate(tris).astype(np.int64)


def weld(points, tris):
    # STL repeats each vertex per triangle: merge exact duplicates so that
    # edges are shared and the surface's faults can be found.
    uniq, inverse = np.unique(points, axis=0, return_inverse=True)
    return uniq, inverse.reshape(-1)[tris]


def faults(points, tris):
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    keys, counts = np.unique(e, axis=0, return_counts=True)
    boundary = keys[counts == 1]
    nonmanifold = keys[counts > 2]
    # Boundary edges grouped into loops (connected components): one hole each.
    holes = []
    if len(boundary):
        parent = {}

        def find(a):
            while parent.setdefault(a, a) != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            return a

        for a, b in boundary:
            parent[find(a)] = find(b)
        groups = {}
        for a, b in boundary:
            groups.setdefault(find(a), set()).update((a, b))
        for g in groups.values():
            idx = np.array(sorted(g))
            holes.append({"centre": points[idx].mean(axis=0).tolist(), "edges": int(len(idx))})
    return {
        "boundary_edges": int(len(boundary)),
        "holes": holes[:20],
        "nonmanifold_edges": int(len(nonmanifold)),
        "nonmanifold": [[points[a].tolist(), points[b].tolist()] for a, b in nonmanifold[:20]],
    }


def winding(points, tris, queries, chunk=256):
    # The generalised winding number of each query point about a closed
    # surface (van Oosterom and Strackee's solid angle per triangle, summed
    # over 4 pi): 1 inside, 0 outside, robust to small holes.
    a0, b0, c0 = points[tris[:, 0]], points[tris[:, 1]], points[tris[:, 2]]
    out = np.empty(len(queries))
    for s in range(0, len(queries), chunk):
        q = queries[s:s + chunk, None, :]
        a, b, c = a0[None] - q, b0[None] - q, c0[None] - q
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        num = np.einsum("ijk,ijk->ij", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("ijk,ijk->ij", a, b) * lc
               + np.einsum("ijk,ijk->ij", b, c) * la + np.einsum("ijk,ijk->ij", c, a) * lb)
        out[s:s + chunk] = np.arctan2(num, den).sum(axis=1) / (2.0 * np.pi)
    return out


def volume(points, tris):
    a, b, c = points[tris[:, 0]], points[tris[:, 1]], points[tris[:, 2]]
    return abs(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def main():
    req = json.loads(sys.argv[1])
    pts_all, tris_all, per_file, shells = [], [], [], []
    offset = 0
    raw = [read_surface(path) for path in req["surfaces"]]
    # No units given: millimetres when the organ (the first surface) is
    # larger than a body in metres could be.
    scale, detected = req["scale"], req["scale"] is None
    if detected:
        p0 = raw[0][0]
        scale = 1e-3 if float((p0.max(axis=0) - p0.min(axis=0)).max()) > req["mm_detect_extent"] else 1.0
    for path, (p, t) in zip(req["surfaces"], raw):
        p, t = weld(p * scale, t)
        f = faults(p, t)
        f.update({"path": path, "vertices": int(len(p)), "triangles": int(len(t)),
                  "volume_m3": float(volume(p, t))})
        per_file.append(f)
        pts_all.append(p)
        tris_all.append(t + offset)
        shells.append((p, t))
        offset += len(p)
    points = np.concatenate(pts_all)
    tris = np.concatenate(tris_all)
    lo, hi = points.min(axis=0), points.max(axis=0)
    vol = sum(f["volume_m3"] for f in per_file[:1]) or float(np.prod(hi - lo))
    if req.get("cell_m"):
        edge = float(req["cell_m"])
    else:
        # A regular tetrahedron of edge a holds a^3 / (6 sqrt 2); K_TETS of
        # fTetWild's per regular one.
        edge = float((K_TETS * 6.0 * np.sqrt(2.0) * vol / float(req["tets"])) ** (1.0 / 3.0))
    estimate = K_TETS * 6.0 * np.sqrt(2.0) * vol / edge**3
    if estimate > req["max_tets"]:
        fail("size", f"about {estimate:.0f} tetrahedra at a {edge * 1e3:.2f} mm edge exceeds the limit "
             f"of {req['max_tets']}: ask for a larger --cell-m or fewer --tets", estimate=float(estimate))
    # The envelope: how far the result's surface may leave the input's.
    # fTetWild's default (1e-3 of the diagonal) keeps every scanner-scale
    # bump and the small elements that resolve it, which cut the explicit
    # step (a 25k-vertex organ at 15 mm cells: 8x below a lattice mesh's
    # bound); a tenth of the cell keeps the shape to that and lets the
    # cells be the size asked for.
    diag = float(np.linalg.norm(hi - lo))
    envelope = float(req.get("envelope_m") or 0.1 * edge)
    tw = load_tetwild()
    start = time.time()
    v, tets = tw.tetrahedralize_mesh(
        points, tris.astype(np.uint32), True, False, 0.0, edge, envelope / diag, 10.0, False,
        int(req["threads"]), 80, 6, True, False, False,
        np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int32), np.zeros(0))
    seconds = time.time() - start
    if len(tets) == 0:
        fail("failed", "fTetWild produced no tetrahedra (is the surface closed around a volume?)")
    # fTetWild's tetrahedra turn the other way from sim-server's (a
    # positive det(b - a, c - a, d - a)): swap two vertices where negative.
    tets = np.asarray(tets, dtype=np.int64)
    a, b, c, d = (v[tets[:, k]] for k in range(4))
    det = np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a))
    flip = det < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    # Physical tags: 1 for the organ (the first surface); each later surface
    # (a vessel, a tumour) tags the tetrahedra whose centroid it encloses
    # with its own number (2, 3, ...; a later one wins where they overlap).
    tags = np.ones(len(tets), dtype=np.int64)
    centroids = v[tets].mean(axis=1)
    for k, (p, t) in enumerate(shells[1:], start=2):
        inside = np.abs(winding(p, t, centroids)) > 0.5
        tags[inside] = k
    a, b, c, d = (v[tets[:, k]] for k in range(4))
    vols = np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a)) / 6.0
    # Raw arrays into the scratch directory (little-endian: counts, f64
    # positions, i64 tetrahedra, i64 tags): sim-server runs its quality
    # pass on them, which also opens the near-flat elements fTetWild
    # sometimes leaves (a file reader would refuse those), then writes the
    # format asked for.
    with open(req["out"], "wb") as f:
        f.write(b"HAPRAW1\n" + np.array([len(v), len(tets)], dtype="<u8").tobytes())
        f.write(np.ascontiguousarray(v, dtype="<f8").tobytes())
        f.write(np.ascontiguousarray(tets, dtype="<i8").tobytes())
        f.write(np.ascontiguousarray(tags, dtype="<i8").tobytes())
    print(json.dumps({"inputs": per_file, "edge_length_m": edge, "vertices": int(len(v)),
                      "tets": int(len(tets)), "seconds": seconds, "envelope_m": envelope,
                      "tags": {str(k): int((tags == k).sum()) for k in range(1, len(shells) + 1)},
                      "tag_volumes_m3": {str(k): float(vols[tags == k].sum())
                                         for k in range(1, len(shells) + 1)},
                      "bounds_m": [lo.tolist(), hi.tolist()],
                      "scale": scale, "units_detected": detected}))


main()
