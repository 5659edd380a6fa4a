//! Mesh import and export (Gmsh MSH 4.1 / 2.2, VTK legacy, VTU, medit; VTU + PVD, OBJ, STL out).
