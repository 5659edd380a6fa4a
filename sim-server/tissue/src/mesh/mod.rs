//! Tetrahedral meshes: the rest geometry and connectivity that a model is built
//! from, validated on construction, plus generators and vertex reordering.
//!
//! The mesh is immutable; topology that changes with cutting (which tetrahedra
//! are alive, edges, the surface) lives in [`crate::topology`].

pub mod extent;
mod generate;
pub mod quality;
pub mod refine;
mod reorder;
pub mod shapes;
pub mod transfer;

pub use generate::{BoxSpec, CellSize, GenerateError};
pub use reorder::{bandwidth, rcm_order};

use crate::ids::{TetId, VertexId};
use crate::math::{Real, Vec3, tet_signed_volume};
use thiserror::Error;

/// The four faces of a positively oriented tetrahedron (v0..v3 with positive
/// signed volume), each listed so that its normal points out of the tetrahedron.
/// Face `k` is the one opposite vertex `k`.
pub const TET_FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

/// The six edges of a tetrahedron as local vertex pairs.
pub const TET_EDGES: [[usize; 2]; 6] = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]];

/// Relative volume below which a tetrahedron counts as degenerate: its volume
/// divided by the cube of its longest edge (a regular tetrahedron has 0.118).
pub const DEGENERATE_RELATIVE_VOLUME: Real = 1e-10;

/// A conformal P1 tetrahedral mesh at rest, in metres, every tetrahedron
/// positively oriented.
#[derive(Clone, Debug)]
pub struct TetMesh {
    positions_m: Vec<Vec3>,
    tets: Vec<[VertexId; 4]>,
    reoriented: usize,
    /// The first [`NAMED_REORIENTED`] of them, for messages.
    reoriented_first: Vec<usize>,
}

/// How many reoriented tetrahedra [`TetMesh::reoriented_first`] names.
pub const NAMED_REORIENTED: usize = 8;

/// The largest coordinate magnitude a mesh may have (in its file's units,
/// before any scaling): a kilometre in micrometres, far from where
/// products of coordinates overflow.
pub const MAX_COORDINATE: Real = 1e9;

/// The first tetrahedron with the same four vertices as an earlier one,
/// and that one: a duplicated element doubles the stiffness there and
/// hides its faces from the surface (a mesh of one element twice had no
/// surface at all).
fn duplicate_tet(tets: &[[u32; 4]]) -> Option<(usize, usize)> {
    let mut keys: Vec<([u32; 4], usize)> = (tets.iter().enumerate())
        .map(|(t, tet)| {
            let mut k = *tet;
            k.sort_unstable();
            (k, t)
        })
        .collect();
    keys.sort_unstable();
    keys.windows(2)
        .filter(|w| w[0].0 == w[1].0)
        .map(|w| (w[1].1, w[0].1))
        .min()
}

/// Why a mesh was refused.
#[derive(Debug, Error, PartialEq)]
pub enum MeshError {
    /// The mesh has no tetrahedra.
    #[error("the mesh has no tetrahedra")]
    Empty,
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex {vertex} has a non-finite coordinate {coords:?}")]
    NonFinite {
        /// The vertex index (0-based).
        vertex: usize,
        /// Its coordinates.
        coords: [Real; 3],
    },
    /// A vertex coordinate is finite but absurdly large: its edges and
    /// volumes would overflow (1e300 was reported as a zero volume "for
    /// a longest edge of inf m").
    #[error(
        "vertex {vertex} has a coordinate of magnitude above {MAX_COORDINATE:e} {coords:?}: not a mesh of tissue in metres or millimetres"
    )]
    OutOfRange {
        /// The vertex index (0-based).
        vertex: usize,
        /// Its coordinates.
        coords: [Real; 3],
    },
    /// A tetrahedron repeats another's four vertices.
    #[error(
        "tetrahedron {tet} has the same four vertices as tetrahedron {first}: a duplicated element"
    )]
    Duplicate {
        /// The later one (0-based).
        tet: usize,
        /// The earlier one.
        first: usize,
    },
    /// A tetrahedron references a vertex that does not exist.
    #[error("tetrahedron {tet} references vertex {vertex}, but the mesh has {count} vertices")]
    IndexOutOfRange {
        /// The tetrahedron index (0-based).
        tet: usize,
        /// The bad vertex index.
        vertex: usize,
        /// Number of vertices.
        count: usize,
    },
    /// A tetrahedron repeats a vertex.
    #[error("tetrahedron {tet} repeats a vertex: {vertices:?}")]
    RepeatedVertex {
        /// The tetrahedron index.
        tet: usize,
        /// Its vertices.
        vertices: [usize; 4],
    },
    /// A tetrahedron has (nearly) zero volume.
    #[error(
        "tetrahedron {tet} (vertices {vertices:?}) has zero volume ({volume_m3:e} m^3 for a longest edge of {longest_edge_m:e} m)"
    )]
    Degenerate {
        /// The tetrahedron index.
        tet: usize,
        /// Its vertices.
        vertices: [usize; 4],
        /// Its signed volume.
        volume_m3: Real,
        /// Its longest edge.
        longest_edge_m: Real,
    },
}

impl TetMesh {
    /// Validates and builds a mesh. Inverted tetrahedra (negative volume) are
    /// reoriented by swapping their last two vertices; [`TetMesh::reoriented`]
    /// tells how many were, so that callers can warn.
    pub fn new(positions_m: Vec<Vec3>, tets: Vec<[u32; 4]>) -> Result<Self, MeshError> {
        if tets.is_empty() {
            return Err(MeshError::Empty);
        }
        if let Some((vertex, p)) = positions_m.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(MeshError::NonFinite {
                vertex,
                coords: p.to_array(),
            });
        }
        if let Some((vertex, p)) =
            (positions_m.iter().enumerate()).find(|(_, p)| p.abs().max_element() > MAX_COORDINATE)
        {
            return Err(MeshError::OutOfRange {
                vertex,
                coords: p.to_array(),
            });
        }
        let count = positions_m.len();
        let mut out = Vec::with_capacity(tets.len());
        let mut reoriented = 0;
        let mut reoriented_first = Vec::new();
        for (t, tet) in tets.iter().enumerate() {
            let vertices = tet.map(|v| v as usize);
            if let Some(&vertex) = vertices.iter().find(|&&v| v >= count) {
                return Err(MeshError::IndexOutOfRange {
                    tet: t,
                    vertex,
                    count,
                });
            }
            for a in 0..4 {
                for b in a + 1..4 {
                    if vertices[a] == vertices[b] {
                        return Err(MeshError::RepeatedVertex { tet: t, vertices });
                    }
                }
            }
            let p = vertices.map(|v| positions_m[v]);
            let volume_m3 = tet_signed_volume(p[0], p[1], p[2], p[3]);
            let longest_edge_m = TET_EDGES
                .iter()
                .map(|[a, b]| p[*a].distance(p[*b]))
                .fold(0.0, Real::max);
            if volume_m3.abs() <= DEGENERATE_RELATIVE_VOLUME * longest_edge_m.powi(3) {
                return Err(MeshError::Degenerate {
                    tet: t,
                    vertices,
                    volume_m3,
                    longest_edge_m,
                });
            }
            let mut ids = tet.map(VertexId);
            if volume_m3 < 0.0 {
                ids.swap(2, 3);
                reoriented += 1;
                if reoriented_first.len() < NAMED_REORIENTED {
                    reoriented_first.push(t);
                }
            }
            out.push(ids);
        }
        if let Some((tet, first)) = duplicate_tet(&tets) {
            return Err(MeshError::Duplicate { tet, first });
        }
        Ok(Self {
            positions_m,
            tets: out,
            reoriented,
            reoriented_first,
        })
    }

    /// Rest positions (m).
    pub fn positions_m(&self) -> &[Vec3] {
        &self.positions_m
    }

    /// Tetrahedra, each positively oriented.
    pub fn tets(&self) -> &[[VertexId; 4]] {
        &self.tets
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions_m.len()
    }

    /// Number of tetrahedra.
    pub fn tet_count(&self) -> usize {
        self.tets.len()
    }

    /// How many tetrahedra were given inverted and reoriented by [`TetMesh::new`].
    pub fn reoriented(&self) -> usize {
        self.reoriented
    }

    /// The indices (0-based, in the order given) of the first
    /// [`NAMED_REORIENTED`] reoriented tetrahedra.
    pub fn reoriented_first(&self) -> &[usize] {
        &self.reoriented_first
    }

    /// The rest positions of tetrahedron `t`.
    pub fn tet_points(&self, t: TetId) -> [Vec3; 4] {
        self.tets[t.idx()].map(|v| self.positions_m[v.idx()])
    }

    /// Volume of tetrahedron `t` (m^3, positive).
    pub fn tet_volume_m3(&self, t: TetId) -> Real {
        let p = self.tet_points(t);
        tet_signed_volume(p[0], p[1], p[2], p[3])
    }

    /// The same mesh without the listed tetrahedra (vertices kept, so vertex
    /// ids stay the same). Used to check that cutting equals rebuilding.
    pub fn without_tets(&self, removed: &[TetId]) -> Result<Self, MeshError> {
        let mut keep = vec![true; self.tets.len()];
        for t in removed {
            keep[t.idx()] = false;
        }
        let tets = self
            .tets
            .iter()
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(t, _)| t.map(|v| v.0))
            .collect();
        Self::new(self.positions_m.clone(), tets)
    }

    /// Renumbers the vertices: vertex `order[k]` becomes vertex `k`.
    /// `order` must be a permutation of `0..vertex_count()`.
    pub fn permuted(&self, order: &[VertexId]) -> Self {
        let new_of_old = new_of_old(order, self.vertex_count());
        Self {
            positions_m: order.iter().map(|v| self.positions_m[v.idx()]).collect(),
            tets: self
                .tets
                .iter()
                .map(|t| t.map(|v| VertexId(new_of_old[v.idx()])))
                .collect(),
            reoriented: self.reoriented,
            reoriented_first: self.reoriented_first.clone(),
        }
    }

    /// Axis-aligned bounds (min, max) of the rest positions.
    pub fn bounds_m(&self) -> (Vec3, Vec3) {
        self.positions_m.iter().fold(
            (Vec3::splat(Real::INFINITY), Vec3::splat(Real::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        )
    }
}

/// For a renumbering `order` (vertex `order[k]` becomes `k`) of `count`
/// vertices, each old vertex's new index. Panics unless `order` is a
/// permutation of `0..count`.
pub fn new_of_old(order: &[VertexId], count: usize) -> Vec<u32> {
    assert_eq!(order.len(), count, "order is not a permutation");
    let mut map = vec![u32::MAX; count];
    for (new, old) in order.iter().enumerate() {
        map[old.idx()] = new as u32;
    }
    assert!(
        map.iter().all(|&v| v != u32::MAX),
        "order is not a permutation"
    );
    map
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_tet() -> Vec<Vec3> {
        vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z]
    }

    #[test]
    fn faces_point_outwards() {
        let p = unit_tet();
        let centre = (p[0] + p[1] + p[2] + p[3]) / 4.0;
        for f in TET_FACES {
            let n = (p[f[1]] - p[f[0]]).cross(p[f[2]] - p[f[0]]);
            assert!(n.dot(p[f[0]] - centre) > 0.0, "face {f:?} points inwards");
        }
    }

    #[test]
    fn inverted_tets_are_reoriented_and_bad_ones_refused() {
        let m = TetMesh::new(unit_tet(), vec![[0, 2, 1, 3]]).unwrap();
        assert_eq!(m.reoriented(), 1);
        assert!(m.tet_volume_m3(TetId(0)) > 0.0);

        assert_eq!(
            TetMesh::new(unit_tet(), vec![]).unwrap_err(),
            MeshError::Empty
        );
        assert!(matches!(
            TetMesh::new(unit_tet(), vec![[0, 1, 2, 4]]),
            Err(MeshError::IndexOutOfRange {
                tet: 0,
                vertex: 4,
                count: 4
            })
        ));
        assert!(matches!(
            TetMesh::new(unit_tet(), vec![[0, 1, 1, 3]]),
            Err(MeshError::RepeatedVertex { tet: 0, .. })
        ));
        let mut flat = unit_tet();
        flat[3] = Vec3::new(0.3, 0.3, 0.0);
        assert!(matches!(
            TetMesh::new(flat, vec![[0, 1, 2, 3]]),
            Err(MeshError::Degenerate { tet: 0, .. })
        ));
        let mut nan = unit_tet();
        nan[2].y = Real::NAN;
        assert!(matches!(
            TetMesh::new(nan, vec![[0, 1, 2, 3]]),
            Err(MeshError::NonFinite { vertex: 2, .. })
        ));
        // Finite but far beyond any tissue: refused by name, not as a
        // zero volume "for a longest edge of inf m".
        let mut far = unit_tet();
        far[1].x = 1e300;
        let err = TetMesh::new(far, vec![[0, 1, 2, 3]]).unwrap_err();
        assert!(
            matches!(err, MeshError::OutOfRange { vertex: 1, .. }),
            "{err}"
        );
        // The same element twice, in another vertex order.
        let err = TetMesh::new(unit_tet(), vec![[0, 1, 2, 3], [1, 0, 3, 2]]).unwrap_err();
        assert_eq!(err, MeshError::Duplicate { tet: 1, first: 0 });
    }
}
