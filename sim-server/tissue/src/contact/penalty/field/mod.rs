//! The penalty contact field: compliant, frictionless contact between the
//! tool capsules and points spread over the surface triangles, evaluated at
//! every integrator sub-step (not once per step), so that its stiffness can
//! be far above what a force held for a whole step would tolerate.
//!
//! Each contact point p sits on a surface triangle at barycentric weights
//! w (its position x = sum w_j x_j, its velocity likewise). Against a tool
//! part (a capsule: segment S, radius r) its gap is g = |x - c| - r, with c
//! the closest point of S; the normal n = (x - c) / |x - c| is the distance
//! field's gradient. While g < 0 (penetration d = -g) the point feels the
//! Hunt-Crossley force (Hunt and Crossley 1975; the compliant-contact model
//! of haptics and of e.g. MuJoCo's soft contacts)
//!
//! ```text
//! f = k_p d (1 + alpha d')+      d' = rate of penetration
//! ```
//!
//! spread to the triangle's vertices by w, and the tool feels -f n. It is
//! continuous in the tool pose (zero at zero gap), never sticky (the factor
//! is clamped to [0, 2]: the damping never pulls and never more than
//! doubles the spring), and frictionless (along n only) unless the tool
//! has Coulomb friction: then each point also carries a tangential
//! stick-slip spring of stiffness k_p, |f_t| <= mu f (`contact::penalty::field::friction`).
//! The point
//! stiffness is k_p = kappa a_p, a foundation modulus times the point's
//! share of the rest area, so the total over a surface does not depend on
//! how finely it is sampled.
//!
//! The tool moves during the step: each part is swept linearly from its
//! pose at the previous step to the new one across the sub-steps, so a
//! fast tool pushes the tissue ahead of it instead of jumping through it.
//!
//! The force on the tool reported for a step is the mean over the
//! sub-steps of its last [`REPORT_WINDOW_S`] (the whole step if shorter):
//! the sample is published with the tool's pose at the end of the step,
//! and a mean over a whole long step describes the tool half a step
//! earlier (at 100 Hz the sample then matched the 1 kHz truth 10 ms
//! earlier three times better than at its own pose). The window still
//! averages the stiff springs' sub-step ripple, as a 1 kHz step does.

use crate::contact::instrument::Friction;
use crate::contact::instrument::Segment;
use crate::math::{Mat3, Real, Vec3};
use crate::tensor_mass::{ForcePoint, ForceTerm};
use friction::{Carried, Stick, point_key};
use implicit::ImplicitSprings;

/// One contact point: a triangle's vertices, its barycentric weights, the
/// tool part it faces and its stiffness.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactPoint {
    /// The triangle's vertices.
    pub vertices: [u32; 3],
    /// Barycentric weights (sum 1).
    pub weights: [Real; 3],
    /// Index of the tool part (see [`ContactField::add_part`]).
    pub part: u16,
    /// k_p (N/m).
    pub stiffness_n_per_m: Real,
}

/// A tool part swept through one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PartSweep {
    /// The tool this part belongs to.
    pub tool: usize,
    /// Whether it is the tip (false: the shaft).
    pub tip: bool,
    /// The segment at the start of the step.
    pub from: Segment,
    /// The segment at the end of the step.
    pub to: Segment,
    /// The capsule radius (m).
    pub radius_m: Real,
}

impl PartSweep {
    /// How far the part moves during the step (m): its ends' largest
    /// displacement.
    pub fn motion_m(&self) -> Real {
        self.to.end_shift_m(&self.from)
    }

    /// The segment at fraction `s` of the step.
    fn at(&self, s: Real) -> Segment {
        Segment {
            a_m: self.from.a_m.lerp(self.to.a_m, s),
            b_m: self.from.b_m.lerp(self.to.b_m, s),
        }
    }
}

/// The first this fraction of the radius of penetration is a quadratic
/// onset: a point's force then grows from zero with zero slope, so the
/// total force stays smooth (C1) as points enter contact one by one.
pub const ONSET_OF_RADIUS: Real = 0.02;

/// A triangle's points are skipped together only when its bounding sphere
/// clears the capsule by this fraction of the radius: far above the
/// rounding of the distances, so exactly the points that point-by-point
/// tests would find out of contact are skipped.
const CLEAR_MARGIN: Real = 1e-9;
/// ... plus this much (m), for a radius so small that its relative margin
/// would fall below the rounding of coordinates (~1e-16 m per metre).
const CLEAR_MARGIN_M: Real = 1e-12;

/// The reported force is the mean over this last part of a step (s): one
/// period of a 1 kHz haptic loop.
pub const REPORT_WINDOW_S: Real = 1e-3;

/// A point's spring force (N) at penetration `depth_m` and its slope
/// (N/m): `k d^2 / (2 d0)` below the onset depth d0, `k (d - d0/2)` above.
pub fn spring(k_n_per_m: Real, depth_m: Real, radius_m: Real) -> (Real, Real) {
    let d0 = ONSET_OF_RADIUS * radius_m;
    if depth_m < d0 {
        (
            k_n_per_m * depth_m * depth_m / (2.0 * d0),
            k_n_per_m * depth_m / d0,
        )
    } else {
        (k_n_per_m * (depth_m - 0.5 * d0), k_n_per_m)
    }
}

/// A point's spring energy (J) at penetration `depth_m`: the integral of
/// [`spring`]'s force over the depth (`k d^3 / (6 d0)` below the onset,
/// `k (d^2 / 2 - d0 d / 2 + d0^2 / 6)` above), the merit a static solve
/// descends on.
pub fn spring_energy(k_n_per_m: Real, depth_m: Real, radius_m: Real) -> Real {
    let d0 = ONSET_OF_RADIUS * radius_m;
    if depth_m <= 0.0 {
        0.0
    } else if depth_m < d0 {
        k_n_per_m * depth_m * depth_m * depth_m / (6.0 * d0)
    } else {
        k_n_per_m * (0.5 * depth_m * depth_m - 0.5 * d0 * depth_m + d0 * d0 / 6.0)
    }
}

/// The contact damping is scaled down where its coefficient over a
/// vertex's mass, times the sub-step, would exceed this (explicit damping
/// stays monotone below 1).
pub const DAMPING_STABILITY: Real = 0.5;

pub use crate::tensor_mass::SubStep;

/// A point in contact at this evaluation.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Acting {
    /// Normal (from the tool to the point).
    n: Vec3,
    /// Spring force (N).
    spring: Real,
    /// Penetration rate (m/s).
    rate: Real,
    /// The point's motion relative to the tool over the sub-step (m).
    slip_m: Vec3,
}

/// The contact points of one step and what they did.
#[derive(Clone, Debug, Default)]
pub struct ContactField {
    points: Vec<ContactPoint>,
    parts: Vec<PartSweep>,
    /// Hunt-Crossley alpha (s/m).
    damping_s_per_m: Real,
    /// Vertices written by the last evaluation (zeroed before the next).
    dirty: Vec<u32>,
    /// Per tool: the sum over the sub-steps of the report window of the
    /// force on the tool (N).
    force_sum_n: Vec<Vec3>,
    /// Evaluations in the report window.
    evaluations: usize,
    /// Per point: the penetration of the last evaluation (m, 0 if none).
    penetration_m: Vec<Real>,
    /// Per part: its deepest point at the last evaluation (m, 0 if none).
    part_depth_m: Vec<Real>,
    /// Per point: the Hessian of its contact energy with respect to its
    /// position relative to the tool at the last evaluation (zero if not
    /// in contact).
    hessians: Vec<Mat3>,
    /// Per point: the spring part of its Hessian alone (slope n n^T).
    spring_hessians: Vec<Mat3>,
    /// Per point, this evaluation: where it acts.
    acting: Vec<Option<Acting>>,
    /// Per tool: its Coulomb friction.
    friction: Vec<Friction>,
    /// Per point: its identity across selections ([`point_key`]) and its
    /// friction state.
    keys: Vec<u64>,
    sticks: Vec<Stick>,
    /// The friction states of the points dropped last.
    carried: Carried,
    /// Springs integrated implicitly (`contact::penalty::field::implicit`), if so.
    implicit: Option<Box<ImplicitSprings>>,
    /// Whether the last evaluation was in the report window.
    last_reported: bool,
    /// Per tool: scratch for the implicit correction's force change.
    tool_change_n: Vec<Vec3>,
    /// Per vertex: the contact damping coefficients summed (scratch, zero
    /// between evaluations).
    damping_sum: Vec<Real>,
}

impl ContactField {
    /// An empty field for `tools` tools with Hunt-Crossley `damping_s_per_m`.
    pub fn new(tools: usize, damping_s_per_m: Real) -> Self {
        Self {
            damping_s_per_m,
            force_sum_n: vec![Vec3::ZERO; tools],
            friction: vec![Friction::NONE; tools],
            ..Self::default()
        }
    }

    /// The same with the springs integrated implicitly (`true`) or
    /// explicitly (see `contact::penalty::field::implicit`).
    pub fn with_implicit_springs(mut self, implicit: bool) -> Self {
        self.implicit = implicit.then(Box::default);
        self
    }

    /// Whether the springs are integrated implicitly.
    pub fn implicit_springs(&self) -> bool {
        self.implicit.is_some()
    }

    /// Corrects the explicit sub-step `u_new` (from `u_old`) for the
    /// springs of the last evaluation taken at its end (linearly implicit;
    /// see `contact::penalty::field::implicit`), `inverse_d(i)` being a free vertex's
    /// integration coefficient h^2 / m' (`None`: its motion is imposed).
    /// The tools' reported forces include the change. Does nothing when
    /// the springs are explicit. Returns the solver's iterations.
    pub fn correct_implicit(
        &mut self,
        inverse_d: impl Fn(usize) -> Option<Real>,
        u_old: &[[Real; 3]],
        u_new: &mut [[Real; 3]],
    ) -> usize {
        let Some(mut solver) = self.implicit.take() else {
            return 0;
        };
        let mut change = std::mem::take(&mut self.tool_change_n);
        change.resize(self.force_sum_n.len(), Vec3::ZERO);
        solver.correct(self, inverse_d, u_old, u_new, &mut change);
        if self.last_reported {
            for (sum, c) in self.force_sum_n.iter_mut().zip(&change) {
                *sum += *c;
            }
        }
        let iterations = solver.iterations();
        self.tool_change_n = change;
        self.implicit = Some(solver);
        iterations
    }

    /// The same with each tool's Coulomb friction (`per_tool[i]` for tool
    /// `i`; missing tools are frictionless).
    pub fn with_friction(mut self, per_tool: &[Friction]) -> Self {
        for (f, mu) in self.friction.iter_mut().zip(per_tool) {
            *f = *mu;
        }
        self
    }

    /// Starts a new step: no points, no parts, reactions cleared (the
    /// vertices written last are remembered, to be zeroed).
    pub fn clear(&mut self) {
        self.clear_points();
        self.parts.clear();
        self.part_depth_m.clear();
        self.restart_report();
    }

    /// Forgets the reactions summed so far in this step: a solver that
    /// evaluates the springs several times in a step (the precomputed
    /// backend's Newton iterations) reports its last evaluation only.
    pub(crate) fn restart_report(&mut self) {
        self.evaluations = 0;
        self.force_sum_n.fill(Vec3::ZERO);
    }

    /// Drops the points (within a step, before they are selected again);
    /// the parts and the step's reactions stay.
    pub fn clear_points(&mut self) {
        self.carried.save(&self.keys, &self.sticks);
        self.keys.clear();
        self.sticks.clear();
        self.points.clear();
        self.penetration_m.clear();
        self.hessians.clear();
        self.spring_hessians.clear();
        self.acting.clear();
    }

    /// Adds a swept tool part; returns its index for [`ContactField::push`].
    pub fn add_part(&mut self, part: PartSweep) -> u16 {
        self.parts.push(part);
        self.part_depth_m.push(0.0);
        (self.parts.len() - 1) as u16
    }

    /// Adds a contact point: a point that was in contact before the last
    /// [`ContactField::clear`] keeps its friction state (if its part was
    /// added first).
    pub fn push(&mut self, p: ContactPoint) {
        // Its part may come later (a selection being recorded): then it
        // starts unstuck.
        let part = self.parts.get(p.part as usize);
        // The key only where friction needs it (this runs for every point
        // of every step).
        let (key, stick) = match part {
            Some(part) if self.friction[part.tool].is_active() => {
                let key = point_key(&p, part);
                (key, self.carried.get(key))
            }
            _ => (0, Stick::default()),
        };
        self.keys.push(key);
        self.sticks.push(stick);
        self.points.push(p);
        self.penetration_m.push(0.0);
        self.hessians.push(Mat3::ZERO);
        self.spring_hessians.push(Mat3::ZERO);
        self.acting.push(None);
    }

    /// Whether there is nothing to evaluate and nothing to zero.
    pub fn is_idle(&self) -> bool {
        self.points.is_empty() && self.dirty.is_empty()
    }

    /// The points of this step.
    pub fn points(&self) -> &[ContactPoint] {
        &self.points
    }

    /// The parts of this step.
    pub fn parts(&self) -> &[PartSweep] {
        &self.parts
    }

    /// Tool `tool`'s deepest tip point at the last evaluation (m; 0: no
    /// contact).
    pub fn deepest_tip_m(&self, tool: usize) -> Real {
        self.parts
            .iter()
            .zip(&self.part_depth_m)
            .filter(|(p, _)| p.tip && p.tool == tool)
            .map(|(_, d)| *d)
            .fold(0.0, Real::max)
    }

    /// Per point: its penetration at the last evaluation (m; 0: no contact).
    pub fn penetrations_m(&self) -> &[Real] {
        &self.penetration_m
    }

    /// Per point: the Hessian (N/m) of its spring energy 1/2 k d^2 with
    /// respect to its position relative to the tool, at the last
    /// evaluation: k n n^T - (f / r_p) P, with r_p its distance to the
    /// axis and P the projector on the directions that turn the normal
    /// (perpendicular to n, and to the axis where the closest point is
    /// inside the segment): moving sideways against a round tool turns the
    /// force as much as it changes its size. Zero if not in contact.
    pub fn hessians(&self) -> &[Mat3] {
        &self.hessians
    }

    /// Per point: the spring part of its Hessian alone, slope n n^T (N/m).
    pub fn spring_hessians(&self) -> &[Mat3] {
        &self.spring_hessians
    }

    /// The springs' energy at the last evaluation (J): the sum of
    /// [`spring_energy`] over the points in contact (no damping, no
    /// friction: the potential a static solve descends on).
    pub fn spring_energy_j(&self) -> Real {
        (self.points.iter().zip(&self.penetration_m))
            .filter(|(_, d)| **d > 0.0)
            .map(|(p, d)| {
                let radius_m = self.parts[p.part as usize].radius_m;
                spring_energy(p.stiffness_n_per_m, *d, radius_m)
            })
            .sum()
    }

    /// Zeroes the forces the last evaluation wrote in `out`.
    pub fn zero(&mut self, out: &mut [[Real; 3]]) {
        for &v in &self.dirty {
            out[v as usize] = [0.0; 3];
        }
        self.dirty.clear();
    }

    /// Adds to `out` the contact forces at fraction `s` of the step, for
    /// displacements `u` and the previous sub-step's `u_prev` (`h_s` apart)
    /// over rest positions `rest_m`. Call [`ContactField::zero`] first.
    /// Friction states advance by the sub-step's motion.
    pub fn add_forces(
        &mut self,
        rest_m: &[Vec3],
        u: &[[Real; 3]],
        u_prev: &[[Real; 3]],
        at: SubStep,
        out: &mut [[Real; 3]],
    ) {
        self.evaluate(rest_m, u, u_prev, at, true, out);
    }

    /// The mean force on tool `i` over the evaluations of the last step's
    /// report window (N).
    pub fn force_n(&self, i: usize) -> Vec3 {
        match (self.force_sum_n.get(i), self.evaluations) {
            (Some(f), n) if n > 0 => *f / n as Real,
            _ => Vec3::ZERO,
        }
    }

    /// Evaluates once (no motion) for forces at `u`, without damping: for
    /// quasi-static checks and the stiffness probe.
    pub fn static_forces(&mut self, rest_m: &[Vec3], u: &[[Real; 3]], out: &mut [[Real; 3]]) {
        let alpha = std::mem::replace(&mut self.damping_s_per_m, 0.0);
        self.zero(out);
        let at = SubStep {
            h_s: 1.0,
            step_s: 1.0,
            s: 1.0,
            masses_kg: &[],
        };
        self.evaluate(rest_m, u, u, at, false, out);
        self.damping_s_per_m = alpha;
    }
}

impl ForcePoint for ContactPoint {
    fn vertices(&self) -> [u32; 3] {
        self.vertices
    }
    fn weights(&self) -> [Real; 3] {
        self.weights
    }
}

/// The penalty field as the integrators see it (each method is the one
/// above of the same name).
impl ForceTerm for ContactField {
    type Point = ContactPoint;

    fn is_idle(&self) -> bool {
        ContactField::is_idle(self)
    }
    fn zero(&mut self, out: &mut [[Real; 3]]) {
        ContactField::zero(self, out);
    }
    fn add_forces(
        &mut self,
        rest_m: &[Vec3],
        u: &[[Real; 3]],
        u_prev: &[[Real; 3]],
        at: SubStep,
        out: &mut [[Real; 3]],
    ) {
        ContactField::add_forces(self, rest_m, u, u_prev, at, out);
    }
    fn implicit_springs(&self) -> bool {
        ContactField::implicit_springs(self)
    }
    fn correct_implicit(
        &mut self,
        inverse_d: impl Fn(usize) -> Option<Real>,
        u_old: &[[Real; 3]],
        u_new: &mut [[Real; 3]],
    ) -> usize {
        ContactField::correct_implicit(self, inverse_d, u_old, u_new)
    }
    fn points(&self) -> &[ContactPoint] {
        ContactField::points(self)
    }
    fn penetrations_m(&self) -> &[Real] {
        ContactField::penetrations_m(self)
    }
    fn hessians(&self) -> &[Mat3] {
        ContactField::hessians(self)
    }
    fn spring_hessians(&self) -> &[Mat3] {
        ContactField::spring_hessians(self)
    }
    fn static_forces(&mut self, rest_m: &[Vec3], u: &[[Real; 3]], out: &mut [[Real; 3]]) {
        ContactField::static_forces(self, rest_m, u, out);
    }
    fn spring_energy_j(&self) -> Real {
        ContactField::spring_energy_j(self)
    }
    fn restart_report(&mut self) {
        ContactField::restart_report(self);
    }
}

mod evaluate;
mod friction;
mod implicit;

/// Test fixtures shared by the contact modules' unit tests.
#[cfg(test)]
pub(crate) mod fixtures;

#[cfg(test)]
mod tests;
