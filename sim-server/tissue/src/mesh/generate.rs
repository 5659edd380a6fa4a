//! The structured box generator: a grid of cubes, each split into six
//! tetrahedra around its main diagonal (Kuhn/Freudenthal split). The split is
//! the same in every cube, so neighbouring cubes share their face diagonals and
//! the mesh is conformal without alternating cube parities.

use super::{MeshError, TetMesh};
use crate::math::{Real, Vec3};
use thiserror::Error;

/// The most vertices a generated mesh may have (a box or a shape): 8
/// million, about 48 million tetrahedra and 1 GB of mesh; beyond, a typo
/// in `size_m` or `cell_m` (or a size in millimetres) would allocate
/// without bound.
pub const MAX_GENERATED_VERTICES: usize = 8_000_000;

/// How finely a box is divided.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CellSize {
    /// Target cell edge length in metres; each side gets `round(side / h)` cells (at least 1).
    EdgeM(Real),
    /// Target number of tetrahedra; the cell edge is chosen so that the mesh has about this many.
    TargetTets(usize),
}

/// A box from `origin_m` with sides `size_m`, split into cubes of about equal edge.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoxSpec {
    /// The minimum corner (m).
    pub origin_m: Vec3,
    /// Side lengths (m).
    pub size_m: Vec3,
    /// Cell size.
    pub cells: CellSize,
}

/// Why a box could not be generated.
#[derive(Debug, Error, PartialEq)]
pub enum GenerateError {
    /// A size or the cell length is not a positive finite number.
    #[error("{field} must be a positive finite number, got {value}")]
    NotPositive {
        /// Which input.
        field: &'static str,
        /// The value given.
        value: Real,
    },
    /// The grid would have more than `MAX_GENERATED_VERTICES` vertices.
    #[error(
        "{cells:?} cells are too many: a generated mesh has at most {} vertices (check size_m and cell_m, and their units: metres)",
        MAX_GENERATED_VERTICES
    )]
    TooLarge {
        /// The cell counts per axis.
        cells: [usize; 3],
    },
    /// A coordinate is NaN or infinite.
    #[error("{field} must be finite, got {value}")]
    NotFinite {
        /// Which input.
        field: &'static str,
        /// The value given.
        value: Real,
    },
    /// Nothing of the shape was meshed.
    #[error("nothing to mesh: {reason}")]
    Empty {
        /// Why, in words (which shape, bounds and cell).
        reason: String,
    },
    /// Trimming a lattice to a shape left non-manifold vertices that the
    /// repair could not remove (a shape with features thinner than a cell).
    #[error(
        "{vertices} vertices are still non-manifold after {rounds} repair rounds; use a smaller cell"
    )]
    NotManifold {
        /// Non-manifold vertices left.
        vertices: usize,
        /// Repair rounds done.
        rounds: usize,
    },
    /// The generated mesh failed validation (cannot happen for valid sizes).
    #[error(transparent)]
    Mesh(#[from] MeshError),
}

impl BoxSpec {
    /// A box at the origin with the given sides and cell size.
    pub fn new(size_m: Vec3, cells: CellSize) -> Self {
        Self {
            origin_m: Vec3::ZERO,
            size_m,
            cells,
        }
    }

    /// The number of cells along each axis.
    pub fn cell_counts(&self) -> Result<[usize; 3], GenerateError> {
        for (field, value) in [
            ("size_m.x", self.size_m.x),
            ("size_m.y", self.size_m.y),
            ("size_m.z", self.size_m.z),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(GenerateError::NotPositive { field, value });
            }
        }
        let h = match self.cells {
            CellSize::EdgeM(h) => h,
            CellSize::TargetTets(n) => {
                let cubes = (n as Real / 6.0).max(1.0);
                (self.size_m.x * self.size_m.y * self.size_m.z / cubes).cbrt()
            }
        };
        if !(h.is_finite() && h > 0.0) {
            return Err(GenerateError::NotPositive {
                field: "cell_m",
                value: h,
            });
        }
        // Counted in floating point first: a cell of 5e-30 m gives counts
        // no integer holds (the cast saturates and the + 1 wrapped).
        let exact = self.size_m.to_array().map(|l| (l / h).round().max(1.0));
        let counts = exact.map(|c| c.min(usize::MAX as Real) as usize);
        let vertices: Real = exact.iter().map(|c| c + 1.0).product();
        if vertices <= MAX_GENERATED_VERTICES as Real {
            Ok(counts)
        } else {
            Err(GenerateError::TooLarge { cells: counts })
        }
    }

    /// Generates the mesh. Vertices are numbered x fastest, then y, then z.
    pub fn generate(&self) -> Result<TetMesh, GenerateError> {
        let [nx, ny, nz] = self.cell_counts()?;
        let step = self.size_m / Vec3::new(nx as Real, ny as Real, nz as Real);
        let index = |i: usize, j: usize, k: usize| (i + (nx + 1) * (j + (ny + 1) * k)) as u32;
        let mut positions = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
        for k in 0..=nz {
            for j in 0..=ny {
                for i in 0..=nx {
                    positions
                        .push(self.origin_m + step * Vec3::new(i as Real, j as Real, k as Real));
                }
            }
        }
        let mut tets = Vec::with_capacity(6 * nx * ny * nz);
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    tets.extend(kuhn_cube(i, j, k, index));
                }
            }
        }
        let mesh = TetMesh::new(positions, tets)?;
        debug_assert_eq!(mesh.reoriented(), 0);
        Ok(mesh)
    }
}

/// The six tetrahedra of grid cube (i, j, k) in the Kuhn split, positively
/// oriented: one per path from corner 000 to 111 along the axes in some
/// order. `corner` numbers the grid vertices. The split is the same in every
/// cube, so neighbouring cubes share their face diagonals.
pub(crate) fn kuhn_cube(
    i: usize,
    j: usize,
    k: usize,
    corner: impl Fn(usize, usize, usize) -> u32,
) -> [[u32; 4]; 6] {
    const ORDERS: [[usize; 3]; 6] = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    ORDERS.map(|order| {
        let mut c = [i, j, k];
        let mut tet = [corner(i, j, k); 4];
        for (s, axis) in order.iter().enumerate() {
            c[*axis] += 1;
            tet[s + 1] = corner(c[0], c[1], c[2]);
        }
        // Odd axis permutations give negative orientation.
        if matches!(order, [0, 2, 1] | [1, 0, 2] | [2, 1, 0]) {
            tet.swap(2, 3);
        }
        tet
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ids::TetId;

    #[test]
    fn box_volume_and_count() {
        let spec = BoxSpec::new(Vec3::new(0.1, 0.02, 0.03), CellSize::EdgeM(0.01));
        let mesh = spec.generate().unwrap();
        assert_eq!(spec.cell_counts().unwrap(), [10, 2, 3]);
        assert_eq!(mesh.tet_count(), 6 * 60);
        assert_eq!(
            mesh.reoriented(),
            0,
            "the generator must emit positive tetrahedra"
        );
        let volume: Real = (0..mesh.tet_count())
            .map(|t| mesh.tet_volume_m3(TetId(t as u32)))
            .sum();
        assert!((volume - 0.1 * 0.02 * 0.03).abs() < 1e-15);
    }

    #[test]
    fn target_tet_count_is_close() {
        for n in [1000, 8000, 100_000] {
            let mesh = BoxSpec::new(Vec3::splat(0.1), CellSize::TargetTets(n))
                .generate()
                .unwrap();
            let ratio = mesh.tet_count() as Real / n as Real;
            assert!(
                (0.7..1.4).contains(&ratio),
                "asked {n}, got {}",
                mesh.tet_count()
            );
        }
    }

    #[test]
    fn bad_sizes_are_refused() {
        let e = BoxSpec::new(Vec3::new(0.1, -1.0, 0.1), CellSize::EdgeM(0.01)).generate();
        assert!(matches!(
            e,
            Err(GenerateError::NotPositive {
                field: "size_m.y",
                ..
            })
        ));
        let e = BoxSpec::new(Vec3::splat(0.1), CellSize::EdgeM(Real::NAN)).generate();
        assert!(matches!(
            e,
            Err(GenerateError::NotPositive {
                field: "cell_m",
                ..
            })
        ));
    }
}
