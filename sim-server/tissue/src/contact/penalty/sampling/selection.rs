//! The contact points selected for each tool part, kept across steps while
//! nothing that moved since could have brought an unselected point within
//! reach of a part.
//!
//! Selecting the points (the sampler's walk over the triangles near each
//! part) was two thirds of the contact update on the liver demo, and the
//! tools and tissue move a few hundredths of a millimetre per step. So the
//! sampler selects with an extra margin ([`REUSE_MARGIN_OF_RADIUS`]), and the
//! selection is replayed unchanged while, for every part,
//!
//! ```text
//! tissue motion + part motion <= the margin the selection kept beyond reach
//! ```
//!
//! where the tissue motion is the largest displacement of any live surface
//! vertex since the selection (every surface point is a convex combination
//! of its triangle's vertices, so no point moved further), and the part
//! motion the largest displacement of the part's segment ends from where
//! they were at the selection (the Hausdorff distance between two segments
//! is at most their ends' displacement) plus twice the part's motion within
//! the step (what a fresh selection adds to its reach). A point left out
//! was further than `reach + margin` from the part then; it is still
//! further than this step's reach now. Each step then takes, from the
//! selection, the points within this step's reach at the current positions:
//! exactly the points a fresh selection would take, so the forces, the
//! distances per sub-step and the sub-steps are those of a fresh selection.
//! What differs is the lattice density of a stretching triangle, which
//! follows the deformation at each fresh selection only (at most
//! [`MAX_REUSE_STEPS`] steps apart).
//!
//! Anything else invalidates it: a cut (the surface changed), a part
//! appearing or going (a tool withdrawn, a grip closing), a selection made
//! within a step (long steps re-select every millisecond).

use super::subdivisions;
use crate::contact::instrument::Segment;
use crate::contact::penalty::field::{ContactField, ContactPoint, PartSweep};
use crate::ids::VertexId;
use crate::math::{Real, Vec3};

/// The margin (in tool radii) selected beyond the reach the step needs, so
/// that the selection can serve the next steps: a quarter of a radius is 1
/// mm for the liver's cavitron, some 20 steps of a hand moving at 50 mm/s.
/// The points in the margin cost one distance per sub-step each.
pub const REUSE_MARGIN_OF_RADIUS: Real = 0.25;

/// A selection is made afresh at least this often (steps), so that each
/// triangle's lattice follows its deformation.
pub const MAX_REUSE_STEPS: u32 = 32;

/// One part's selection.
#[derive(Clone, Copy, Debug)]
struct Selected {
    tool: usize,
    tip: bool,
    /// The part's segment at the end of the step it was selected in.
    to: Segment,
    /// How far beyond the step's reach points were kept (m).
    slack_m: Real,
    /// Its points in `SelectionCache::points`.
    start: usize,
    end: usize,
}

/// The last selection, and what is needed to tell whether it still holds.
#[derive(Debug, Default)]
pub struct SelectionCache {
    parts: Vec<Selected>,
    points: Vec<ContactPoint>,
    /// The live surface vertices' positions at the selection, in the
    /// surface index's member order.
    surface_m: Vec<Vec3>,
    /// `ElasticModel::topology_changes` at the selection.
    topology: u64,
    /// Every triangle the selection looked at: its vertices, subdivisions
    /// and point spacing (m).
    lattices: Vec<([u32; 3], usize, Real)>,
    /// Steps the selection has served.
    age: u32,
    valid: bool,
    /// Off: every step selects afresh (to check that reuse changes nothing).
    no_reuse: bool,
    /// Steps replayed and selected afresh (for the tests and the report).
    replays: u64,
    selections: u64,
}

impl SelectionCache {
    /// Forgets the selection: the next step selects afresh.
    pub fn invalidate(&mut self) {
        self.valid = false;
        self.lattices.clear();
    }

    /// Whether selections may be reused (the default).
    pub fn set_reuse(&mut self, reuse: bool) {
        self.no_reuse = !reuse;
    }

    /// Steps that replayed a selection.
    pub fn replays(&self) -> u64 {
        self.replays
    }

    /// Steps that selected afresh.
    pub fn selections(&self) -> u64 {
        self.selections
    }

    /// Whether the selection holds for the parts of `field` (this step's
    /// sweeps) with the surface `members` at positions `position` (rest
    /// positions `rest_m`), and the model at `topology`.
    pub fn holds(
        &self,
        field: &ContactField,
        members: &[VertexId],
        position: impl Fn(VertexId) -> Vec3,
        rest_m: &[Vec3],
        topology: u64,
    ) -> bool {
        if !self.valid
            || self.no_reuse
            || self.age >= MAX_REUSE_STEPS
            || self.topology != topology
            || self.parts.len() != field.parts().len()
            || self.surface_m.len() != members.len()
        {
            return false;
        }
        let mut least_slack = Real::INFINITY;
        for (s, p) in self.parts.iter().zip(field.parts()) {
            if s.tool != p.tool || s.tip != p.tip {
                return false;
            }
            let moved = part_motion_m(&s.to, p);
            if moved > s.slack_m {
                return false;
            }
            least_slack = least_slack.min(s.slack_m - moved);
        }
        // A triangle whose lattice a fresh selection would split otherwise
        // (it stretched) has other points.
        let same_lattices = self.lattices.iter().all(|&(tri, n, spacing_m)| {
            let x0 = tri.map(|v| rest_m[v as usize]);
            let x = tri.map(|v| position(VertexId(v)));
            subdivisions(&x0, &x, spacing_m) == n
        });
        // The surface's largest motion, stopping as soon as it is too far.
        let limit2 = least_slack * least_slack;
        same_lattices
            && members
                .iter()
                .zip(&self.surface_m)
                .all(|(&v, x0)| position(v).distance_squared(*x0) <= limit2)
    }

    /// Notes a triangle the selection looked at, split `n` times per edge
    /// for points `spacing_m` apart.
    pub fn note_lattice(&mut self, tri: [u32; 3], n: usize, spacing_m: Real) {
        // A selection within a step (invalidated) is never replayed.
        if self.valid {
            self.lattices.push((tri, n, spacing_m));
        }
    }

    /// Part `k`'s points (their `part` is the index at the selection).
    pub fn points_of(&self, k: usize) -> &[ContactPoint] {
        let s = &self.parts[k];
        &self.points[s.start..s.end]
    }

    /// Counts a step served by the selection.
    pub fn replayed(&mut self) {
        self.age += 1;
        self.replays += 1;
    }

    /// Starts recording a fresh selection of the surface `members` (at
    /// `position`) and the model at `topology`.
    pub fn begin(
        &mut self,
        members: &[VertexId],
        position: impl Fn(VertexId) -> Vec3,
        topology: u64,
    ) {
        self.parts.clear();
        self.points.clear();
        self.lattices.clear();
        self.surface_m.clear();
        self.surface_m.extend(members.iter().map(|&v| position(v)));
        self.topology = topology;
        self.age = 0;
        self.valid = true;
        self.selections += 1;
    }

    /// Records part `sweep`'s points, `field.points()[from..]`, selected
    /// `slack_m` beyond the step's reach.
    pub fn record(&mut self, sweep: &PartSweep, slack_m: Real, field: &ContactField, from: usize) {
        let start = self.points.len();
        self.points.extend_from_slice(&field.points()[from..]);
        self.parts.push(Selected {
            tool: sweep.tool,
            tip: sweep.tip,
            to: sweep.to,
            slack_m,
            start,
            end: self.points.len(),
        });
    }
}

/// How much of a selection's slack part `p` uses this step (m): its
/// segment's largest end displacement from the selected one, plus twice its
/// motion within the step (a point within reach of the part during the
/// step is kept if it is within reach plus twice that motion of the part at
/// the end of the step; see [`crate::contact::penalty::sampling`]).
fn part_motion_m(selected: &Segment, p: &PartSweep) -> Real {
    p.to.end_shift_m(selected) + 2.0 * p.motion_m()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(z: Real) -> Segment {
        Segment {
            a_m: Vec3::new(0.0, 0.0, z + 0.01),
            b_m: Vec3::new(0.0, 0.0, z),
        }
    }

    fn sweep(from: Real, to: Real) -> PartSweep {
        PartSweep {
            tool: 0,
            tip: true,
            from: seg(from),
            to: seg(to),
            radius_m: 0.002,
        }
    }

    fn point() -> ContactPoint {
        ContactPoint {
            vertices: [0, 1, 2],
            weights: [0.2, 0.3, 0.5],
            part: 7,
            stiffness_n_per_m: 10.0,
        }
    }

    /// A cache holding one part selected at z = 0 with `slack` beyond reach,
    /// over a surface of one vertex at the origin.
    fn cache(slack: Real) -> (SelectionCache, ContactField) {
        let mut c = SelectionCache::default();
        let members = [VertexId(0)];
        c.begin(&members, |_| Vec3::ZERO, 3);
        let mut f = ContactField::new(1, 0.0);
        let s = sweep(0.0, 0.0);
        f.add_part(s);
        f.push(point());
        c.record(&s, slack, &f, 0);
        (c, f)
    }

    #[test]
    fn holds_while_part_and_tissue_moved_less_than_the_slack() {
        let (c, _) = cache(0.001);
        let members = [VertexId(0)];
        let mut f = ContactField::new(1, 0.0);
        f.add_part(sweep(0.0002, 0.0003));
        // Part 0.3 mm from the selection plus twice 0.1 mm within the
        // step, tissue 0.4 mm: 0.9 <= 1 mm.
        let tissue = |_| Vec3::new(0.0004, 0.0, 0.0);
        assert!(c.holds(&f, &members, tissue, &[], 3));
        // Tissue 0.6 mm: 1.1 mm > 1 mm.
        let tissue = |_| Vec3::new(0.0, 0.0006, 0.0);
        assert!(!c.holds(&f, &members, tissue, &[], 3));
        // The motion within the step counts twice: 0 + 2 x 0.55 mm.
        let mut f = ContactField::new(1, 0.0);
        f.add_part(sweep(0.00055, 0.0));
        assert!(!c.holds(&f, &members, |_| Vec3::ZERO, &[], 3));
    }

    #[test]
    fn a_cut_a_new_part_age_or_invalidation_end_it() {
        let (mut c, f) = cache(0.001);
        let members = [VertexId(0)];
        let still = |_| Vec3::ZERO;
        assert!(c.holds(&f, &members, still, &[], 3));
        assert!(!c.holds(&f, &members, still, &[], 4), "topology changed");
        let mut two = ContactField::new(2, 0.0);
        two.add_part(sweep(0.0, 0.0));
        two.add_part(PartSweep {
            tool: 1,
            ..sweep(0.0, 0.0)
        });
        assert!(!c.holds(&two, &members, still, &[], 3), "a part appeared");
        let mut shaft = ContactField::new(1, 0.0);
        shaft.add_part(PartSweep {
            tip: false,
            ..sweep(0.0, 0.0)
        });
        assert!(!c.holds(&shaft, &members, still, &[], 3), "another part");
        for _ in 0..MAX_REUSE_STEPS {
            assert!(c.holds(&f, &members, still, &[], 3));
            c.replayed();
        }
        assert!(!c.holds(&f, &members, still, &[], 3), "too old");
        let (mut c, f) = cache(0.001);
        c.invalidate();
        assert!(!c.holds(&f, &members, still, &[], 3));
    }

    #[test]
    fn the_recorded_points_are_kept_per_part() {
        let (mut c, _) = cache(0.001);
        assert_eq!(c.points_of(0), &[point()]);
        c.replayed();
        assert_eq!((c.replays(), c.selections()), (1, 1));
    }
}
