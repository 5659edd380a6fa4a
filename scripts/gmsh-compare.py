#!/usr/bin/env python3
# The Gmsh side of the mesher comparison in docs/guide/own-organ.md: meshes one
# surface (metres) with Gmsh 4 (pip install gmsh; GPL, so never linked into
# hapsim) at an edge of at most H and writes FILE-gmsh.msh beside it, or says
# why it failed. Usage: scripts/gmsh-compare.py SURFACE.stl H
import gmsh, sys, time, math
path, h = sys.argv[1], float(sys.argv[2])
gmsh.initialize(); gmsh.option.setNumber("General.Terminal", 0)
t=time.time()
try:
    gmsh.merge(path)
    gmsh.model.mesh.classifySurfaces(40*math.pi/180, True, True, math.pi)
    gmsh.model.mesh.createGeometry()
    s = gmsh.model.getEntities(2)
    l = gmsh.model.geo.addSurfaceLoop([e[1] for e in s])
    gmsh.model.geo.addVolume([l]); gmsh.model.geo.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMax", h); gmsh.option.setNumber("Mesh.MeshSizeMin", h/3)
    gmsh.option.setNumber("Mesh.Optimize", 1)
    gmsh.model.mesh.generate(3)
    types, tags, nodes = gmsh.model.mesh.getElements(3)
    n = sum(len(x) for x in tags)
    print(f"{path}: {n} tets in {time.time()-t:.1f} s")
    gmsh.write(path.replace('.stl','-gmsh.msh'))
except Exception as e:
    print(f"{path}: FAILED after {time.time()-t:.1f} s: {str(e)[:150]}")
gmsh.finalize()
