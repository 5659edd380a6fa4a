//! Explicit central differences with lumped mass and damping (paper 3.4.1):
//! (m/dt^2 + c/(2dt)) U(t+1) = F + (2m/dt^2) U(t) - (m/dt^2 - c/(2dt)) U(t-1),
//! with fixed and prescribed vertices, external forces, cutting, and a time
//! step checked against the stability bound (refused, or split into sub-steps).

use super::force_term::{ForceTerm, NoForce, SubStep};
use super::huge_pages::huge_vec;
use super::kernel::{Kernel, Part, StepInputs, Storage, V3, kind};
use super::large_strain::LargeStrain;
use super::model::ElasticModel;
use super::stability::StableStep;
use crate::math::Real;
use multirate::Multirate;
pub use multirate::MultirateReport;
use partition::{PartBuffers, PartPlan, run_parts};
use predicted::Prediction;
pub use step_size::{DtPolicy, ExplicitConfig, ExplicitError, MultirateError, substeps_for};
pub use step_size::{
    MAX_SUBSTEPS, MAX_THREADS, PREDICTED_FINE_SUBSTEPS_MAX, PREDICTED_SUBSTEPS_MAX,
};

/// What a kernel pass reads ([`StepInputs`]) and, borrowed apart from it,
/// what it writes.
struct Pass<'a, S: Storage> {
    inputs: StepInputs<'a>,
    kernel: &'a Kernel<S>,
    next: &'a mut [V3],
    plans: &'a [PartPlan],
    buffers: &'a mut [PartBuffers],
    pool: Option<&'a rayon::ThreadPool>,
    ku_ahead: &'a mut [V3],
}

/// The thread parts of a kernel pass: how the vertices are split, each
/// part's buffers, and the pool that runs them (`None`: one thread).
struct Parts {
    threads: usize,
    plans: Vec<PartPlan>,
    buffers: Vec<PartBuffers>,
    pool: Option<rayon::ThreadPool>,
}

/// The step size and its sub-steps, with the bounds they follow.
struct StepSize {
    /// The contact springs' share of omega_max^2 ([`Explicit::set_contact_bound`]).
    contact_omega2: Real,
    /// The nonlinear elements' tangent bound the sub-steps follow: the
    /// largest recent one, decaying by [`step_size::TANGENT_DECAY_PER_STEP`].
    tangent_lambda: Real,
    stable: StableStep,
    /// The bound of the elastic model alone (before contact springs).
    elastic_stable: StableStep,
    policy: DtPolicy,
    dt_s: Real,
    substeps: usize,
    /// Sub-steps of the slow vertices with multirate stepping engaged
    /// (`substeps` is then a whole multiple of it; see `multirate.rs`).
    coarse_substeps: usize,
    /// Sub-steps the elastic model alone needs.
    elastic_substeps: usize,
    /// Every step's sub-steps are multiplied by this
    /// ([`Explicit::set_substep_factor`]).
    substep_factor: usize,
    /// Times the sub-step count changed.
    resubsteps: u64,
}

/// What is computed ahead of the next step while the loop waits for a pose.
struct Ahead {
    /// K U(t) of the next step's first sub-step, computed by
    /// [`Explicit::prepare_step`] (valid while `ku_ready`).
    ku_ahead: Vec<V3>,
    ku_ready: bool,
    /// The whole next step computed without the tools, where every row is
    /// the linear kernel's (see `tensor_mass/explicit/predicted/`).
    prediction: Prediction,
    /// Steps finished from a prediction.
    predicted_steps: u64,
    /// The contact field's re-selection period of the last contact step
    /// (a prediction is not made for steps it would split).
    resample_every_s: Option<Real>,
}

/// The explicit tensor-mass simulation, generic over the kernel's storage precision.
pub struct Explicit<S: Storage> {
    model: ElasticModel,
    kernel: Kernel<S>,
    u: Vec<V3>,
    next: Vec<V3>,
    coef: Vec<V3>,
    constraint: Vec<u8>,
    kind: Vec<u8>,
    target: Vec<V3>,
    fext: Vec<V3>,
    /// Nonlinear membrane forces, and the vertices they touch (empty without
    /// a nonlinear membrane: a scene without one pays nothing).
    fmem: Vec<V3>,
    capsule_vertices: Vec<u32>,
    /// Nonlinear elements and their force corrections, or whole forces
    /// when every element is nonlinear (none and empty in a linear scene).
    large: Option<LargeStrain>,
    fnl: Vec<V3>,
    /// The thread parts of a pass.
    parts: Parts,
    /// The step, its sub-steps and the bounds they follow.
    size: StepSize,
    steps: u64,
    /// What is computed ahead of the next step while the loop waits.
    ahead: Ahead,
    /// The fast and slow vertices of multirate stepping (`None`: off).
    multirate: Option<Multirate>,
}

impl<S: Storage> Explicit<S> {
    /// Recomputes the integration coefficients and kind of vertex `v`.
    fn refresh_vertex(&mut self, v: usize) {
        let h = self.size.dt_s / self.own_substeps(v) as Real;
        let m = self.model.masses_kg()[v];
        let c = self.model.damping_kg_s()[v];
        if m > 0.0 {
            let mh = m / (h * h);
            let ch = c / (2.0 * h);
            let den = mh + ch;
            self.coef[v] = [1.0 / den, 2.0 * mh / den, (mh - ch) / den];
            self.kind[v] = self.constraint[v];
        } else {
            self.coef[v] = [0.0; 3];
            self.kind[v] = kind::INACTIVE;
        }
    }

    /// Advances by `dt_s` (in `substeps()` equal sub-steps).
    pub fn step(&mut self) {
        self.finish_step();
        if self.ahead.prediction.ready(self.size.substeps) {
            self.finish_predicted(None::<&mut NoForce>);
            return;
        }
        let mut k = 0;
        while k < self.size.substeps {
            let fine = self.begin_substep(k);
            self.membrane_step();
            k *= self.large_strain_pass();
            self.end_substep(fine);
            k += 1;
        }
        self.steps += 1;
        self.follow_tangent();
    }

    /// Sub-step `k` of a step: whether it is a fine one (the fast rows
    /// alone, with the slow neighbours interpolated; see `multirate.rs`)
    /// or a whole pass.
    fn begin_substep(&mut self, k: usize) -> bool {
        let m = self.fine_per_coarse();
        let fine = m > 1 && !k.is_multiple_of(m);
        if fine {
            self.interpolate_interface((k % m) as Real / m as Real);
        }
        fine
    }

    /// Finishes the sub-step [`Explicit::begin_substep`] began.
    fn end_substep(&mut self, fine: bool) {
        if fine {
            self.fast_rows();
        } else {
            self.kernel_step();
        }
    }

    /// The nonlinear elements' forces at the current state, and the step
    /// made finer at once when their tangent needs it (see
    /// [`Explicit::refine_mid_step`]) before the state is advanced with
    /// them. Returns the refinement factor (1: none).
    fn large_strain_pass(&mut self) -> usize {
        let Some(large) = &mut self.large else {
            return 1;
        };
        let u = &self.u;
        let fnl = &mut self.fnl;
        match &self.parts.pool {
            Some(pool) => pool.install(|| large.pass(u, fnl, self.parts.threads)),
            None => large.pass(u, fnl, 1),
        }
        self.refine_mid_step()
    }

    /// When the nonlinear elements' tangent at the current state needs more
    /// sub-steps than this step uses (a prescribed jump, a sudden stretch),
    /// the rest of the step is split finer at once, by a whole factor so
    /// that it still ends at dt: the sub-step about to be taken already
    /// uses the finer one (one sub-step at the coarse one was enough to
    /// fling a vertex 12 cm after a 3 cm jump). Returns the factor (1:
    /// unchanged).
    fn refine_mid_step(&mut self) -> usize {
        let Some(large) = &self.large else {
            return 1;
        };
        let now = large.last().lambda;
        if !now.is_finite() {
            return 1;
        }
        let needed = self.needed_substeps(now);
        if needed <= self.size.substeps {
            return 1;
        }
        let factor = needed
            .div_ceil(self.size.substeps)
            .min(MAX_SUBSTEPS / self.size.substeps)
            .max(1);
        self.size.tangent_lambda = self.size.tangent_lambda.max(now);
        self.resubstep(self.size.substeps * factor);
        factor
    }

    /// Advances by `dt_s` with the penalty contact `field` evaluated at
    /// every sub-step (the tools swept across the step), its forces added
    /// to the elastic ones; `resample` selects the field's points again
    /// every `resample_every_s` of simulated time within the step. The
    /// first contact allocates one force array.
    pub fn step_with_contact<F: ForceTerm, R: FnMut(&Self, &mut F)>(
        &mut self,
        field: &mut F,
        resample_every_s: Real,
        resample: &mut R,
    ) {
        self.finish_step();
        if field.is_idle() {
            self.step();
            return;
        }
        self.multirate_cover(field);
        if self.fmem.len() != self.u.len() {
            self.fmem = huge_vec(self.u.len(), [0.0; 3]);
        }
        let mut h = self.size.dt_s / self.size.substeps as Real;
        let mut every = ((resample_every_s / h).floor() as usize).max(1);
        self.ahead.resample_every_s = Some(resample_every_s);
        if self.ahead.prediction.ready(self.size.substeps) {
            // The prediction cannot re-select points inside the step.
            if every >= self.size.substeps {
                self.finish_predicted(Some(field));
                return;
            }
            self.forget_prepared();
        }
        let mut k = 0;
        while k < self.size.substeps {
            if k > 0 && k % every == 0 {
                resample(self, field);
            }
            let fine = self.begin_substep(k);
            let factor = self.large_strain_pass();
            if factor > 1 {
                k *= factor;
                h = self.size.dt_s / self.size.substeps as Real;
                every = ((resample_every_s / h).floor() as usize).max(1);
            }
            // Before the membrane (which zeroes and writes its own vertices).
            field.zero(&mut self.fmem);
            self.membrane_step();
            let s = (k + 1) as Real / self.size.substeps as Real;
            let rest = self.model.mesh().positions_m();
            let at = SubStep {
                h_s: h,
                step_s: self.size.dt_s,
                s,
                masses_kg: self.model.masses_kg(),
            };
            field.add_forces(rest, &self.u, &self.next, at, &mut self.fmem);
            self.end_substep(fine);
            if field.implicit_springs() {
                // After the swap: `u` is the explicit prediction, `next`
                // the sub-step's start.
                let (coef, kind) = (&self.coef, &self.kind);
                let inverse_d = |i: usize| (kind[i] == kind::FREE).then(|| coef[i][0]);
                field.correct_implicit(inverse_d, &self.next, &mut self.u);
            }
            k += 1;
        }
        self.steps += 1;
        self.follow_tangent();
    }

    /// The nonlinear elements (none in a linear scene): their last pass's
    /// tangent bound and collapsed StVK elements.
    pub fn large_strain(&self) -> Option<&LargeStrain> {
        self.large.as_ref()
    }

    /// How many times the sub-step count changed (contact springs coming
    /// and going).
    pub fn resubsteps(&self) -> u64 {
        self.size.resubsteps
    }

    /// How many steps were finished from the prediction
    /// [`Explicit::prepare_step`] made (the rest ran in full).
    pub fn predicted_steps(&self) -> u64 {
        self.ahead.predicted_steps
    }

    /// Rows the predicted steps recomputed, summed over their sub-steps
    /// (against `predicted_steps() * substeps() * vertex count` for full
    /// passes): how local the correction was.
    pub fn predicted_rows(&self) -> u64 {
        self.ahead.prediction.rows_total()
    }

    /// Predicted steps whose correction found its rows kept from the step
    /// before (the same first rows: the tools' contact points unchanged).
    pub fn predicted_steps_reusing_rows(&self) -> u64 {
        self.ahead.prediction.reused_total()
    }

    fn membrane_step(&mut self) {
        if !self.capsule_vertices.is_empty() {
            for &v in &self.capsule_vertices {
                self.fmem[v as usize] = [0.0; 3];
            }
            self.model.membrane_forces(&self.u, &mut self.fmem);
        }
    }

    /// Computes now what the next step can before its tools are known, so
    /// that a server loop spends its wait for the next pose on it and
    /// answers the pose sooner. Where every row's force is the linear
    /// kernel's (no nonlinear elements or membrane; multirate or not): the whole step without
    /// the tools, which the step then finishes by recomputing only the rows
    /// the tools' forces, prescribed vertices and changed loads reach, one
    /// ring of neighbours a sub-step (`tensor_mass/explicit/predicted/`). Otherwise: the
    /// first sub-step's K U (the kernel's deferred-row path). Either way
    /// the step's result is identical to the bit (tests). One part only
    /// (with worker threads it does nothing); a cut before the step has
    /// its element's rows recomputed (and discards a K U ahead); a new
    /// sub-step count, cleared loads or [`Explicit::set_state`] discard it.
    /// The first call allocates its arrays.
    pub fn prepare_step(&mut self) {
        self.finish_step();
        if self.parts.plans.len() != 1 || self.ahead.ku_ready {
            return;
        }
        // A whole step ahead where the correction can use it: linear rows,
        // few sub-steps (an array each), and no re-selection of contact
        // points inside the step (the last contact step's period says).
        let h = self.size.dt_s / self.size.substeps as Real;
        let resamples = self
            .ahead
            .resample_every_s
            .is_some_and(|r| ((r / h).floor() as usize).max(1) < self.size.substeps);
        if self.large.is_none()
            && self.capsule_vertices.is_empty()
            && self.kernel.is_elastic()
            && self.size.substeps / self.fine_per_coarse() <= PREDICTED_SUBSTEPS_MAX
            && self.size.substeps <= PREDICTED_FINE_SUBSTEPS_MAX
            && !resamples
        {
            self.predict();
            return;
        }
        let n = self.u.len();
        if self.ahead.ku_ahead.len() != n {
            self.ahead.ku_ahead = huge_vec(n, [0.0; 3]);
        }
        let pass = self.pass();
        let b = &mut pass.buffers[0];
        // Every row deferred: K U lands in `ku_ahead`, nothing is integrated
        // and `next` is not written.
        pass.kernel.run_part(
            &pass.inputs,
            Part {
                start: 0,
                end: n,
                deferred_end: n,
                ring: &mut b.ring,
                deferred: pass.ku_ahead,
                next: pass.next,
                spill: &mut b.spill,
            },
        );
        self.ahead.ku_ready = true;
    }

    /// Drops what [`Explicit::prepare_step`] computed (the state or the
    /// model changed under it).
    fn forget_prepared(&mut self) {
        self.finish_step();
        self.ahead.ku_ready = false;
        self.ahead.prediction.forget();
    }

    /// The step's inputs, borrowed beside what a kernel pass writes.
    fn pass(&mut self) -> Pass<'_, S> {
        let Self {
            kernel,
            u,
            next,
            coef,
            kind,
            target,
            fext,
            fmem,
            fnl,
            parts:
                Parts {
                    plans,
                    buffers,
                    pool,
                    ..
                },
            ahead: Ahead { ku_ahead, .. },
            ..
        } = self;
        Pass {
            inputs: StepInputs {
                u,
                coef,
                kind,
                target,
                fext,
                fmem,
                fnl,
            },
            kernel,
            next,
            plans,
            buffers,
            pool: pool.as_ref(),
            ku_ahead,
        }
    }

    fn kernel_step(&mut self) {
        let ahead = std::mem::take(&mut self.ahead.ku_ready);
        let Pass {
            inputs,
            kernel,
            next,
            plans,
            buffers,
            pool,
            ku_ahead,
        } = self.pass();
        if ahead {
            // K U was computed by `prepare_step`: only integrate.
            for (i, (ku, next)) in ku_ahead.iter().zip(next.iter_mut()).enumerate() {
                inputs.integrate(i, *ku, next);
            }
        } else {
            let mut run = || run_parts(kernel, &inputs, plans, 0, next, buffers);
            match pool {
                Some(pool) => pool.install(run),
                None => run(),
            }
            if plans.len() > 1 {
                // Rows reached across a part boundary: add the spills to
                // their deferred K U, then finish them.
                for p in 0..plans.len() {
                    let (before, after) = buffers.split_at_mut(p + 1);
                    let mut q = 0;
                    for (r, s) in before[p].spill.iter_mut().enumerate() {
                        let row = plans[p].end + r;
                        while plans[p + 1 + q].end <= row {
                            q += 1;
                        }
                        let d = &mut after[q].deferred[row - plans[p + 1 + q].start];
                        for k in 0..3 {
                            d[k] += s[k];
                        }
                        *s = [0.0; 3];
                    }
                }
                for (plan, buf) in plans.iter().zip(buffers.iter_mut()).skip(1) {
                    for (i, d) in (plan.start..plan.deferred_end).zip(buf.deferred.iter_mut()) {
                        inputs.integrate(i, *d, &mut next[i]);
                        *d = [0.0; 3];
                    }
                }
            }
        }
        std::mem::swap(&mut self.u, &mut self.next);
    }
}

mod inputs;
mod multirate;
mod partition;
pub(in crate::tensor_mass) mod predicted;
mod setup;
mod step_size;
