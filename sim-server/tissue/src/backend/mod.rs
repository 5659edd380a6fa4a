//! Simulation backends: what the simulation process and the tools drive.
//! The tensor-mass explicit integrator ([`crate::tensor_mass::Explicit`])
//! is one; [`Precomputed`] (Cotin's static responses), [`Hybrid`] (a
//! precomputed part joined to a cuttable tensor-mass part) and [`Implicit`]
//! (backward Euler, beyond the paper) the others. Tools,
//! contact and the reaction force work on any [`Backend`]; hot paths are
//! generic over it.
//!
//! ```
//! use tissue::backend::{Backend, Implicit, ImplicitConfig};
//! use tissue::prelude::*;
//! let mesh = BoxSpec::new(Vec3::new(0.04, 0.02, 0.02), CellSize::EdgeM(0.005)).generate().unwrap();
//! let tissue = Material::isotropic(5000.0, 0.45, 1000.0, 5.0).unwrap();
//! let model = ElasticModel::new(mesh.clone(), TetMaterials::uniform(tissue, mesh.tet_count())).unwrap();
//! // Ten times the explicit stability bound: fine for backward Euler.
//! let mut sim = Implicit::new(model, ImplicitConfig::new(0.005)).unwrap();
//! sim.fix(VertexId(0));
//! sim.set_external_force(VertexId(7), Vec3::new(0.0, 0.0, -0.01));
//! sim.step();
//! assert!(sim.displacement(VertexId(7)).z < 0.0);
//! ```

mod cache;
mod capabilities;
mod compliance;
mod explicit;
mod holds;
mod hybrid;
mod implicit;
mod precomputed;

pub use cache::{FNV_OFFSET, MAX_RESPONSE_BYTES, TooManyResponses, fnv};
pub use capabilities::Capabilities;
pub use compliance::Compliance;
pub use hybrid::{Hybrid, HybridConfig, HybridError};
pub use implicit::{Implicit, ImplicitConfig, ImplicitError, Preconditioner};
pub use precomputed::{Precomputed, PrecomputedError};

use crate::ids::{TetId, VertexId};
use crate::math::{Real, Vec3};
use crate::tensor_mass::{CutChange, CutError, ElasticModel, ForceTerm};

/// A deformable-body simulation the tools can act on.
pub trait Backend {
    /// What the backend can do (its name, dynamics, contact, regions).
    fn capabilities(&self) -> Capabilities;
    /// The model (mesh, topology, tensors).
    fn model(&self) -> &ElasticModel;
    /// Advances one step.
    fn step(&mut self);
    /// The step (s).
    fn dt_s(&self) -> Real;
    /// Displacement of `v` (m).
    fn displacement(&self, v: VertexId) -> Vec3;
    /// All displacements (m).
    fn displacements(&self) -> &[[Real; 3]];
    /// Velocity of `v` (m/s) at the end of the last step where the backend
    /// integrates in time (zero where it does not).
    fn velocity(&self, v: VertexId) -> Vec3 {
        let _ = v;
        Vec3::ZERO
    }
    /// Current position of `v` (m).
    fn position(&self, v: VertexId) -> Vec3 {
        self.model().mesh().positions_m()[v.idx()] + self.displacement(v)
    }
    /// Fixes `v` at rest.
    fn fix(&mut self, v: VertexId) {
        self.prescribe(v, Vec3::ZERO);
    }
    /// Imposes displacement `d_m` on `v` from the next step on.
    fn prescribe(&mut self, v: VertexId, d_m: Vec3);
    /// Frees `v`.
    fn release(&mut self, v: VertexId);
    /// Sets the external force on `v` (N).
    fn set_external_force(&mut self, v: VertexId, f_n: Vec3);
    /// Removes a tetrahedron (cutting); a backend that cannot cut refuses.
    fn remove_tet(&mut self, t: TetId) -> Result<CutChange, CutError>;
    /// Whether [`Backend::remove_tet`] would accept tetrahedron `t` (the
    /// cutting capability: everywhere for tensor-mass and implicit, nowhere
    /// for precomputed, in its tensor-mass part for the hybrid).
    fn can_cut(&self, t: TetId) -> bool {
        let _ = t;
        true
    }
    /// What the last step's large-strain pass found (StVK elements in the
    /// volume barrier, the tangent's bound), for a backend running
    /// nonlinear materials; `None` otherwise.
    fn large_strain(&self) -> Option<crate::tensor_mass::large_strain::PassReport> {
        None
    }
    /// The nonlinear elements' force at vertex `v` after the last step, for
    /// a backend running nonlinear materials (the reaction a tool feels
    /// adds it); `None` otherwise.
    fn nonlinear_force_n(
        &self,
        v: VertexId,
    ) -> Option<crate::tensor_mass::large_strain::VertexForce> {
        let _ = v;
        None
    }
    /// The last step's linear solve, for a backend that solves one per
    /// step (implicit); `None` otherwise.
    fn linear_solve(&self) -> Option<SolveReport> {
        None
    }
    /// Runs `f` once on each worker thread a step waits for (the explicit
    /// integrator's pool with `threads` above 1), and returns how many;
    /// none for a backend that steps on the calling thread alone. For the
    /// caller to give them its real-time priority: a step that hands its
    /// work to lower-priority threads and waits for them runs at their
    /// priority, preempted by anything above it. Cold: called at start.
    fn on_step_workers(&self, f: &(dyn Fn() + Sync)) -> usize {
        let _ = f;
        0
    }
    /// Does now what the next step can do before its tools are known (the
    /// explicit backend: the whole step without the tools on a linear
    /// model, finished locally once they are known; else the first
    /// sub-step's elastic forces), so that the step answers a pose sooner;
    /// the step's result is unchanged. A loop
    /// calls it while it waits for the next pose. Others: nothing.
    fn prepare_step(&mut self) {}
    /// Has each step leave what its force cannot depend on until
    /// [`Backend::finish_step`], so that a loop sends the force first (the
    /// explicit backend: the rows of a predicted step far from the tools).
    /// Reading the state before the step is finished sees those parts as
    /// predicted; stepping or changing anything finishes it first. Others:
    /// nothing.
    fn defer_far_rows(&mut self, on: bool) {
        let _ = on;
    }
    /// Finishes the step [`Backend::defer_far_rows`] left pending.
    fn finish_step(&mut self) {}
    /// Steps finished from a whole-step prediction ([`Backend::prepare_step`]),
    /// and the rows they recomputed (summed over sub-steps); `None` for
    /// backends that do not predict.
    fn predicted(&self) -> Option<(u64, u64)> {
        None
    }
    /// The multirate partition (`None`: the backend steps every vertex alike).
    fn multirate(&self) -> Option<crate::tensor_mass::MultirateReport> {
        None
    }
    /// Makes the linear tetrahedra flagged in `corotational` corotational
    /// (and the others linear) from the next step on: the region that
    /// follows the tools (the scene's `[contact] corotational_radius_m`).
    /// Nothing for a backend without [`Capabilities::corotational_region`],
    /// which the contact set-up refuses with the reason. Cold: called when
    /// the region changes.
    fn set_corotational_region(&mut self, corotational: &[bool]) {
        let _ = corotational;
    }
    /// Makes the coming steps stable with contact springs adding up to
    /// `omega2` (rad^2/s^2) to omega_max^2 (sub-stepping as needed).
    /// Backends that do not integrate contact ignore it.
    fn set_contact_bound(&mut self, omega2: Real) {
        let _ = omega2;
    }
    /// One step with the penalty contact `field`, calling `resample` to
    /// select its points again every `resample_every_s` of simulated time
    /// within the step; a backend that does not integrate contact steps
    /// without it. `resample` is generic, not `dyn`: it runs inside the
    /// step, in the hot path.
    fn step_with_contact<F: ForceTerm, R: FnMut(&Self, &mut F)>(
        &mut self,
        field: &mut F,
        resample_every_s: Real,
        resample: &mut R,
    ) where
        Self: Sized,
    {
        let _ = (field, resample_every_s, resample);
        self.step();
    }
}

/// What a step's linear solve did ([`Backend::linear_solve`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveReport {
    /// Iterations it took.
    pub iterations: usize,
    /// Whether a per-step iteration budget stopped it above its tolerance.
    pub capped: bool,
}

/// How much of the body `sim` can cut: (cuttable, live) tetrahedra.
pub fn cuttable<B: Backend + ?Sized>(sim: &B) -> (usize, usize) {
    let topo = sim.model().topology();
    (0..sim.model().mesh().tet_count())
        .map(TetId::from)
        .filter(|t| topo.is_alive(*t))
        .fold((0, 0), |(c, n), t| (c + sim.can_cut(t) as usize, n + 1))
}
