//! Where a mesh is and how big its elements are, for a user putting a
//! foreign mesh into a scene: the bounding box, the typical edge, and a
//! warning when the numbers do not look like metres (a mesh in millimetres
//! is a 1000-times-too-large organ that simulates, silently, as a building).

use super::TetMesh;
use crate::math::{Real, Vec3};

/// Typical edges of a tetrahedral organ mesh in metres: 0.1 mm to 5 cm.
const PLAUSIBLE_EDGE_M: (Real, Real) = (1e-4, 0.05);

/// A mesh's extent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extent {
    /// Bounding box corners (m).
    pub min_m: Vec3,
    /// Bounding box corners (m).
    pub max_m: Vec3,
    /// The median edge length over the tetrahedra's edges (m).
    pub median_edge_m: Real,
}

impl Extent {
    /// The extent of `mesh` (0 edges for an empty mesh).
    pub fn of(mesh: &TetMesh) -> Self {
        let (min_m, max_m) = mesh.bounds_m();
        let x = mesh.positions_m();
        let mut edges: Vec<Real> = mesh
            .tets()
            .iter()
            .flat_map(|t| {
                [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
                    .map(|(a, b)| x[t[a].idx()].distance(x[t[b].idx()]))
            })
            .collect();
        let median_edge_m = if edges.is_empty() {
            0.0
        } else {
            let k = edges.len() / 2;
            *edges.select_nth_unstable_by(k, Real::total_cmp).1
        };
        Self {
            min_m,
            max_m,
            median_edge_m,
        }
    }

    /// A warning when the typical edge is not plausible in metres, with the
    /// `[mesh] scale` that would make it so.
    pub fn units_warning(&self) -> Option<String> {
        let e = self.median_edge_m;
        let size = self.max_m - self.min_m;
        let (lo, hi) = PLAUSIBLE_EDGE_M;
        let guess = if e > hi {
            // Edges cannot tell millimetres from centimetres (1 mm cells in
            // mm and 1 cm cells in cm are both 1): the body can. The unit
            // that makes it closest to a typical organ (15 cm across) first.
            let across = |s: Real| ((size.length() * s) / 0.15).log10().abs();
            if across(0.001) <= across(0.01) {
                "millimetres? set [mesh] scale = 0.001 (or units = \"mm\"); centimetres: 0.01"
            } else {
                "centimetres? set [mesh] scale = 0.01 (or units = \"cm\"); millimetres: 0.001"
            }
        } else if e < lo && e > 0.0 {
            "a unit smaller than the metre? set [mesh] scale to what makes it metres"
        } else {
            return None;
        };
        Some(format!(
            "the typical edge is {e:.3e} m and the body {:.3e} x {:.3e} x {:.3e} m: not plausibly an organ in metres ({guess})",
            size.x, size.y, size.z
        ))
    }
}

/// Per physical tag, how many tetrahedra carry it, by tag.
pub fn tag_counts(tags: &[i32]) -> Vec<(i32, usize)> {
    let mut sorted = tags.to_vec();
    sorted.sort_unstable();
    let mut out: Vec<(i32, usize)> = Vec::new();
    for t in sorted {
        match out.last_mut() {
            Some((last, n)) if *last == t => *n += 1,
            _ => out.push((t, 1)),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{BoxSpec, CellSize};

    fn block(scale: Real) -> TetMesh {
        BoxSpec::new(Vec3::splat(0.04 * scale), CellSize::EdgeM(0.01 * scale))
            .generate()
            .unwrap()
    }

    #[test]
    fn metres_pass_millimetres_and_centimetres_are_named() {
        let m = Extent::of(&block(1.0));
        assert!(m.max_m.abs_diff_eq(Vec3::splat(0.04), 1e-12));
        // Kuhn cubes: edges 1, sqrt 2 and sqrt 3 cells; the median a diagonal.
        assert!(
            m.median_edge_m >= 0.01 && m.median_edge_m <= 0.0174,
            "{m:?}"
        );
        assert_eq!(m.units_warning(), None);
        // A 4 cm block in millimetres (40 units across) and in
        // centimetres (4 units): the unit that makes it organ-sized first.
        let mm = Extent::of(&block(1000.0)).units_warning().unwrap();
        assert!(mm.contains("millimetres? set [mesh] scale = 0.001"), "{mm}");
        let cm = Extent::of(&block(100.0)).units_warning().unwrap();
        assert!(cm.contains("centimetres? set [mesh] scale = 0.01"), "{cm}");
        assert!(Extent::of(&block(1e-3)).units_warning().is_some());
    }

    #[test]
    fn tags_are_counted_in_order() {
        assert_eq!(tag_counts(&[2, 1, 2, 0, 2]), [(0, 1), (1, 1), (2, 3)]);
        assert!(tag_counts(&[]).is_empty());
    }
}
