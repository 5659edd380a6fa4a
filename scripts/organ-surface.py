#!/usr/bin/env python3
"""Writes an organ-shaped closed surface (binary STL, millimetres) for
measuring `sim-server mesh`: an ellipsoid 200 x 140 x 90 mm with two lobes and
scanner-scale bumps, as a segmentation exports it.

    scripts/organ-surface.py OUT.stl [--triangles 50000] [--seed 1]

The sphere is a geodesic icosahedron of frequency n (20 n^2 triangles), so the
count is the nearest 20 n^2 to the one asked for. Needs only numpy.
"""
import argparse
import struct

import numpy as np


def geodesic(n):
    """Vertices on the unit sphere and triangles of an icosahedron whose
    faces are each split into n^2 triangles."""
    t = (1.0 + 5 ** 0.5) / 2.0
    ico = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                    [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    faces = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
             [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
             [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    index = {}
    points = []

    def vertex(p):
        key = tuple(np.round(p / np.linalg.norm(p), 9))
        if key not in index:
            index[key] = len(points)
            points.append(np.array(key))
        return index[key]

    tris = []
    for a, b, c in faces:
        A, B, C = ico[a], ico[b], ico[c]
        grid = {}
        for i in range(n + 1):
            for j in range(n + 1 - i):
                grid[i, j] = vertex(A + (B - A) * i / n + (C - A) * j / n)
        for i in range(n):
            for j in range(n - i):
                tris.append([grid[i, j], grid[i + 1, j], grid[i, j + 1]])
                if i + j < n - 1:
                    tris.append([grid[i + 1, j], grid[i + 1, j + 1], grid[i, j + 1]])
    return np.array(points), np.array(tris)


def organ(p, rng):
    """The unit sphere's points moved onto the organ (mm)."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    r = 1.0
    # Two lobes: the right one larger, a notch between them at the top.
    r += 0.18 * np.exp(-((x - 0.45) ** 2 + (y + 0.1) ** 2) / 0.25)
    r += 0.10 * np.exp(-((x + 0.5) ** 2 + (y - 0.2) ** 2) / 0.2)
    r -= 0.12 * np.exp(-(x ** 2 + (z - 0.9) ** 2) / 0.05)
    # Scanner-scale bumps: 40 random dents and swellings of 5-15 mm.
    for _ in range(40):
        c = rng.normal(size=3)
        c /= np.linalg.norm(c)
        width = rng.uniform(0.03, 0.08)
        r += rng.uniform(-0.02, 0.02) * np.exp(-np.sum((p - c) ** 2, axis=1) / width ** 2)
    return p * r[:, None] * np.array([100.0, 70.0, 45.0])


def write_stl(path, p, t):
    with open(path, "wb") as f:
        f.write(b"organ-surface.py".ljust(80, b" "))
        f.write(struct.pack("<I", len(t)))
        a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
        n = np.cross(b - a, c - a)
        n /= np.linalg.norm(n, axis=1)[:, None]
        rec = np.zeros(len(t), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
        rec["n"] = n
        rec["v"] = np.stack([a, b, c], axis=1)
        f.write(rec.tobytes())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--triangles", type=int, default=50000)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    n = max(1, round((a.triangles / 20.0) ** 0.5))
    p, t = geodesic(n)
    write_stl(a.out, organ(p, np.random.default_rng(a.seed)), t)
    print(f"{a.out}: {len(t)} triangles, {len(p)} vertices (mm)")


if __name__ == "__main__":
    main()
