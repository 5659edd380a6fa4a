//! Mesh quality and topology checks: dihedral angles, aspect ratios, edge lengths,
//! duplicate and unused vertices, non-manifold pieces, connected components.
