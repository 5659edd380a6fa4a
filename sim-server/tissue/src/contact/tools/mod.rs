//! The tools of a scene, updated together each step so that they share one
//! surface index and never fight over a vertex.

use super::config::ContactLaw;
use super::local::LocalContact;
use super::tool::ToolContact;
use super::{ContactReport, Reaction};
use crate::backend::Backend;
use crate::contact::penalty::field::ContactField;
use crate::contact::penalty::sampling::Sampler;
use crate::contact::response::worker::{ContactStiffness, StiffnessSolves};
use crate::contact::surface::adjacency::Adjacency;
use crate::contact::surface::crossing::Crossing;
use crate::contact::surface::index::SurfaceIndex;
use crate::contact::tool::claims::Claims;
use crate::ids::VertexId;
use crate::math::{Mat3, Real, Vec3};
use crate::tensor_mass::ElasticModel;
pub use local_problems::LocalSpec;
use local_problems::{LocalSampling, LocalScratch};

/// omega^2 the springs of `field`'s points may add: by Gershgorin, a
/// vertex's springs (sum of k_p w_p over the points on its triangles) over
/// its mass, the largest; 25% more for points selected again within a long
/// step. `spring_n_per_m` (zero outside `sprung`) and `sprung` are scratch.
fn springs_omega2(
    field: &ContactField,
    spring_n_per_m: &mut [Real],
    sprung: &mut Vec<u32>,
    model: &ElasticModel,
) -> Real {
    for p in field.points() {
        for (v, w) in p.vertices.iter().zip(p.weights) {
            let k = &mut spring_n_per_m[*v as usize];
            if *k == 0.0 {
                sprung.push(*v);
            }
            *k += w * p.stiffness_n_per_m;
        }
    }
    let masses = model.masses_kg();
    let mut omega2: Real = 0.0;
    for v in sprung.drain(..) {
        let k = std::mem::take(&mut spring_n_per_m[v as usize]);
        let m = masses[v as usize];
        if m > 0.0 {
            omega2 = omega2.max(1.25 * k / m);
        }
    }
    omega2
}

/// Simulated time between two selections of the contact points within a
/// step (s).
const RESAMPLE_EVERY_S: Real = 1e-3;

/// Where a tool is this step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToolInput {
    /// The requested tip position (m).
    pub tip_m: Vec3,
    /// Jaw opening, 0 closed to 1 open (ignored by tools without jaws).
    pub jaw_opening: Real,
}

/// Every tool of a scene with its contact state.
///
/// Each step, [`Tools::update`] runs, for all tools in turn: placing and
/// cutting; holding gripped tissue; sliding contact of the tips, then of
/// the shafts; and last, releasing what no tool holds any more and imposing
/// the rest. A vertex belongs to at most one tool per step: grips come
/// first (a held vertex is never taken by another tool's plane), then tools
/// in declaration order.
pub struct Tools {
    tools: Vec<ToolContact>,
    index: SurfaceIndex,
    adjacency: Adjacency,
    claims: Claims,
    reports: Vec<ContactReport>,
    law: ContactLaw,
    field: ContactField,
    sampler: Option<Sampler>,
    /// The tips' surface test (penalty law).
    crossing: Option<Crossing>,
    stiffness: Option<ContactStiffness>,
    /// Per tool: the last input with finite fields.
    last_inputs: Vec<Option<ToolInput>>,
    /// Per tool: the penalty contact stiffness after the last step.
    stiffness_n_per_m: Vec<Mat3>,
    mark: Vec<bool>,
    /// Per vertex: the contact springs on it this step (N/m), zero outside
    /// `sprung`.
    spring_n_per_m: Vec<Real>,
    sprung: Vec<u32>,
    /// The contact problems' request and scratch.
    local: LocalScratch,
    /// Steps taken.
    steps: u64,
    /// The stiffness hand-over waits for [`Tools::hand_over`] instead of
    /// ending [`Tools::step`] (see [`Tools::hand_over_after_sample`]).
    deferred_hand_over: bool,
    /// Simulated time since the last hand-over (s), while deferred.
    hand_over_due_s: Real,
    /// The corotational region round the tips, when the scene asks.
    follow: Option<super::follow_region::FollowRegion>,
}

/// Why contact cannot run as the scene asks.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ContactError {
    /// The scene asks for a corotational region round the tools on a
    /// backend whose model is fixed when it starts.
    #[error(
        "[contact] corotational_radius_m needs the tensor-mass backend, which changes its elements' model while it runs; the {backend} backend fixes its model when it starts: make the region static with a [[region]] of model = \"corotational\""
    )]
    CorotationalRegionUnsupported {
        /// The backend's name.
        backend: &'static str,
    },
    /// The scene asks for the penalty law on a backend that cannot
    /// integrate it.
    #[error(
        "[contact] law = \"penalty\" needs a backend that integrates it at every sub-step or solves each step's equilibrium with it (tensor-mass, precomputed); the {backend} backend has only the projection law (law = \"projection\")"
    )]
    PenaltyUnsupported {
        /// The backend's name.
        backend: &'static str,
    },
    /// A contact constant is out of range.
    #[error("[contact] {key} must be a {range} finite number, got {value}")]
    BadConstant {
        /// The key.
        key: &'static str,
        /// Its value.
        value: Real,
        /// What it must be: "positive", or "zero or positive".
        range: &'static str,
    },
    /// The implicit springs asked stiffer than they integrate faithfully
    /// ([`super::MAX_IMPLICIT_STIFFNESS_FACTOR`]).
    #[error(
        "[contact] stiffness_factor must be at most {max:e} with the implicit springs (beyond it their linearisation no longer holds the force), got {value}: use springs = \"explicit\" for a stiffer contact (more sub-steps)"
    )]
    TooStiffForImplicitSprings {
        /// The factor asked for.
        value: Real,
        /// The largest accepted.
        max: Real,
    },
    /// A tool asks for friction under the projection law.
    #[error(
        "tool {tool:?} has friction, which the penalty contact law models; the contact here is the projection law (on the {backend} backend), whose prescribed vertices cannot slide: remove friction_static/friction_dynamic or use law = \"penalty\" on a tensor-mass backend"
    )]
    FrictionUnsupported {
        /// The tool's name.
        tool: String,
        /// The backend's name.
        backend: &'static str,
    },
    /// A tool asks for friction on a static backend.
    #[error(
        "tool {tool:?} has friction, whose stick-slip springs follow the tissue's motion between steps; the {backend} backend is static (it solves each step's equilibrium, with no motion between): remove friction_static/friction_dynamic or use the tensor-mass backend"
    )]
    FrictionStatic {
        /// The tool's name.
        tool: String,
        /// The backend's name.
        backend: &'static str,
    },
    /// A tool's friction coefficients are out of range.
    #[error("tool {tool:?}: {why}")]
    BadFriction {
        /// The tool's name.
        tool: String,
        /// What is wrong.
        why: String,
    },
}

impl Tools {
    /// The contact law in force.
    pub fn law(&self) -> ContactLaw {
        self.law
    }

    /// The penalty contact field of the last step.
    pub fn field(&self) -> &ContactField {
        &self.field
    }

    /// Advances `sim` one step with the contact the last
    /// [`Tools::update`] set up, and completes each tool's report (whether
    /// it touched tissue during the step). Use instead of `sim.step()`.
    pub fn step<B: Backend>(&mut self, sim: &mut B) -> &[ContactReport] {
        if let (ContactLaw::Penalty, Some(sampler)) = (self.law, &mut self.sampler) {
            let (index, adj) = (&mut self.index, &self.adjacency);
            // A long step (a slow simulation) re-selects the points from
            // the current positions every millisecond of simulated time:
            // tissue can move further than the margin in one long step.
            let mut resample = |sim: &B, field: &mut ContactField| {
                index.refit(sim);
                field.clear_points();
                for part in 0..field.parts().len() {
                    sampler.sample(sim, index, adj, part as u16, field);
                }
            };
            sim.step_with_contact(&mut self.field, RESAMPLE_EVERY_S, &mut resample);
        } else {
            sim.step();
        }
        for (t, r) in self.tools.iter_mut().zip(&mut self.reports) {
            r.contact = t.after_step(&self.field, &mut self.mark);
        }
        self.steps += 1;
        if self.deferred_hand_over {
            self.hand_over_due_s += sim.dt_s();
            // What the hand-over does first, kept before the sample: no
            // contact, no stiffness (the sample says zero at once).
            if self.stiffness.is_some() && !self.field.penetrations_m().iter().any(|d| *d > 0.0) {
                self.stiffness_n_per_m.fill(Mat3::ZERO);
            }
        } else {
            self.hand_over_since(sim, sim.dt_s());
        }
        &self.reports
    }

    /// Has [`Tools::step`] leave the contact stiffness's hand-over (the
    /// snapshot of the contact set for the stiffness solver, a contact
    /// problem's sampling, taking the solver's results) to
    /// [`Tools::hand_over`], which a live loop calls once the step's force
    /// sample is out: on the liver it is nearly nothing on most steps and
    /// up to a few hundred microseconds on a few (p90 29 us, p99 358 us),
    /// which delayed those steps' forces. The sample then carries the
    /// stiffness received a step earlier (zero at once when nothing
    /// touches) (it is a few steps old anyway: the
    /// solver works on snapshots every `HAND_OVER_EVERY_S` (`contact/response/worker.rs`)).
    pub fn hand_over_after_sample(&mut self, deferred: bool) {
        self.deferred_hand_over = deferred;
    }

    /// The hand-over [`Tools::step`] left (see
    /// [`Tools::hand_over_after_sample`]); nothing when none is pending.
    pub fn hand_over<B: Backend + ?Sized>(&mut self, sim: &B) {
        if self.deferred_hand_over && self.hand_over_due_s > 0.0 {
            let since_s = std::mem::take(&mut self.hand_over_due_s);
            self.hand_over_since(sim, since_s);
        }
    }

    /// The stiffness hand-over after `since_s` of simulated time.
    fn hand_over_since<B: Backend + ?Sized>(&mut self, sim: &B, since_s: Real) {
        if let Some(k) = &mut self.stiffness {
            let spec = self.local.spec;
            self.local.since_s += since_s;
            let due = spec.is_some_and(|s| self.local.since_s >= s.every_s);
            let mut made = false;
            let mut ctx = self.sampler.as_mut().map(|sampler| LocalSampling {
                sampler,
                index: &mut self.index,
                adjacency: &self.adjacency,
                scratch: &mut self.local,
                tools: &self.tools,
                step: self.steps,
            });
            let mut make = |lc: &mut LocalContact| {
                let ok = match (&mut ctx, spec) {
                    (Some(ctx), Some(spec)) => ctx.sample(&*sim, spec, lc),
                    _ => false,
                };
                made |= ok;
                ok
            };
            let wanted = due && self.law == ContactLaw::Penalty;
            k.update(
                sim.model(),
                &self.field,
                self.stiffness_n_per_m.len(),
                since_s,
                wanted.then_some(&mut make as &mut dyn FnMut(&mut LocalContact) -> bool),
            );
            if made {
                self.local.since_s = 0.0;
            }
            for (i, out) in self.stiffness_n_per_m.iter_mut().enumerate() {
                *out = k.stiffness(i);
            }
        }
    }

    /// Where the contact stiffness is computed (see [`StiffnessSolves`];
    /// the default is a worker thread, its newest result published).
    pub fn set_stiffness_solves(&mut self, mode: StiffnessSolves) {
        if let Some(k) = &mut self.stiffness {
            k.set_solves(mode);
        }
    }

    /// Where the contact stiffness is being computed now (`None`: no
    /// penalty contact, no stiffness).
    pub fn stiffness_solves(&self) -> Option<StiffnessSolves> {
        self.stiffness.as_ref().map(ContactStiffness::solves)
    }

    /// Penalty contact: how many steps replayed the last selection of
    /// contact points and how many selected afresh (see
    /// `contact::selection`); `None` under the projection law.
    pub fn point_selections(&self) -> Option<(u64, u64)> {
        self.sampler.as_ref().map(Sampler::selection_counts)
    }

    /// Penalty contact: whether a selection of contact points may serve
    /// the next steps while nothing moved far enough to change it (the
    /// default; off, every step selects afresh, to check that it is the
    /// same).
    pub fn set_point_reuse(&mut self, reuse: bool) {
        if let Some(s) = &mut self.sampler {
            s.set_reuse(reuse);
        }
    }

    /// No tool ever imposes nor releases `v` (a vertex the scene fixes or
    /// prescribes).
    pub fn reserve(&mut self, v: VertexId) {
        self.claims.reserve(v);
    }

    /// Number of tools.
    pub fn len(&self) -> usize {
        self.tools.len()
    }

    /// Whether the scene has no tool.
    pub fn is_empty(&self) -> bool {
        self.tools.is_empty()
    }

    /// Tool `i`.
    pub fn tool(&self, i: usize) -> &ToolContact {
        &self.tools[i]
    }

    /// The tools in declaration order.
    pub fn iter(&self) -> impl Iterator<Item = &ToolContact> {
        self.tools.iter()
    }

    /// The tool holding `v` after the last update, if any.
    pub fn owner(&self, v: VertexId) -> Option<usize> {
        self.claims.owner(v)
    }

    /// The surface index the tools query (under the penalty law as of the
    /// last fresh selection of points, not necessarily this step).
    pub fn surface_index(&self) -> &SurfaceIndex {
        &self.index
    }

    /// Detects contact, cuts, and imposes the contact vertices for the
    /// coming step; `inputs[i]` places tool `i` (`None` or missing: the tool
    /// is withdrawn and lets go). Call once before each `sim.step()`.
    /// Returns one report per tool.
    pub fn update<B: Backend + ?Sized>(
        &mut self,
        sim: &mut B,
        inputs: &[Option<ToolInput>],
    ) -> &[ContactReport] {
        if self.tools.is_empty() {
            return &self.reports;
        }
        // A pose with a non-finite field never reaches the contact code:
        // the tool keeps its last finite one.
        for (i, last) in self.last_inputs.iter_mut().enumerate() {
            *last = match inputs.get(i).copied().flatten() {
                Some(p) if p.tip_m.is_finite() && p.jaw_opening.is_finite() => Some(p),
                Some(_) => *last,
                None => None,
            };
        }
        let last_inputs = &self.last_inputs;
        let input = |i: usize| last_inputs[i];
        self.claims.clear();
        for (i, t) in self.tools.iter_mut().enumerate() {
            t.begin(
                sim,
                &self.adjacency,
                input(i).map(|p| (p.tip_m, p.jaw_opening)),
            );
        }
        if let Some(follow) = &mut self.follow {
            let tools = &self.tools;
            follow.follow(sim, tools.iter().map(|t| t.pose().map(|p| p.end_m)));
        }
        // After the cuts: the index follows them, and the new positions
        // where a query comes (the projection law's detection; the
        // penalty law refits only to select its points afresh, which most
        // steps do not).
        if self.law == ContactLaw::Projection {
            self.index.refit(sim);
        } else {
            self.index.sync(sim);
            if let Some(crossing) = &mut self.crossing {
                let spacing = crossing.spacing_of_radius();
                let mut refitted = false;
                for (i, t) in self.tools.iter_mut().enumerate() {
                    let deepest_m = self.field.deepest_tip_m(i);
                    let touching = deepest_m > 0.0;
                    t.note_catching_up(sim.dt_s());
                    let approach = t.approach_due();
                    let check = t.surface_check_due(deepest_m, spacing);
                    if (check || (approach && !touching)) && !refitted {
                        // The tips are tested against the current surface.
                        self.index.refit(sim);
                        refitted = true;
                    }
                    if approach {
                        let out_n = touching.then(|| self.field.force_n(i));
                        t.approach(sim, &self.index, &self.adjacency, crossing, out_n);
                    }
                    // After the approach: its slower step may not reach the
                    // surface any more.
                    if t.surface_check_due(deepest_m, spacing) {
                        t.keep_outside(sim, &self.index, &self.adjacency, crossing);
                    }
                }
            }
        }
        for t in &mut self.tools {
            t.hold(sim, &mut self.claims);
        }
        for t in &mut self.tools {
            t.detect(sim, &self.index, &self.adjacency, &mut self.claims);
        }
        self.field.clear();
        if let Some(sampler) = &mut self.sampler {
            for t in &self.tools {
                for sweep in t.sweeps().into_iter().flatten() {
                    self.field.add_part(sweep);
                }
            }
            sampler.select(sim, &mut self.index, &self.adjacency, &mut self.field);
            // Implicit springs do not bound the step.
            let omega2 = if self.field.implicit_springs() {
                0.0
            } else {
                springs_omega2(
                    &self.field,
                    &mut self.spring_n_per_m,
                    &mut self.sprung,
                    sim.model(),
                )
            };
            sim.set_contact_bound(omega2);
        }
        for (i, t) in self.tools.iter_mut().enumerate() {
            let jaw = input(i).map_or(1.0, |p| p.jaw_opening);
            self.reports[i] = t.commit(sim, &self.claims, jaw);
        }
        &self.reports
    }

    /// The corotational region round the tips: per tetrahedron whether it
    /// is in it now, and times it changed (`None`: the scene asks for none).
    pub fn corotational_region(&self) -> Option<(&[bool], u64)> {
        self.follow.as_ref().map(|f| f.state())
    }

    /// What the corotational region that follows the tools did so far
    /// (`None` without `corotational_radius_m`).
    pub fn corotational_region_stats(&self) -> Option<crate::contact::RegionStats> {
        self.follow.as_ref().map(|f| f.stats())
    }

    /// The force on tool `i` and its contact stiffness after the step.
    pub fn reaction<B: Backend + ?Sized>(&self, i: usize, sim: &B) -> Reaction {
        self.tools[i].reaction(sim, &self.adjacency, &self.field, self.stiffness_n_per_m[i])
    }
}

mod carry;
mod local_problems;
mod setup;
