//! Where the penalty contact is evaluated: points spread over the surface
//! triangles near a tool part, so that the tool feels the surface between
//! vertices (with 5 mm vertices and a 2.5 mm tool, a fifth of the tool
//! positions have no vertex under the tool at all).
//!
//! Each surface triangle is split into n^2 equal sub-triangles (n from its
//! longest rest edge and the target spacing) and carries one point at each
//! sub-triangle's centroid, with the sub-triangle's rest area. The points'
//! weights spread the triangle's area exactly a third to each vertex, so a
//! uniformly pressed triangle loads its vertices equally whatever n is.

use super::adjacency::Adjacency;
use super::field::{ContactField, ContactPoint};
use super::surface_index::SurfaceIndex;
use crate::backend::Backend;
use crate::ids::VertexId;
use crate::math::{Real, Vec3};
use crate::mesh::TET_FACES;
use crate::tensor_mass::ElasticModel;

/// At most this many subdivisions per triangle edge (256 points).
const MAX_SUBDIVISIONS: usize = 16;

/// Builds each step's contact points and holds the penalty constants.
pub struct Sampler {
    /// Foundation modulus kappa (N/m^3): a point's stiffness is kappa times
    /// its rest area.
    kappa_n_per_m3: Real,
    /// Target point spacing as a fraction of the tool radius.
    spacing_of_radius: Real,
    /// The longest rest edge of a surface triangle (m), for the query.
    max_edge_m: Real,
    /// Per (tet, face): the stamp of the last pass that took it.
    face_stamp: Vec<u32>,
    stamp: u32,
    candidates: Vec<VertexId>,
}

impl Sampler {
    /// Penalty contact over `model` with springs `stiffness_factor` times
    /// the tissue's own vertex stiffness (median over the surface of
    /// trace(K_ii)/3 per unit lumped area) and points every
    /// `spacing_of_radius` radii.
    pub fn new(model: &ElasticModel, stiffness_factor: Real, spacing_of_radius: Real) -> Self {
        let (areas, max_edge_m) = lumped_areas(model);
        let k = model.vertex_tensors();
        let mut per_area: Vec<Real> = areas
            .iter()
            .enumerate()
            .filter(|(_, a)| **a > 0.0)
            .map(|(v, a)| (k[v].x_axis.x + k[v].y_axis.y + k[v].z_axis.z) / 3.0 / a)
            .filter(|x| x.is_finite() && *x > 0.0)
            .collect();
        per_area.sort_by(Real::total_cmp);
        let median = per_area.get(per_area.len() / 2).copied().unwrap_or(0.0);
        Self {
            kappa_n_per_m3: stiffness_factor * median,
            spacing_of_radius,
            max_edge_m,
            face_stamp: vec![0; 4 * model.mesh().tet_count()],
            stamp: 0,
            candidates: Vec::new(),
        }
    }

    /// omega^2 (rad^2/s^2) the contact springs may add to the explicit
    /// bound: by Gershgorin, a vertex's springs add at most kappa times its
    /// lumped area over its mass; twice that, since the tip and the shaft
    /// (or two tools) may press the same triangle.
    pub fn omega2_bound(&self, model: &ElasticModel) -> Real {
        let (areas, _) = lumped_areas(model);
        areas
            .iter()
            .zip(model.masses_kg())
            .filter(|(a, m)| **a > 0.0 && **m > 0.0)
            .map(|(a, m)| 2.0 * self.kappa_n_per_m3 * a / m)
            .fold(0.0, Real::max)
    }

    /// Adds to `field` the points of the live surface triangles that may
    /// touch the field's part `part` during the step (within its radius
    /// plus half of it of the part at either end of the step).
    pub fn sample<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        index: &SurfaceIndex,
        adj: &Adjacency,
        part: u16,
        field: &mut ContactField,
    ) {
        let sweep = field.parts()[part as usize];
        // Tissue near the tool moves well under half a radius between two
        // selections (one step, or a millisecond of a long one).
        let margin_m = 0.5 * sweep.radius_m;
        let r = sweep.radius_m;
        let moved_m = (sweep.to.a_m - sweep.from.a_m)
            .length()
            .max((sweep.to.b_m - sweep.from.b_m).length());
        let reach_m = r + margin_m;
        // A triangle within reach has a vertex within reach + its longest
        // edge (1.5x the longest rest edge: stretched tissue), anywhere on
        // the sweep.
        let query = super::geometry::Segment {
            a_m: sweep
                .from
                .a_m
                .min(sweep.to.a_m)
                .min(sweep.from.b_m.min(sweep.to.b_m)),
            b_m: sweep
                .from
                .a_m
                .max(sweep.to.a_m)
                .max(sweep.from.b_m.max(sweep.to.b_m)),
        };
        self.candidates.clear();
        index.candidates(
            &query,
            reach_m + 1.5 * self.max_edge_m,
            &mut self.candidates,
        );
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            // Wrapped (after 2^32 passes): old stamps must not match.
            self.face_stamp.fill(0);
            self.stamp = 1;
        }
        let spacing_m = (self.spacing_of_radius * r).max(1e-6);
        let model = sim.model();
        let topo = model.topology();
        let tets = model.mesh().tets();
        let rest = model.mesh().positions_m();
        for ci in 0..self.candidates.len() {
            let v = self.candidates[ci];
            for &t in adj.tets_of(v) {
                if !topo.is_alive(t) {
                    continue;
                }
                let tet = tets[t.idx()];
                for (k, face) in TET_FACES.iter().enumerate() {
                    let id = 4 * t.idx() + k;
                    if tet[k] == v || self.face_stamp[id] == self.stamp {
                        continue;
                    }
                    self.face_stamp[id] = self.stamp;
                    if !topo.is_surface_face(t, k) {
                        continue;
                    }
                    let tri = face.map(|l| tet[l]);
                    let x = tri.map(|w| sim.position(w));
                    let x0 = tri.map(|w| rest[w.idx()]);
                    // Cheap rejection: the triangle's bounding sphere.
                    let centre = (x[0] + x[1] + x[2]) / 3.0;
                    let radius = x.iter().map(|p| p.distance(centre)).fold(0.0, Real::max);
                    let near = dist(&sweep.from, centre).min(dist(&sweep.to, centre));
                    if near > radius + reach_m + moved_m {
                        continue;
                    }
                    let area0 = 0.5 * (x0[1] - x0[0]).cross(x0[2] - x0[0]).length();
                    let longest = (x0[1] - x0[0])
                        .length()
                        .max((x0[2] - x0[1]).length())
                        .max((x0[0] - x0[2]).length());
                    let n = ((longest / spacing_m).ceil() as usize).clamp(1, MAX_SUBDIVISIONS);
                    let k_p = self.kappa_n_per_m3 * area0 / (n * n) as Real;
                    let ids = tri.map(|w| w.0);
                    for_each_centroid(n, |w| {
                        let p = x[0] * w[0] + x[1] * w[1] + x[2] * w[2];
                        let d = dist(&sweep.from, p).min(dist(&sweep.to, p));
                        if d < reach_m + moved_m {
                            field.push(ContactPoint {
                                vertices: ids,
                                weights: w,
                                part,
                                stiffness_n_per_m: k_p,
                            });
                        }
                    });
                }
            }
        }
    }
}

fn dist(seg: &super::geometry::Segment, x: Vec3) -> Real {
    seg.distance_m(x)
}

/// Calls `f` with the barycentric weights of the centroids of the n^2
/// sub-triangles of a triangle split n times along each edge.
pub(crate) fn for_each_centroid(n: usize, mut f: impl FnMut([Real; 3])) {
    let inv = 1.0 / n as Real;
    for i in 0..n {
        for j in 0..n - i {
            // The "upward" sub-triangle at (i, j) and, where it exists,
            // the "downward" one beside it.
            let (b, c) = ((i as Real + 1.0 / 3.0) * inv, (j as Real + 1.0 / 3.0) * inv);
            f([1.0 - b - c, b, c]);
            if i + j + 1 < n {
                let (b, c) = ((i as Real + 2.0 / 3.0) * inv, (j as Real + 2.0 / 3.0) * inv);
                f([1.0 - b - c, b, c]);
            }
        }
    }
}

/// Per vertex: a third of the rest area of each live surface triangle it
/// belongs to (m^2); and the longest rest edge of a surface triangle (m).
fn lumped_areas(model: &ElasticModel) -> (Vec<Real>, Real) {
    let rest = model.mesh().positions_m();
    let mut areas = vec![0.0; model.vertex_count()];
    let mut longest: Real = 0.0;
    for tri in model.topology().surface_triangles(model.mesh()) {
        let x = tri.map(|v| rest[v.idx()]);
        let a = 0.5 * (x[1] - x[0]).cross(x[2] - x[0]).length();
        for v in tri {
            areas[v.idx()] += a / 3.0;
        }
        for (p, q) in [(0, 1), (1, 2), (2, 0)] {
            longest = longest.max(x[p].distance(x[q]));
        }
    }
    (areas, longest)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centroids_cover_the_triangle_evenly() {
        for n in 1..=6 {
            let mut count = 0;
            let mut sum = [0.0; 3];
            for_each_centroid(n, |w| {
                count += 1;
                assert!(w.iter().all(|x| *x > 0.0 && *x < 1.0));
                assert!((w.iter().sum::<Real>() - 1.0).abs() < 1e-12);
                for k in 0..3 {
                    sum[k] += w[k];
                }
            });
            assert_eq!(count, n * n);
            // Each vertex gets exactly a third of the area.
            for s in sum {
                assert!(
                    (s / count as Real - 1.0 / 3.0).abs() < 1e-12,
                    "n {n}: {sum:?}"
                );
            }
        }
    }
}
