//! Backward Euler on the same tensors (beyond the paper): unconditionally
//! stable, for stiff materials (nu near 0.5, a stiff capsule) and steps far
//! above the explicit bound, at the price of a linear solve per step.
//!
//! (M + h C + h^2 K) v' = M v + h (f - K u),  u' = u + h v'
//!
//! solved for the new velocities v' by preconditioned conjugate gradients,
//! warm-started from the previous velocities. Fixed and prescribed vertices
//! are Dirichlet rows: their v' = (target - u) / h, and the solve runs on the
//! free ones. The default preconditioner is a sparse Cholesky factor of A
//! for the held set of the step it was built in ([`factor`]): exact while
//! that set holds (one or two iterations, whatever the step or Poisson
//! ratio), close when tools hold or release a few vertices or cuts change K
//! (a few more iterations: each held or released vertex is a rank-3 change),
//! and rebuilt once the iterations spent beyond one per step since it was
//! built pass [`REFACTOR_BUDGET`], about what a factorisation costs.
//! The Jacobi preconditioner (diagonal of A) needs no factor, for meshes
//! too large to factorise, at hundreds of iterations at nu 0.45.
//!
//! Rebuilds run off the stepping thread ([`rebuild`], unless
//! [`ImplicitConfig::background_rebuild`] is off): the step that finds the
//! budget spent copies the tensors and the held set into a buffer it owns
//! and posts it to the backend's worker thread, which factorises while the
//! steps go on with the old factor; the first step after the worker is done
//! swaps the new factor in (the old one goes to the worker to be freed).
//! Only the first factor, when there is no old one, is built inline in the
//! first step. The buffers are reused, so a step allocates nothing once
//! running, a background swap included; with inline rebuilds, a step that
//! refactorises allocates.
//!
//! A real-time loop bounds the step ([`ImplicitConfig::step_iterations`]):
//! with a factor, a step stops after that many iterations even if the
//! residual is still above the tolerance, and posts a rebuild to the worker
//! at once (the factor has shown itself stale; while one is in flight, the
//! first capped step after its swap does). A grip holds some fifty vertices at
//! once, a rank-150 change the old factor answers in 15-16 iterations,
//! each a sparse solve; bounded, those steps cost what a step with a fresh
//! factor costs, and their solution is the best the budget reaches (CG
//! minimises the step's energy over the Krylov space, so it is a stable,
//! energy-reducing partial solve, not an extrapolation): the free rows near
//! the new holds lag by the remaining residual for the few steps until the
//! new factor is swapped in ([`Implicit::capped_steps`] counts them). This is
//! the fixed-iteration CG of real-time simulators (SOFA's `CGLinearSolver`
//! with its `iterations`), kept exact whenever the factor is current.
//!
//! A factor always belongs to the held set of its snapshot, whenever it
//! arrives: the preconditioner compares that set with the current one at
//! every use (rows held since get 0, rows released since the Jacobi step),
//! so holds and releases while a rebuild is in flight cost iterations, not
//! correctness, and the budget, counted afresh from the swap, orders the
//! next rebuild if they cost too many. A cut while a rebuild is in flight is
//! treated the same way, as a cut after an inline rebuild always was: the
//! arriving factor is the inverse of a nearby SPD matrix (K before the cut),
//! still a valid preconditioner, and no staler about the cut than the factor
//! it replaces, which also predates it; so it is swapped in, not discarded.
//!
//! Cutting updates the same tensors as the explicit backend. A nonlinear
//! membrane (eq 29) is not linear in u and is refused; the linear one is in K.

mod config;
mod factor;
mod rebuild;

use super::{Backend, Capabilities};
use crate::ids::{TetId, VertexId};
use crate::math::{Real, Vec3};
use crate::membrane::MembraneModel;
use crate::tensor_mass::{CutChange, CutError, ElasticModel};
use factor::{Assembly, Factor};
use rebuild::{Rebuilder, Received};
use std::sync::Weak;

pub use config::{ImplicitConfig, ImplicitError, Preconditioner, REFACTOR_BUDGET};
pub use rebuild::RebuildGate;

/// The backward-Euler backend.
pub struct Implicit {
    model: ElasticModel,
    cfg: ImplicitConfig,
    u: Vec<[Real; 3]>,
    v: Vec<Vec3>,
    /// Fixed, prescribed or orphaned (a Dirichlet row).
    held: Vec<bool>,
    target: Vec<Vec3>,
    fext: Vec<Vec3>,
    // CG workspace, reused.
    scratch: Vec<Vec3>,
    force: Vec<Vec3>,
    b: Vec<Vec3>,
    r: Vec<Vec3>,
    z: Vec<Vec3>,
    p: Vec<Vec3>,
    ap: Vec<Vec3>,
    diag: Vec<Vec3>,
    factor: Option<Factor>,
    /// The background worker (Cholesky with `background_rebuild`).
    rebuilder: Option<Rebuilder>,
    /// Build (or post) the Cholesky factor before the next step.
    refactor: bool,
    /// Iterations beyond one per step since the factor was swapped in.
    excess_iterations: usize,
    /// Factors put to use so far.
    factor_builds: usize,
    /// Steps stopped by `step_iterations` above the tolerance.
    capped_steps: u64,
    /// Whether the last step was one of them.
    capped: bool,
    iterations: usize,
    residual: Real,
}

impl Implicit {
    /// Refuses nonlinear material models (the scene checks with this too).
    pub fn check_model(model: &ElasticModel) -> Result<(), crate::tensor_mass::LinearOnly> {
        model.require_linear(
            "implicit backend",
            "backward Euler on the stiffness K assembled once",
            |_| true,
        )
    }

    /// A backend over `model` at rest.
    pub fn new(model: ElasticModel, cfg: ImplicitConfig) -> Result<Self, ImplicitError> {
        if !(cfg.dt_s.is_finite() && cfg.dt_s > 0.0) {
            return Err(ImplicitError::BadDt(cfg.dt_s));
        }
        if model
            .membrane()
            .is_some_and(|m| m.model() == MembraneModel::Nonlinear)
        {
            return Err(ImplicitError::NonlinearMembrane);
        }
        Self::check_model(&model)?;
        let n = model.vertex_count();
        let z = vec![Vec3::ZERO; n];
        // No thread (rare) means inline rebuilds, as with the option off.
        let rebuilder = (cfg.preconditioner == Preconditioner::Cholesky && cfg.background_rebuild)
            .then(|| Rebuilder::new(&model, cfg.dt_s).ok())
            .flatten();
        Ok(Self {
            model,
            cfg,
            u: vec![[0.0; 3]; n],
            v: z.clone(),
            held: vec![false; n],
            target: z.clone(),
            fext: z.clone(),
            scratch: z.clone(),
            force: z.clone(),
            b: z.clone(),
            r: z.clone(),
            z: z.clone(),
            p: z.clone(),
            ap: z.clone(),
            diag: z,
            factor: None,
            rebuilder,
            refactor: cfg.preconditioner == Preconditioner::Cholesky,
            excess_iterations: 0,
            factor_builds: 0,
            capped_steps: 0,
            capped: false,
            iterations: 0,
            residual: 0.0,
        })
    }

    /// CG iterations of the last step.
    pub fn iterations(&self) -> usize {
        self.iterations
    }

    /// Steps so far that [`ImplicitConfig::step_iterations`] stopped with
    /// the residual still above the tolerance.
    pub fn capped_steps(&self) -> u64 {
        self.capped_steps
    }

    /// The iterations this step may take: the budget while a factor
    /// preconditions, else the limit.
    fn iteration_limit(&self) -> usize {
        match (&self.factor, self.cfg.step_iterations) {
            (Some(_), Some(k)) => k.max(1).min(self.cfg.max_iterations),
            _ => self.cfg.max_iterations,
        }
    }

    /// The preconditioner in use: `"cholesky"`, or `"jacobi"` when asked
    /// for or when no factor could be built.
    pub fn preconditioner(&self) -> &'static str {
        if self.factor.is_some() {
            "cholesky"
        } else {
            "jacobi"
        }
    }

    /// z = P r.
    fn precondition(&mut self) {
        match &mut self.factor {
            Some(f) => f.apply(&self.r, &self.held, &self.diag, &mut self.z),
            None => {
                for ((z, r), d) in self.z.iter_mut().zip(&self.r).zip(&self.diag) {
                    *z = *r / *d;
                }
            }
        }
    }

    /// Cholesky factors put to use so far: the first, built inline, and
    /// every rebuild once swapped in.
    pub fn factor_builds(&self) -> usize {
        self.factor_builds
    }

    /// A background rebuild has been posted and not yet swapped in.
    pub fn rebuild_in_flight(&self) -> bool {
        self.rebuilder.as_ref().is_some_and(Rebuilder::in_flight)
    }

    /// Blocks until the background rebuild in flight, if any, is done; the
    /// next step swaps it in. For tests and offline runs that want the
    /// background path reproducibly: never call it from a real-time loop,
    /// and never while the [`RebuildGate`] is closed (it would wait for ever).
    #[doc(hidden)]
    pub fn wait_for_rebuild(&self) {
        if let Some(r) = &self.rebuilder {
            r.wait();
        }
    }

    /// The worker's gate, for tests that need a rebuild to stay in flight
    /// (`None` without a worker).
    #[doc(hidden)]
    pub fn rebuild_gate(&self) -> Option<RebuildGate> {
        self.rebuilder.as_ref().map(Rebuilder::gate)
    }

    /// Upgrades while the worker thread runs (`None` without a worker), for
    /// tests that check it ends with the backend.
    #[doc(hidden)]
    pub fn rebuild_worker(&self) -> Option<Weak<()>> {
        self.rebuilder.as_ref().map(Rebuilder::alive)
    }

    /// Before a step: swaps in a factor the worker has finished, then builds
    /// or posts one if the last steps asked for it.
    fn update_factor(&mut self) {
        if let Some(rebuilder) = &mut self.rebuilder {
            match rebuilder.receive(&mut self.factor) {
                Some(Received::Swapped) => {
                    self.factor_builds += 1;
                    self.excess_iterations = 0;
                }
                Some(Received::Failed) => {
                    // As inline: Jacobi for good (the factor was retired).
                    self.cfg.preconditioner = Preconditioner::Jacobi;
                    self.refactor = false;
                }
                None => {}
            }
        }
        if !self.refactor {
            return;
        }
        if let (Some(rebuilder), Some(_)) = (&mut self.rebuilder, &self.factor) {
            // The old factor serves until the new one arrives. A busy lock
            // leaves `refactor` set: posted next step.
            if rebuilder.request(&self.model, &self.held) {
                self.refactor = false;
            }
            return;
        }
        // Inline: rebuilds without a worker, and the first factor.
        self.refactor = false;
        self.excess_iterations = 0;
        // A factor that cannot be built (memory) leaves the backend on
        // Jacobi for good rather than retrying every step.
        self.factor = Factor::new(&Assembly::of(&self.model), self.cfg.dt_s, &self.held).ok();
        if self.factor.is_some() {
            self.factor_builds += 1;
        } else {
            self.cfg.preconditioner = Preconditioner::Jacobi;
        }
    }

    /// Relative residual reached by the last step.
    pub fn residual(&self) -> Real {
        self.residual
    }

    /// Total kinetic plus elastic energy (J).
    pub fn energy_j(&mut self) -> Real {
        for (s, u) in self.scratch.iter_mut().zip(&self.u) {
            *s = Vec3::from_array(*u);
        }
        self.model.elastic_forces(&self.scratch, &mut self.force);
        let m = self.model.masses_kg();
        let elastic: Real = self
            .scratch
            .iter()
            .zip(&self.force)
            .map(|(u, f)| -0.5 * u.dot(*f))
            .sum();
        let kinetic: Real = self
            .v
            .iter()
            .zip(m)
            .map(|(v, m)| 0.5 * m * v.length_squared())
            .sum();
        elastic + kinetic
    }

    /// ap = A p = (M + h C) p + h^2 K p on the free rows, 0 on held ones.
    fn apply(&mut self) {
        let h = self.cfg.dt_s;
        let (x, out) = (&self.p, &mut self.ap);
        self.model.elastic_forces(x, &mut self.force);
        let (m, c) = (self.model.masses_kg(), self.model.damping_kg_s());
        for i in 0..x.len() {
            out[i] = if self.held[i] {
                Vec3::ZERO
            } else {
                (m[i] + h * c[i]) * x[i] - h * h * self.force[i]
            };
        }
    }
}

fn dot(a: &[Vec3], b: &[Vec3]) -> Real {
    a.iter().zip(b).map(|(x, y)| x.dot(*y)).sum()
}

impl Backend for Implicit {
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            stable_at_any_step: true,
            ..Capabilities::dynamic("implicit")
        }
    }
    fn model(&self) -> &ElasticModel {
        &self.model
    }
    fn dt_s(&self) -> Real {
        self.cfg.dt_s
    }
    fn linear_solve(&self) -> Option<super::SolveReport> {
        Some(super::SolveReport {
            iterations: self.iterations,
            capped: self.capped,
        })
    }

    fn step(&mut self) {
        let h = self.cfg.dt_s;
        let n = self.u.len();
        self.update_factor();
        let (m, c) = (self.model.masses_kg(), self.model.damping_kg_s());
        // b = M v + h (f - K u); held rows carry their known velocity.
        for (s, u) in self.scratch.iter_mut().zip(&self.u) {
            *s = Vec3::from_array(*u);
        }
        self.model.elastic_forces(&self.scratch, &mut self.force);
        let vk = self.model.vertex_tensors();
        for i in 0..n {
            self.diag[i] = Vec3::splat(m[i] + h * c[i])
                + h * h * Vec3::new(vk[i].x_axis.x, vk[i].y_axis.y, vk[i].z_axis.z);
            if self.held[i] {
                self.p[i] = (self.target[i] - self.scratch[i]) / h;
                // Not part of the system: kept out of |b| (the stopping test).
                self.b[i] = Vec3::ZERO;
            } else {
                self.b[i] = m[i] * self.v[i] + h * (self.fext[i] + self.force[i]);
                // Warm start from the previous velocity.
                self.p[i] = self.v[i];
            }
        }
        // The held rows' known velocities enter the free rows' right side:
        // r = b - A x with x = (free: guess, held: known), A's full rows.
        self.model.elastic_forces(&self.p, &mut self.force);
        for i in 0..n {
            self.v[i] = self.p[i];
            self.r[i] = if self.held[i] {
                Vec3::ZERO
            } else {
                self.b[i] - ((m[i] + h * c[i]) * self.p[i] - h * h * self.force[i])
            };
        }
        // The residual is relative to the larger of |b| and the first
        // residual: a hold that starts moving tissue at rest has b = 0 (no
        // velocity, no force) and its whole right side in the held rows'
        // known velocities, which reach the free rows through r only;
        // relative to |b| alone that step iterated until the residual was
        // exactly zero or the iteration limit (38 iterations on the demo's
        // first grip, where 1 to 4 is usual).
        let norm_r0 = dot(&self.r, &self.r).sqrt();
        let norm_b = dot(&self.b, &self.b).sqrt().max(norm_r0).max(1e-300);
        let mut rz = 0.0;
        let mut iterations = 0;
        let mut residual = norm_r0 / norm_b;
        let limit = self.iteration_limit();
        while residual > self.cfg.tolerance && iterations < limit {
            if iterations == 0 {
                // The first direction, only in a step that needs one: tissue
                // at rest, or a warm start already within the tolerance,
                // needs no solve (about half the demo's steps, where the
                // solve, ~1 ms on the liver, is most of a step's cost).
                self.precondition();
                self.p.copy_from_slice(&self.z);
                rz = dot(&self.r, &self.z);
            }
            self.apply();
            let pap = dot(&self.p, &self.ap);
            // A non-positive curvature means round-off has taken over.
            if pap.is_nan() || pap <= 0.0 {
                break;
            }
            let alpha = rz / pap;
            for i in 0..n {
                self.v[i] += alpha * self.p[i];
                self.r[i] -= alpha * self.ap[i];
            }
            iterations += 1;
            residual = dot(&self.r, &self.r).sqrt() / norm_b;
            if residual <= self.cfg.tolerance || iterations == limit {
                // Done: the next direction (a preconditioner solve) is not needed.
                break;
            }
            self.precondition();
            let rz_new = dot(&self.r, &self.z);
            let beta = rz_new / rz;
            rz = rz_new;
            for i in 0..n {
                self.p[i] = self.z[i] + beta * self.p[i];
            }
        }
        self.iterations = iterations;
        self.residual = residual;
        let capped =
            residual > self.cfg.tolerance && iterations == limit && limit < self.cfg.max_iterations;
        self.capped = capped;
        if capped {
            self.capped_steps += 1;
        }
        if self.cfg.preconditioner == Preconditioner::Cholesky {
            self.excess_iterations += iterations.saturating_sub(1);
            // Not again while one is in flight: its swap resets the count.
            // A capped step orders the rebuild at once: from the worker, or
            // inline where inline rebuilds were asked for; but a worker that
            // could not be started leaves the excess rule alone to decide
            // (not a factorisation in a real-time loop after every grip).
            let stale = capped && (self.rebuilder.is_some() || !self.cfg.background_rebuild);
            self.refactor =
                (stale || self.excess_iterations > REFACTOR_BUDGET) && !self.rebuild_in_flight();
        }
        for i in 0..n {
            if self.held[i] {
                self.u[i] = self.target[i].to_array();
            } else {
                self.u[i] = (Vec3::from_array(self.u[i]) + h * self.v[i]).to_array();
            }
        }
    }

    fn displacement(&self, v: VertexId) -> Vec3 {
        Vec3::from_array(self.u[v.idx()])
    }
    fn displacements(&self) -> &[[Real; 3]] {
        &self.u
    }
    fn prescribe(&mut self, v: VertexId, d_m: Vec3) {
        self.held[v.idx()] = true;
        self.target[v.idx()] = d_m;
    }
    fn release(&mut self, v: VertexId) {
        self.held[v.idx()] = false;
    }
    fn set_external_force(&mut self, v: VertexId, f_n: Vec3) {
        self.fext[v.idx()] = f_n;
    }
    fn remove_tet(&mut self, t: TetId) -> Result<CutChange, CutError> {
        let change = self.model.remove_tet(t)?;
        for v in change.vertices {
            if self.model.topology().vertex_tet_count(v) == 0 {
                // An orphan has no mass left: hold it where it is.
                self.held[v.idx()] = true;
                self.target[v.idx()] = Vec3::from_array(self.u[v.idx()]);
                self.v[v.idx()] = Vec3::ZERO;
            }
        }
        Ok(change)
    }
}
