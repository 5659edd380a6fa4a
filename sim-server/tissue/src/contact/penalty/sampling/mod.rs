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

use crate::backend::Backend;
use crate::contact::penalty::field::{ContactField, ContactPoint, PartSweep};
use crate::contact::surface::adjacency::Adjacency;
use crate::contact::surface::faces::SurfaceFaces;
use crate::contact::surface::index::SurfaceIndex;
use crate::ids::VertexId;
use crate::math::{Real, Vec3};
use crate::tensor_mass::ElasticModel;
use selection::{REUSE_MARGIN_OF_RADIUS, SelectionCache};

mod selection;

/// At most this many subdivisions per triangle edge (256 points): 32 gave
/// the liver demo twice the p99 step time (stretched triangles around the
/// cavitron's hole) for nothing the tests could see.
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
    /// The surface triangles a pass has taken.
    faces: SurfaceFaces,
    candidates: Vec<VertexId>,
    /// The last selection, replayed while it holds.
    cache: SelectionCache,
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
            faces: SurfaceFaces::new(model),
            candidates: Vec::new(),
            cache: SelectionCache::default(),
        }
    }

    /// Adds to `field` the points for each of its parts: the last
    /// selection again while it holds (see [`SelectionCache`]), else a
    /// fresh one with the margin that lets the next steps reuse it.
    pub fn select<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        index: &mut SurfaceIndex,
        adj: &Adjacency,
        field: &mut ContactField,
    ) {
        if field.parts().is_empty() {
            // No tool part: nothing to select, nothing to check.
            return;
        }
        let topology = sim.model().topology_changes();
        let position = |v| sim.position(v);
        let rest = sim.model().mesh().positions_m();
        if !self
            .cache
            .holds(field, index.members(), position, rest, topology)
        {
            index.refit(sim);
            self.cache.begin(index.members(), position, topology);
            for part in 0..field.parts().len() {
                let from = field.points().len();
                let sweep = field.parts()[part];
                let extra_m = REUSE_MARGIN_OF_RADIUS * sweep.radius_m;
                let slack_m = self.sample_part(sim, index, adj, part as u16, field, extra_m, true);
                self.cache.record(&sweep, slack_m, field, from);
            }
            field.clear_points();
        } else {
            self.cache.replayed();
        }
        // This step's points: those of the selection within this step's
        // reach (what a selection without the margin takes), so the
        // margin costs neither distances in every sub-step nor sub-steps.
        let u = sim.displacements();
        for part in 0..field.parts().len() {
            let sweep = field.parts()[part];
            let to = SegmentQuery::new(&sweep.to);
            let keep_m = step_keep_m(&sweep);
            let keep2 = keep_m * keep_m;
            let points = self.cache.points_of(part);
            let mut start = 0;
            while start < points.len() {
                // One triangle's points (consecutive, as selected): decided
                // together where its bounding sphere lies clearly inside or
                // outside the reach (the distance to a segment moves no
                // faster than the point), point by point where it straddles.
                let ids = points[start].vertices;
                let end = start
                    + points[start..]
                        .iter()
                        .position(|p| p.vertices != ids)
                        .unwrap_or(points.len() - start);
                // Positions from the slices: this runs every step.
                let x = ids.map(|v| rest[v as usize] + Vec3::from_array(u[v as usize]));
                let centre = (x[0] + x[1] + x[2]) / 3.0;
                let radius = x.iter().map(|p| p.distance(centre)).fold(0.0, Real::max);
                let d = to.distance2(centre).sqrt();
                let run = &points[start..end];
                start = end;
                let margin = keep_m * WHOLE_TRIANGLE_MARGIN + WHOLE_TRIANGLE_MARGIN_M;
                if d - radius > keep_m + margin {
                    continue;
                }
                let all = d + radius < keep_m - margin;
                for p in run {
                    let inside = all || {
                        let xp = (0..3).fold(Vec3::ZERO, |xp, k| xp + x[k] * p.weights[k]);
                        to.distance2(xp) < keep2
                    };
                    if inside {
                        field.push(ContactPoint {
                            part: part as u16,
                            ..*p
                        });
                    }
                }
            }
        }
    }

    /// Adds to `field` the points that may touch part `part` during the
    /// step, for a selection within the step (no reuse: the selection kept
    /// for the next steps is forgotten).
    pub fn sample<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        index: &SurfaceIndex,
        adj: &Adjacency,
        part: u16,
        field: &mut ContactField,
    ) {
        self.cache.invalidate();
        self.sample_part(sim, index, adj, part, field, 0.0, true);
    }

    /// Adds to `field` the points within the step's reach of part `part`
    /// or `extra_m` further, leaving the selection kept for the next steps
    /// alone (for [`crate::contact::local::LocalContact`]).
    pub fn sample_around<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        index: &SurfaceIndex,
        adj: &Adjacency,
        part: u16,
        field: &mut ContactField,
        extra_m: Real,
    ) {
        self.sample_part(sim, index, adj, part, field, extra_m, false);
    }

    /// The longest rest edge of a surface triangle (m).
    pub(in crate::contact) fn max_edge_m(&self) -> Real {
        self.max_edge_m
    }

    /// How often selections were replayed and made afresh.
    pub fn selection_counts(&self) -> (u64, u64) {
        (self.cache.replays(), self.cache.selections())
    }

    /// Whether a selection may serve later steps (the default).
    pub fn set_reuse(&mut self, reuse: bool) {
        self.cache.set_reuse(reuse);
    }

    /// Adds to `field` the points of the live surface triangles that may
    /// touch the field's part `part` during the step (within its radius
    /// plus half of it of the part at either end of the step) or lie
    /// `extra_m` further. Returns how far beyond that reach points were
    /// kept, from the part at the end of the step (m). `record`: the
    /// triangles' lattices go into the selection being made.
    #[allow(clippy::too_many_arguments)]
    fn sample_part<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        index: &SurfaceIndex,
        adj: &Adjacency,
        part: u16,
        field: &mut ContactField,
        extra_m: Real,
        record: bool,
    ) -> Real {
        let sweep = field.parts()[part as usize];
        let r = sweep.radius_m;
        let keep_m = step_keep_m(&sweep) + extra_m;
        // A triangle with a point within `keep_m` of the part at the end of
        // the step has a vertex within that plus its longest edge (1.5x the
        // longest rest edge: stretched tissue) of the sweep's box.
        let query = crate::contact::instrument::Segment {
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
        index.candidates(&query, keep_m + 1.5 * self.max_edge_m, &mut self.candidates);
        let to = SegmentQuery::new(&sweep.to);
        let keep2 = keep_m * keep_m;
        self.faces.begin();
        let spacing_m = (self.spacing_of_radius * r).max(1e-6);
        let model = sim.model();
        let rest = model.mesh().positions_m();
        // The box query of a long, slanted shaft returns much of the
        // organ: keep the vertices within reach of the swept part (its end
        // segment, grown by the motion) plus a triangle's extent.
        let vertex_reach2 = (keep_m + 1.5 * self.max_edge_m).powi(2);
        for ci in 0..self.candidates.len() {
            let v = self.candidates[ci];
            if to.distance2(sim.position(v)) > vertex_reach2 {
                continue;
            }
            self.faces.around(model, adj, v, |tri| {
                let x = tri.map(|w| sim.position(w));
                let x0 = tri.map(|w| rest[w.idx()]);
                // Cheap rejection: the triangle's bounding sphere.
                let centre = (x[0] + x[1] + x[2]) / 3.0;
                let radius = x.iter().map(|p| p.distance(centre)).fold(0.0, Real::max);
                if to.distance2(centre).sqrt() > radius + keep_m {
                    return;
                }
                let area0 = 0.5 * (x0[1] - x0[0]).cross(x0[2] - x0[0]).length();
                let n = subdivisions(&x0, &x, spacing_m);
                let ids = tri.map(|w| w.0);
                if record {
                    self.cache.note_lattice(ids, n, spacing_m);
                }
                let k_p = self.kappa_n_per_m3 * area0 / (n * n) as Real;
                let near = |c: Vec3, r: Real| to.distance2(c).sqrt() < keep_m + r;
                for_each_centroid_near(n, &x, near, |w| {
                    let p = x[0] * w[0] + x[1] * w[1] + x[2] * w[2];
                    if to.distance2(p) < keep2 {
                        field.push(ContactPoint {
                            vertices: ids,
                            weights: w,
                            part,
                            stiffness_n_per_m: k_p,
                        });
                    }
                });
            });
        }
        keep_m - step_reach_m(&sweep)
    }
}

/// Subdivisions per edge of a triangle at rest `x0`, now at `x`, for
/// points `spacing_m` apart. The lattice follows the deformed triangle: a
/// triangle stretched around a deep probe must not let it slip between its
/// points.
pub(in crate::contact) fn subdivisions(x0: &[Vec3; 3], x: &[Vec3; 3], spacing_m: Real) -> usize {
    let longest = [(0, 1), (1, 2), (2, 0)]
        .iter()
        .map(|&(a, b)| x0[a].distance(x0[b]).max(x[a].distance(x[b])))
        .fold(0.0, Real::max);
    ((longest / spacing_m).ceil() as usize).clamp(1, MAX_SUBDIVISIONS)
}

/// How far from a part's segment tissue can touch it during a step (m):
/// its radius plus half of it, since tissue near the tool moves well under
/// half a radius between two selections (one step, or a millisecond of a
/// long one).
fn step_reach_m(sweep: &PartSweep) -> Real {
    1.5 * sweep.radius_m
}

/// How far from the part's segment at the end of the step a point must be
/// kept (m): within reach of the part at the start of the step is within
/// reach plus twice the motion of it at the end (each end moved at most
/// that far), so one distance per point decides.
fn step_keep_m(sweep: &PartSweep) -> Real {
    step_reach_m(sweep) + 2.0 * sweep.motion_m()
}

/// A triangle's points are taken or left together only when its bounding
/// sphere is inside or outside the reach by this fraction of it: far more
/// than the rounding of the distances, so the points are exactly those
/// that point-by-point tests take.
const WHOLE_TRIANGLE_MARGIN: Real = 1e-9;
/// ... plus this much (m), for a reach so short that its relative margin
/// would fall below the rounding of coordinates (~1e-16 m per metre).
const WHOLE_TRIANGLE_MARGIN_M: Real = 1e-12;

/// A segment ready for many distance queries.
struct SegmentQuery {
    a: Vec3,
    d: Vec3,
    inv_len2: Real,
}

impl SegmentQuery {
    fn new(seg: &crate::contact::instrument::Segment) -> Self {
        let d = seg.b_m - seg.a_m;
        let len2 = d.length_squared();
        Self {
            a: seg.a_m,
            d,
            inv_len2: if len2 > 0.0 { 1.0 / len2 } else { 0.0 },
        }
    }

    /// Squared distance from `x` (m^2).
    fn distance2(&self, x: Vec3) -> Real {
        let s = ((x - self.a).dot(self.d) * self.inv_len2).clamp(0.0, 1.0);
        (x - (self.a + self.d * s)).length_squared()
    }
}

/// Lattice rows and columns per block of [`for_each_centroid_near`].
const BLOCK: usize = 4;

/// [`for_each_centroid`] over the triangle `x`, skipping blocks of
/// BLOCK x BLOCK lattice cells whose bounding sphere (centre, radius) is
/// not `near`: a tool touches a few blocks of a large triangle.
pub(crate) fn for_each_centroid_near(
    n: usize,
    x: &[Vec3; 3],
    near: impl Fn(Vec3, Real) -> bool,
    mut f: impl FnMut([Real; 3]),
) {
    let inv = 1.0 / n as Real;
    let (e1, e2) = ((x[1] - x[0]) * inv, (x[2] - x[0]) * inv);
    let half = BLOCK as Real / 2.0;
    let radius = (half + 1.0) * (e1.length() + e2.length());
    for bi in (0..n).step_by(BLOCK) {
        for bj in (0..n - bi).step_by(BLOCK) {
            let centre = x[0] + e1 * (bi as Real + half) + e2 * (bj as Real + half);
            if !near(centre, radius) {
                continue;
            }
            for i in bi..(bi + BLOCK).min(n) {
                for j in bj..(bj + BLOCK).min(n - i) {
                    let (b, c) = ((i as Real + 1.0 / 3.0) * inv, (j as Real + 1.0 / 3.0) * inv);
                    f([1.0 - b - c, b, c]);
                    if i + j + 1 < n {
                        let (b, c) = ((i as Real + 2.0 / 3.0) * inv, (j as Real + 2.0 / 3.0) * inv);
                        f([1.0 - b - c, b, c]);
                    }
                }
            }
        }
    }
}

/// Calls `f` with the barycentric weights of the centroids of the n^2
/// sub-triangles of a triangle split n times along each edge (the
/// reference [`for_each_centroid_near`] is tested against).
#[cfg(test)]
fn for_each_centroid(n: usize, mut f: impl FnMut([Real; 3])) {
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
    fn blocks_visit_every_centroid_once_and_cull_far_ones() {
        let x = [
            Vec3::ZERO,
            Vec3::new(0.01, 0.0, 0.0),
            Vec3::new(0.0, 0.01, 0.0),
        ];
        for n in [1, 3, 4, 7, 16] {
            let mut all = Vec::new();
            for_each_centroid(n, |w| all.push(w));
            let mut blocked = Vec::new();
            for_each_centroid_near(n, &x, |_, _| true, |w| blocked.push(w));
            let key = |w: &[Real; 3]| ((w[1] * 1e9) as i64, (w[2] * 1e9) as i64);
            let mut a: Vec<_> = all.iter().map(key).collect();
            let mut b: Vec<_> = blocked.iter().map(key).collect();
            a.sort_unstable();
            b.sort_unstable();
            assert_eq!(a, b, "n {n}");
            // Culling by a sphere keeps every point within it.
            let q = Vec3::new(0.002, 0.002, 0.0);
            let r = 0.0015;
            let mut kept = Vec::new();
            for_each_centroid_near(n, &x, |c, s| c.distance(q) < r + s, |w| kept.push(key(&w)));
            for w in &all {
                let p = x[1] * w[1] + x[2] * w[2];
                if p.distance(q) < r {
                    assert!(kept.contains(&key(w)), "n {n}: {w:?} culled");
                }
            }
        }
    }

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
