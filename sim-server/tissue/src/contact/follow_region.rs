//! The corotational region that follows the tools: the linear tetrahedra
//! within a radius of a tool's tip (at their current positions) are
//! integrated corotationally, the rest of the organ stays linear.
//!
//! Why: a tool narrower than the cells, pressed deep, wraps a linear
//! surface round its tip into a cone that slips off it (the linear strain
//! of a rotated element is not zero, so the wrapped tissue pushes back
//! wrongly and lets go); the corotational model (each element's linear
//! energy in its own rotated frame: Felippa 2000, Mueller and Gross 2004,
//! SOFA's `TetrahedronFEMForceField` "large" method) holds the tip where
//! the linear one slipped, and it is needed only where the strain is large,
//! round the tools: the space-adaptive idea of Debunne, Desbrun, Cani, Barr
//! (2001) applied to the model instead of the cells. Measured (docs/design,
//! refinement): a 2.5 mm probe held 15 mm deep in a box of 5 mm cells, the
//! linear model slips (a 30 Hz sawtooth), so does linear refinement round
//! the tip; a corotational region of 12 mm holds it steady at a fifth of the
//! cost of an all-corotational box.
//!
//! The region is rebuilt only when a tip has moved a quarter of the radius
//! since the last build, and with hysteresis (a tetrahedron joins within
//! the radius and leaves past 1.5 radii), so it changes rarely and never
//! flickers; an element leaving it is far from the tip, where its rotation
//! and so the difference between the two models are small.

use crate::backend::Backend;
use crate::ids::VertexId;
use crate::math::{Real, Vec3};
use crate::tensor_mass::ElasticModel;

/// A tetrahedron leaves the region past this many radii from every tip.
const LEAVE_RADII: Real = 1.5;
/// The region is rebuilt once a tip has moved this fraction of the radius.
const MOVE_FRACTION: Real = 0.25;

/// The region and its scratch, sized once.
/// What the corotational region that follows the tools did over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RegionStats {
    /// Times it changed (a tip moved a quarter of the radius and the set
    /// of tetrahedra within it changed).
    pub rebuilds: u64,
    /// The most tetrahedra it held at once.
    pub largest_tets: usize,
}

#[derive(Clone, Debug)]
pub(crate) struct FollowRegion {
    radius_m: Real,
    /// Per tool: its tip when the region was last built (`None`: no pose).
    built_at: Vec<Option<Vec3>>,
    /// Per vertex: within the radius of a tip; within [`LEAVE_RADII`].
    near: Vec<(bool, bool)>,
    /// Per tetrahedron: in the region now; the candidate.
    region: Vec<bool>,
    next: Vec<bool>,
    rebuilds: u64,
    /// Most tetrahedra in the region at once (counted when it changes).
    largest: usize,
}

impl FollowRegion {
    pub(crate) fn new(radius_m: Real, tools: usize, model: &ElasticModel) -> Self {
        Self {
            radius_m,
            built_at: vec![None; tools],
            near: vec![(false, false); model.vertex_count()],
            region: vec![false; model.mesh().tet_count()],
            next: vec![false; model.mesh().tet_count()],
            rebuilds: 0,
            largest: 0,
        }
    }

    /// Takes over `old`'s counts (times changed, most tetrahedra) as the
    /// same region over another mesh of the tissue: the counts are of the
    /// run, not of one mesh.
    pub(crate) fn carry_counts(&mut self, old: &FollowRegion) {
        self.rebuilds = old.rebuilds;
        self.largest = old.largest;
    }

    /// Times the region changed, and the most tetrahedra it held at once.
    pub(crate) fn stats(&self) -> RegionStats {
        RegionStats {
            rebuilds: self.rebuilds,
            largest_tets: self.largest,
        }
    }

    /// Per tetrahedron, whether it is in the region now; times it changed.
    pub(crate) fn state(&self) -> (&[bool], u64) {
        (&self.region, self.rebuilds)
    }

    /// Moves the region to the tools' tips `tips` (one per tool) when one
    /// moved far enough, and hands a changed region to `sim`.
    pub(crate) fn follow<B: Backend + ?Sized>(
        &mut self,
        sim: &mut B,
        tips: impl Iterator<Item = Option<Vec3>> + Clone,
    ) {
        let moved = self
            .built_at
            .iter()
            .zip(tips.clone())
            .any(|(at, tip)| match (at, tip) {
                (Some(a), Some(b)) => a.distance(b) > MOVE_FRACTION * self.radius_m,
                (None, None) => false,
                _ => true,
            });
        // Before the first pose every tip is `None` and the region rightly
        // empty, as it starts.
        if !moved {
            return;
        }
        for (at, tip) in self.built_at.iter_mut().zip(tips.clone()) {
            *at = tip;
        }
        let (r_in, r_out) = (self.radius_m, LEAVE_RADII * self.radius_m);
        for (v, near) in self.near.iter_mut().enumerate() {
            let p = sim.position(VertexId(v as u32));
            let d = tips
                .clone()
                .flatten()
                .map(|t| t.distance(p))
                .fold(Real::INFINITY, Real::min);
            *near = (d <= r_in, d <= r_out);
        }
        let mesh = sim.model().mesh();
        for (t, tet) in mesh.tets().iter().enumerate() {
            let joins = tet.iter().any(|v| self.near[v.idx()].0);
            let stays = self.region[t] && tet.iter().any(|v| self.near[v.idx()].1);
            self.next[t] = joins || stays;
        }
        if self.next != self.region {
            std::mem::swap(&mut self.next, &mut self.region);
            self.rebuilds += 1;
            // Cold: only when the region changes (a tip moved a quarter
            // of the radius).
            let now = self.region.iter().filter(|r| **r).count();
            self.largest = self.largest.max(now);
            sim.set_corotational_region(&self.region);
        }
    }
}
