//! The `local-problem` extrapolator: the simulation's contact problem
//! around the tool, solved again for each new tool position (the idea of
//! SOFA's LCPForceFeedback, Saupin, Duriez, Cotin 2008, with the penalty
//! contact of this project instead of Signorini's law).
//!
//! With each force sample the simulation sends the surface near the tool:
//! its contact points (barycentric on the surface triangles, with their
//! spring stiffness k_p), the positions x of the triangles' vertices V, the
//! tool's capsules, and the tissue's compliance W = (K^-1)_VV. For a tool
//! moved by dx from the sample, the vertices move by delta, the stationary
//! point of
//!
//! ```text
//! Pi(delta) = 1/2 delta^T S delta + delta^T f0 + sum_p E_p(y_p(delta), capsules + dx)
//! ```
//!
//! with S = W^-1 (the tissue condensed on V, exact for the linear model),
//! f0 the penalty forces on V at the sample (so delta = 0 solves the
//! sample's own pose), y_p the point's position and E_p its spring energy
//! (the law of the simulation's field: `k d^2 / (2 d0)` up to the onset
//! depth d0, `k (d - d0/2)` past it, d the penetration into the capsule).
//! Newton's method with a backtracking line search on Pi finds it (warm
//! started from the previous tick; with a Hessian that is not positive
//! definite, as a round tool on a crease can make it, the springs' part
//! alone, which is). The force rendered is the sample's force plus the
//! change of the points' force on the tool: exact at the sample's pose,
//! continuous, and zero when no point touches the moved tool.
//!
//! What it adds over the local model: the geometry. Sliding over a faceted
//! or curved surface, the contact points, their normals and which of them
//! touch change with the tool, and the coupling between them through the
//! tissue is W's; a vertex slipping around the probe (a snap) is in the
//! problem. With the tissue's inertia the simulation sends along
//! ([`LocalProblem::set_inertia`], `inertia.rs`) each solve is instead an
//! implicit Euler step of the tissue condensed on V (Guyan), so the
//! problem follows the damped, massive tissue between samples. What it
//! leaves out: friction, points beyond the margin the simulation sampled,
//! other tools' contacts (held as they were).
//!
//! Fixed capacity ([`MAX_VERTICES`], [`MAX_POINTS`]): after
//! [`LocalProblem::new`] neither [`LocalProblem::set`] nor
//! [`LocalProblem::solve`] allocates.

mod dense;
mod inertia;
mod newton;
mod render;
mod setup;

use inertia::{ForceHistory, Inertia};
use newton::{Budget, Scratch, Selection};
use render::ToolTrack;

use crate::math::{V3, ZERO, norm, sub};
pub use shared::protocol::{
    LOCAL_MAX_PARTS as MAX_PARTS, LOCAL_MAX_POINTS as MAX_POINTS,
    LOCAL_MAX_VERTICES as MAX_VERTICES, LocalContactMsg, LocalPart as Capsule, LocalPoint as Point,
};
/// In contact, the rendered change is at most this many times the
/// sample's contact stiffness (spectral norm) times the tool's distance from
/// the sample. Measured (`hapbench extrapolation`, twelve runs): without it
/// 0.917x the constant hold's error on average, worse than it at 250 Hz
/// (the problem's snaps come early); with 1.5, 0.883x and at most 1.02x;
/// 3 held less.
pub const CHANGE_OF_STIFFNESS: f64 = 1.5;
/// A release of every point the problem finds while the tool has moved out
/// of the newest sample's contact by less than this share of the distance
/// at which the sample's linearisation lets go is not rendered (the
/// sample's `local-normal` is): see `render.rs`. Measured with `hapbench
/// extrapolation` on press-palpate-slide paths over a 5 mm-cell box at
/// 30 Hz: with inertia the problem rendered 0 N for runs of 10 ticks in
/// steady contact (19 ticks on one of three paths) where the simulation
/// said 0.27-0.41 N.
pub const RELEASE_SHARE: f64 = 0.5;
/// A problem taken this long before the newest sample is not used (ns).
pub const MAX_AGE_NS: u64 = 100_000_000;
/// A tool moving faster than this (m/s) is not rendered from the problem
/// (the caller falls back to the newest sample's `local-normal`): the
/// tissue's mass condensed on the problem's few vertices (Guyan) makes a
/// fast slide ring, a one-tick spike of 1-1.5 N then a dip to zero, where
/// the simulation's force stays between 0.3 and 0.6 N. Measured with
/// `hapbench extrapolation` on the liver, strokes of +-20 mm at a 1 kHz
/// simulation: at 1.5 Hz (0.19 m/s at most) the problem errs 0.55x the
/// constant hold, at 3 Hz (0.38 m/s) 1.4x, at 6 Hz (0.75 m/s) 3.6x.
pub const MAX_TOOL_SPEED_M_S: f64 = 0.25;
/// With inertia: the problem's force change is kept for this many ticks,
/// to re-base it on a newer sample (256 ms at 1 kHz, beyond
/// [`MAX_AGE_NS`]).
const HISTORY: usize = 256;
/// Newton iterations per solve at most, over its rounds: bounds the RT
/// thread's time (an unfinished solve goes on from where it stopped at
/// the next tick).
const RENDER_ITERATIONS: usize = 16;
/// A Newton iteration moves no vertex further than this many tool radii.
const TRUST_OF_RADIUS: f64 = 0.25;
/// Converged when no vertex moves more than this in an iteration (m).
const TOLERANCE_M: f64 = 1e-8;
/// Converged when no vertex's forces are out of balance by this (N): a
/// hundredth of a haptic device's force resolution.
const TOLERANCE_N: f64 = 1e-4;
/// Points closer than this to touching are in the Newton iterations (m);
/// a check over all points after them catches the rest.
const CANDIDATE_SLACK_M: f64 = 1e-3;

/// Where [`LocalProblem::evaluate`] adds the points' Hessian: a block
/// over the vertices `slot` maps to `0..size / 3`.
struct Block<'a> {
    h: &'a mut [f64],
    springs_only: bool,
    slot: &'a [u16],
    size: usize,
}

/// Why a problem was refused (the extrapolator then holds the sample).
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LocalProblemError {
    /// More than the fixed capacity.
    #[error(
        "the local problem has {vertices} vertices, {points} points, {parts} parts; at most {MAX_VERTICES}, {MAX_POINTS}, {MAX_PARTS}"
    )]
    TooLarge {
        /// Vertices given.
        vertices: usize,
        /// Points given.
        points: usize,
        /// Parts given.
        parts: usize,
    },
    /// The sizes disagree, an index is out of range or a value is not
    /// finite.
    #[error("the local problem is malformed: {0}")]
    Malformed(&'static str),
    /// W is not positive definite.
    #[error("the local problem's compliance is not positive definite")]
    NotDefinite,
}

/// The problem of one sample and the scratch to solve it (see the module
/// docs). A clone has the full capacity too (the triple buffer that hands
/// problems to the RT thread is made of clones).
#[derive(Debug)]
pub struct LocalProblem {
    tool_m: V3,
    parts: [Capsule; MAX_PARTS],
    part_count: usize,
    x: Vec<V3>,
    points: Vec<Point>,
    /// S = W^-1, row-major (3V)^2.
    s: Vec<f64>,
    /// W itself.
    w: Vec<f64>,
    /// Forces on V at the sample (N), 3V.
    f0: Vec<f64>,
    /// The points' force on the tool at the sample (N).
    tool_force0_n: V3,
    /// f0 less this tick's inertial term (f0 itself without inertia).
    f0_eff: Vec<f64>,
    /// The previous solution (warm start), 3V.
    delta: Vec<f64>,
    /// The trust region: the most a vertex moves per iteration (m).
    max_move_m: f64,
    /// The last Newton run: whether it converged, and its iterations.
    converged: bool,
    iterated: usize,
    ready: bool,
    /// The force message `seq` of the step the problem was taken at.
    seq: u64,
    /// When it was taken (ns).
    t_ns: u64,
    /// The latest sample rendered from: its `seq`, and the points' force
    /// on the tool at its position less that at the problem's own.
    base: Option<(u64, V3)>,
    /// The tissue's condensed mass and velocities (empty: quasi-static).
    inertia: Inertia,
    /// With inertia: each tick's force change.
    history: ForceHistory,
    /// What a render may still spend.
    budget: Budget,
    /// The tool's recent positions, for its speed.
    track: ToolTrack,
    /// The points that may touch in this solve.
    selection: Selection,
    /// The Newton iterations' buffers.
    scratch: Scratch,
}

impl Clone for LocalProblem {
    fn clone(&self) -> Self {
        let mut out = Self::new();
        out.clone_from(self);
        out
    }

    fn clone_from(&mut self, o: &Self) {
        // Vec::clone_from copies into the existing allocation (the full
        // capacity `new` made), so a clone allocates nothing.
        self.tool_m = o.tool_m;
        self.parts = o.parts;
        self.part_count = o.part_count;
        self.x.clone_from(&o.x);
        self.points.clone_from(&o.points);
        self.s.clone_from(&o.s);
        self.w.clone_from(&o.w);
        self.f0.clone_from(&o.f0);
        self.f0_eff.clone_from(&o.f0_eff);
        self.tool_force0_n = o.tool_force0_n;
        self.delta.clone_from(&o.delta);
        self.max_move_m = o.max_move_m;
        self.ready = o.ready;
        self.seq = o.seq;
        self.t_ns = o.t_ns;
        self.base = o.base;
        self.inertia.clone_from(&o.inertia);
        self.history = o.history;
        self.budget.time = o.budget.time;
        self.track = o.track;
        self.selection.clone_from(&o.selection);
        self.scratch.carry_from(&o.scratch);
    }
}

impl Default for LocalProblem {
    fn default() -> Self {
        Self::new()
    }
}

impl LocalProblem {
    /// An empty problem with its full capacity allocated.
    pub fn new() -> Self {
        let n = 3 * MAX_VERTICES;
        let part = Capsule {
            a_m: ZERO,
            b_m: ZERO,
            radius_m: 0.0,
            onset_m: 0.0,
        };
        Self {
            tool_m: ZERO,
            parts: [part; MAX_PARTS],
            part_count: 0,
            x: Vec::with_capacity(MAX_VERTICES),
            points: Vec::with_capacity(MAX_POINTS),
            s: Vec::with_capacity(n * n),
            w: Vec::with_capacity(n * n),
            f0: Vec::with_capacity(n),
            tool_force0_n: ZERO,
            f0_eff: Vec::with_capacity(n),
            delta: Vec::with_capacity(n),
            max_move_m: 0.0,
            converged: false,
            iterated: 0,
            ready: false,
            seq: 0,
            t_ns: 0,
            base: None,
            inertia: Inertia::with_capacity(n),
            history: ForceHistory::default(),
            budget: Budget::default(),
            track: ToolTrack::default(),
            selection: Selection::with_capacity(MAX_POINTS),
            scratch: Scratch::with_capacity(MAX_VERTICES),
        }
    }

    /// Whether a problem is set.
    pub fn is_ready(&self) -> bool {
        self.ready
    }

    /// Forgets the problem.
    pub fn clear(&mut self) {
        self.ready = false;
    }

    /// Bounds each render's time as well as its iterations: no Newton
    /// iteration starts once `budget` has passed since the render began (the
    /// solve goes on from there at the next tick, as when the iterations
    /// run out). `None` (the default): iterations only, deterministic.
    pub fn set_time_budget(&mut self, budget: Option<std::time::Duration>) {
        self.budget.time = budget;
    }

    /// The force message `seq` of the step the problem was taken at.
    pub fn seq(&self) -> u64 {
        self.seq
    }

    /// The points' force on the tool (N) with the tool at `tool_m`, less
    /// the same at the sample's pose; `None` without a problem or when the
    /// solve fails (then the caller holds the sample). The second value
    /// says whether any point touches the tool there.
    pub fn solve(&mut self, tool_m: V3) -> Option<(V3, bool)> {
        self.budget.begin(true);
        self.solve_within_budget(tool_m)
    }

    /// [`LocalProblem::solve`] with the iterations left in `budget`.
    fn solve_within_budget(&mut self, tool_m: V3) -> Option<(V3, bool)> {
        if !self.ready || !tool_m.iter().all(|x| x.is_finite()) {
            return None;
        }
        let n = self.delta.len();
        let dx = sub(tool_m, self.tool_m);
        let inertia = !self.inertia.m_red.is_empty();
        if inertia {
            // This step's inertial load: M (a delta_k + v_k / h), a = 1/h^2
            // + c/h, moved to f0.
            let h = self.inertia.step_s;
            let a = 1.0 / (h * h) + self.inertia.damping_per_s / h;
            for (r, row) in self.inertia.m_red.chunks_exact(n).enumerate() {
                let b: f64 = row
                    .iter()
                    .zip(self.delta.iter().zip(&self.inertia.vel))
                    .map(|(m, (d, v))| m * (a * d + v / h))
                    .sum();
                self.f0_eff[r] = self.f0[r] - b;
            }
            self.inertia.delta_prev.clear();
            self.inertia.delta_prev.extend_from_slice(&self.delta);
        }
        let mut forces = std::mem::take(&mut self.scratch.forces);
        forces.resize(n, 0.0);
        // Newton over the points near the tool; then a check over all that
        // no other point touches, else again with a wider selection. With
        // the iteration budget spent, the state reached stands (the next
        // tick goes on from it).
        let mut slack_m = CANDIDATE_SLACK_M;
        self.scratch.start.clear();
        self.scratch.start.extend_from_slice(&self.delta);
        for round in 0..3 {
            if round > 0 {
                // From the warm start again: a point the last round left
                // out may have gone through the capsule.
                self.delta.copy_from_slice(&self.scratch.start);
            }
            // The selection of an earlier tick serves while the tool is
            // within half the slack of where it was made (points entering
            // anyway are caught below).
            let moved = norm(sub(dx, self.selection.selected_dx));
            if round > 0 || !self.selection.selected || moved > 0.5 * CANDIDATE_SLACK_M {
                self.select(dx, slack_m);
                self.selection.selected = round == 0;
                self.selection.selected_dx = dx;
            }
            if !self.newton(dx, &mut forces) {
                // The state before this solve stays (the next tick starts
                // from it, as when the others-touch check fails below).
                self.delta.copy_from_slice(&self.scratch.start);
                self.scratch.forces = forces;
                if inertia {
                    self.end_first_step();
                }
                return None;
            }
            if !self.others_touch(dx) {
                break;
            }
            if self.budget.left == 0 || round == 2 {
                // Points outside the iterations touch and no time is left
                // to take them in: this tick says nothing (the caller
                // falls back), the next starts where this one did.
                self.delta.copy_from_slice(&self.scratch.start);
                self.scratch.forces = forces;
                if inertia {
                    self.end_first_step();
                }
                return None;
            }
            slack_m *= 4.0;
        }
        if inertia && !self.converged && self.iterated == 0 {
            // The budget was spent before the step's first iteration (a
            // render that started late): committing the unmoved state
            // would stop every vertex (v = 0). This tick falls back; the
            // next takes the same step again.
            self.delta.copy_from_slice(&self.scratch.start);
            self.scratch.forces = forces;
            return None;
        }
        // No point outside the active ones touches: they are the force.
        let (_, tool, touching) = self.evaluate(&self.delta, dx, &mut forces, None);
        if inertia {
            let h = self.inertia.step_s;
            for ((v, d), p) in self
                .inertia
                .vel
                .iter_mut()
                .zip(&self.delta)
                .zip(&self.inertia.delta_prev)
            {
                *v = (d - p) / h;
            }
            self.end_first_step();
        }
        let change = sub(tool, self.tool_force0_n);
        let out = change
            .iter()
            .all(|x| x.is_finite())
            .then_some((change, touching));
        self.scratch.forces = forces;
        out
    }
}

#[cfg(test)]
mod tests;
