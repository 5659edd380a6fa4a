//! The acceleration structure of tool contact: a parry3d bounding-volume
//! hierarchy over the live surface vertices at their current positions,
//! shared by every tool and every part (tip, shaft) of a tool.
//!
//! Each leaf is a vertex's "fat" box: the vertex grown by `margin_m`. Every
//! step [`SurfaceIndex::refit`] checks each vertex against its fat box; only
//! the vertices that left theirs get a new one, and only their paths to the
//! root are refitted (`Bvh::refit_partial`, O(moved x depth)). Tissue moves a
//! fraction of a millimetre per step, so most steps touch few leaves. A cut
//! changes the surface: the leaves of vertices that left it are removed, the
//! new surface vertices inserted, and the tree refitted in full once (never
//! rebuilt from scratch).
//!
//! A query returns the vertices whose fat box meets a segment's box grown by
//! the tool radius: a superset of the vertices within the radius, which the
//! caller then tests exactly.

use parry3d_f64::bounding_volume::Aabb;
use parry3d_f64::math::Vector as PVec;
use parry3d_f64::partitioning::{Bvh, BvhBuildStrategy, BvhWorkspace};

use crate::backend::Backend;
use crate::contact::instrument::Segment;
use crate::ids::VertexId;
use crate::math::{Real, Vec3};
use crate::tensor_mass::ElasticModel;

fn pvec(v: Vec3) -> PVec {
    PVec::new(v.x, v.y, v.z)
}

/// The live surface vertices in a BVH refitted incrementally.
pub struct SurfaceIndex {
    bvh: Bvh,
    workspace: BvhWorkspace,
    margin_m: Real,
    members: Vec<VertexId>,
    /// The centre of each member's leaf box (its position when the leaf
    /// was last written): the leaf is `anchor_m +- margin_m`.
    anchor_m: Vec<Vec3>,
    on_surface: Vec<bool>,
    /// Scratch for a membership change.
    was_on_surface: Vec<bool>,
    /// `ElasticModel::topology_changes` of the current membership.
    seen: Option<u64>,
    changed_before: Vec<u32>,
    changed_now: Vec<u32>,
}

impl SurfaceIndex {
    /// An index over `model`'s vertices, empty until the first
    /// [`SurfaceIndex::refit`]. `margin_m` is how far a vertex may move
    /// before its leaf is updated (a larger margin updates fewer leaves but
    /// returns more candidates).
    pub fn new(model: &ElasticModel, margin_m: Real) -> Self {
        let n = model.vertex_count();
        Self {
            bvh: Bvh::new(),
            workspace: BvhWorkspace::default(),
            margin_m,
            members: Vec::new(),
            anchor_m: Vec::new(),
            on_surface: vec![false; n],
            was_on_surface: vec![false; n],
            seen: None,
            changed_before: Vec::new(),
            changed_now: Vec::new(),
        }
    }

    /// Whether `v` is a live surface vertex (as of the last refit or sync).
    pub fn contains(&self, v: VertexId) -> bool {
        self.on_surface[v.idx()]
    }

    /// The live surface vertices.
    pub fn members(&self) -> &[VertexId] {
        &self.members
    }

    /// Brings the leaves up to the current positions (call before a query
    /// on a state newer than the last refit: the projection law every step,
    /// the penalty law when it selects points afresh). Follows a cut first,
    /// if there was one.
    pub fn refit<B: Backend + ?Sized>(&mut self, sim: &B) {
        if self.sync(sim) {
            return;
        }
        self.changed_now.clear();
        // The fat-box test runs on our contiguous anchors; the tree is
        // touched only for the few vertices that left their box.
        for (k, &v) in self.members.iter().enumerate() {
            let x = sim.position(v);
            if (x - self.anchor_m[k]).abs().max_element() > self.margin_m {
                self.anchor_m[k] = x;
                self.bvh.insert_or_update_partially(self.leaf(x), v.0, 0.0);
                self.changed_now.push(v.0);
            }
        }
        if !self.changed_now.is_empty() || !self.changed_before.is_empty() {
            self.bvh
                .refit_partial(&self.changed_before, &self.changed_now);
        }
        std::mem::swap(&mut self.changed_before, &mut self.changed_now);
    }

    /// Follows a change of the surface (a cut by any tool) at once, so a
    /// query later in the same step sees the new surface. Returns whether
    /// the membership changed.
    pub fn sync<B: Backend + ?Sized>(&mut self, sim: &B) -> bool {
        let model = sim.model();
        let changes = model.topology_changes();
        if self.seen == Some(changes) {
            return false;
        }
        self.seen = Some(changes);
        std::mem::swap(&mut self.on_surface, &mut self.was_on_surface);
        for v in &self.members {
            self.on_surface[v.idx()] = false;
        }
        let fresh = self.bvh.is_empty();
        let mut members = std::mem::take(&mut self.members);
        members.clear();
        for tri in model.topology().surface_triangles(model.mesh()) {
            for v in tri {
                if !self.on_surface[v.idx()] {
                    self.on_surface[v.idx()] = true;
                    members.push(v);
                }
            }
        }
        self.anchor_m.clear();
        self.anchor_m
            .extend(members.iter().map(|&v| sim.position(v)));
        if fresh {
            let leaves: Vec<(usize, Aabb)> = members
                .iter()
                .zip(&self.anchor_m)
                .map(|(&v, &x)| (v.idx(), self.leaf(x)))
                .collect();
            self.bvh = Bvh::from_iter(BvhBuildStrategy::default(), leaves);
        } else {
            // Leaves of vertices no longer on the surface go; new ones come in.
            for i in 0..self.was_on_surface.len() {
                if self.was_on_surface[i] && !self.on_surface[i] {
                    self.bvh.remove(i as u32);
                }
            }
            for (&v, &x) in members.iter().zip(&self.anchor_m) {
                self.bvh.insert_or_update_partially(self.leaf(x), v.0, 0.0);
            }
            self.bvh.refit(&mut self.workspace);
        }
        for w in self.was_on_surface.iter_mut() {
            *w = false;
        }
        self.members = members;
        self.changed_before.clear();
        true
    }

    /// The leaf box of a vertex anchored at `x`.
    fn leaf(&self, x: Vec3) -> Aabb {
        let m = Vec3::splat(self.margin_m);
        Aabb::new(pvec(x - m), pvec(x + m))
    }

    /// Appends to `out` every surface vertex that may be within `radius_m`
    /// of `segment` (a superset; test each exactly).
    pub fn candidates(&self, segment: &Segment, radius_m: Real, out: &mut Vec<VertexId>) {
        let r = Vec3::splat(radius_m);
        let query = Aabb::new(
            pvec(segment.a_m.min(segment.b_m) - r),
            pvec(segment.a_m.max(segment.b_m) + r),
        );
        out.extend(self.bvh.intersect_aabb(&query).map(VertexId));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::prelude::*;
    use std::collections::BTreeSet;

    fn sim() -> Explicit<f64> {
        let mesh = BoxSpec::new(Vec3::splat(0.04), CellSize::EdgeM(0.01))
            .generate()
            .unwrap();
        let tissue = Material::isotropic(3000.0, 0.4, 1000.0, 1.0).unwrap();
        let materials = TetMaterials::uniform(tissue, mesh.tet_count());
        let model = ElasticModel::new(mesh, materials).unwrap();
        Explicit::<f64>::new(model, ExplicitConfig::new(1e-4)).unwrap()
    }

    /// The surface vertices straight from the model's surface triangles.
    fn surface(sim: &Explicit<f64>) -> BTreeSet<VertexId> {
        let m = sim.model();
        m.topology().surface_triangles(m.mesh()).flatten().collect()
    }

    fn brute(sim: &Explicit<f64>, s: &Segment, r: Real) -> Vec<VertexId> {
        surface(sim)
            .into_iter()
            .filter(|&v| s.distance_m(sim.position(v)) < r)
            .collect()
    }

    fn exact(sim: &Explicit<f64>, idx: &SurfaceIndex, s: &Segment, r: Real) -> Vec<VertexId> {
        let mut out = Vec::new();
        idx.candidates(s, r, &mut out);
        out.retain(|&v| s.distance_m(sim.position(v)) < r);
        out.sort();
        out
    }

    #[test]
    fn queries_match_a_brute_force_scan_while_the_tissue_moves_and_is_cut() {
        let mut sim = sim();
        let mut idx = SurfaceIndex::new(sim.model(), 0.001);
        idx.refit(&sim);
        let n_surface = idx.members().len();
        assert!(n_surface > 0 && n_surface < sim.model().vertex_count());
        let segments = [
            Segment {
                a_m: Vec3::new(0.02, 0.02, 0.05),
                b_m: Vec3::new(0.02, 0.02, 0.039),
            },
            Segment {
                a_m: Vec3::new(-0.01, 0.0, 0.0),
                b_m: Vec3::new(0.05, 0.04, 0.04),
            },
        ];
        // Pull the top down a little every step: leaves leave their fat boxes.
        for v in 0..sim.model().vertex_count() {
            let v = VertexId::from(v);
            if sim.model().mesh().positions_m()[v.idx()].z > 0.039 {
                sim.set_external_force(v, Vec3::new(0.0, 0.0, -2.0));
            }
        }
        for step in 0..300 {
            if step == 150 {
                // A cut: remove every tetrahedron around the centre vertex;
                // its interior neighbours come to the surface.
                let p = sim.model().mesh().positions_m().to_vec();
                let centre = (0..p.len())
                    .min_by(|&a, &b| {
                        let c = Vec3::splat(0.02);
                        p[a].distance(c).total_cmp(&p[b].distance(c))
                    })
                    .map(VertexId::from)
                    .unwrap();
                let around: Vec<TetId> = (0..sim.model().mesh().tet_count())
                    .map(TetId::from)
                    .filter(|t| sim.model().mesh().tets()[t.idx()].contains(&centre))
                    .collect();
                for t in around {
                    sim.remove_tet(t).unwrap();
                }
            }
            sim.step();
            idx.refit(&sim);
            let members: BTreeSet<VertexId> = idx.members().iter().copied().collect();
            assert_eq!(members, surface(&sim));
            for s in &segments {
                assert_eq!(exact(&sim, &idx, s, 0.003), brute(&sim, s, 0.003));
            }
        }
        assert!(
            idx.members().len() > n_surface,
            "the cut exposed interior vertices"
        );
    }
}
