//! How big a step [`Explicit`] takes: the policy when the asked step is
//! above the stability bound (refuse, sub-step, unchecked), the bound
//! itself with the contact springs and the nonlinear tangent on top of the
//! elastic one, and the sub-step count that follows them (velocity kept
//! when it changes).

use super::Explicit;
use crate::math::Real;
use crate::tensor_mass::kernel::Storage;
use crate::tensor_mass::stability::{BoundMethod, StableStep};
use thiserror::Error;

/// What to do when the requested step exceeds the stable step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DtPolicy {
    /// Refuse with an error naming the bound.
    Refuse,
    /// Split each step into the fewest equal sub-steps under the bound.
    Substep,
    /// Step as asked even above the bound. For experiments and for systems
    /// whose constraints lower omega_max below the (constraint-free) bound;
    /// the caller must detect divergence.
    Unchecked,
}

/// Integrator settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExplicitConfig {
    /// The step the caller advances per [`Explicit::step`] (s).
    pub dt_s: Real,
    /// Refuse or sub-step when `dt_s` is above the bound.
    pub policy: DtPolicy,
    /// Which bound to enforce.
    pub bound: BoundMethod,
    /// Worker threads for the step (1 = the calling thread only).
    pub threads: usize,
}

impl ExplicitConfig {
    /// One thread, element bound, sub-stepping.
    pub fn new(dt_s: Real) -> Self {
        Self {
            dt_s,
            policy: DtPolicy::Substep,
            bound: BoundMethod::Element,
            threads: 1,
        }
    }
}

/// Why the integrator could not be set up.
#[derive(Debug, Error, PartialEq)]
pub enum ExplicitError {
    /// The step is not a positive finite number.
    #[error("dt_s must be a positive finite number, got {0}")]
    BadDt(Real),
    /// The step exceeds the stable step and the policy is to refuse.
    #[error(
        "dt_s = {dt_s:e} s exceeds the stable step {dt_max_s:e} s ({method} bound, omega_max = {omega_max_rad_s:.4e} rad/s); use dt_s <= {dt_max_s:e} s or sub-stepping"
    )]
    Unstable {
        /// Requested step.
        dt_s: Real,
        /// The bound.
        dt_max_s: Real,
        /// omega_max.
        omega_max_rad_s: Real,
        /// Bound method name.
        method: &'static str,
    },
    /// Sub-stepping the step would take more than [`MAX_SUBSTEPS`].
    #[error(
        "dt_s = {dt_s:e} s needs {needed:e} sub-steps under the stable step {dt_max_s:e} s, more than the {max} a step may take; use dt_s <= {limit:e} s",
        max = MAX_SUBSTEPS,
        limit = dt_max_s * MAX_SUBSTEPS as Real
    )]
    TooManySubsteps {
        /// Requested step.
        dt_s: Real,
        /// The bound.
        dt_max_s: Real,
        /// Sub-steps it would need.
        needed: Real,
    },
    /// Multirate stepping cannot partition this model.
    #[error(transparent)]
    Multirate(#[from] MultirateError),
    /// The thread pool could not be created.
    #[error("cannot start {threads} worker threads: {reason}")]
    Threads {
        /// Requested threads.
        threads: usize,
        /// The OS error.
        reason: String,
    },
}

/// Why multirate stepping cannot be set up.
#[derive(Debug, Error, PartialEq)]
pub enum MultirateError {
    /// The step is unchecked: there is no bound to partition by.
    #[error(
        "multirate stepping partitions the organ by its stable step; with dt_policy = \"unchecked\" there is none: use \"substep\""
    )]
    Unchecked,
    /// Every element's force is the nonlinear pass's (no linear rows to recompute alone).
    #[error(
        "multirate stepping recomputes the fast vertices' linear rows; every element of this scene is nonlinear, so there are none: use a linear material with a corotational region"
    )]
    WholeForces,
}

/// Sub-steps per step of `dt_s` under `stable` as `policy` says: 1 when
/// under the bound (or unchecked), the fewest equal sub-steps under it, or
/// the refusal naming the bound.
pub fn substeps_for(
    dt_s: Real,
    stable: &StableStep,
    policy: DtPolicy,
) -> Result<usize, ExplicitError> {
    if dt_s <= stable.dt_max_s || policy == DtPolicy::Unchecked {
        Ok(1)
    } else if policy == DtPolicy::Substep {
        let needed = (dt_s / stable.dt_max_s).ceil();
        // A step that needs more sub-steps than a diverging state may take
        // would never end (1e300 s asks for usize::MAX of them).
        if needed > MAX_SUBSTEPS as Real {
            return Err(ExplicitError::TooManySubsteps {
                dt_s,
                dt_max_s: stable.dt_max_s,
                needed,
            });
        }
        Ok(needed as usize)
    } else {
        Err(ExplicitError::Unstable {
            dt_s,
            dt_max_s: stable.dt_max_s,
            omega_max_rad_s: stable.omega_max_rad_s,
            method: stable.method.name(),
        })
    }
}

/// Worker threads a step may use at most.
pub const MAX_THREADS: usize = 256;

/// Sub-steps per step at most when contact springs or a stretched
/// nonlinear body raise the bound: a state that needs more is diverging,
/// and the caller's divergence check reports it (rather than a step that
/// never ends).
pub const MAX_SUBSTEPS: usize = 4096;

/// Whole passes (coarse sub-steps) at most for which
/// [`Explicit::prepare_step`] predicts the whole step; above, it computes
/// the first sub-step's K U. The correction after the pose grows one ring
/// of rows over the whole mesh a whole pass, so past this many it reaches
/// most of the mesh and costs the step again on top of the prediction
/// (a refined liver at 9 sub-steps a step dropped time); multirate's fine
/// sub-steps grow it only into the fast rows.
pub const PREDICTED_SUBSTEPS_MAX: usize = 8;

/// Sub-steps at most for which a multirate step is predicted (an array
/// each; its whole passes are bounded by [`PREDICTED_SUBSTEPS_MAX`]).
pub const PREDICTED_FINE_SUBSTEPS_MAX: usize = 32;

/// How fast the sub-steps a stretched nonlinear body needed are given back
/// once it eases (per step): each change of the count rescales U(t-1) to
/// keep the velocity, which is not symplectic, and an undamped StVK body
/// whose count toggled every few steps gained energy (2.8x in 3000 steps
/// at half the rest bound); held for ~100 steps it keeps it.
pub(super) const TANGENT_DECAY_PER_STEP: Real = 0.99;

impl<S: Storage> Explicit<S> {
    /// Makes the coming steps stable with contact springs adding up to
    /// `omega2` to omega_max^2 (Weyl: the bounds add), sub-stepping as
    /// needed whatever the policy (the springs are the simulation's own,
    /// not the user's step; `unchecked` adds none). Called every step with
    /// that step's springs, so a scene pays for them only in contact; when
    /// the sub-step count changes the velocity is kept (U(t-1) rescaled),
    /// an O(n) pass.
    pub fn set_contact_bound(&mut self, omega2: Real) {
        self.size.contact_omega2 = omega2.max(0.0);
        self.update_bound();
    }

    /// With nonlinear elements, sizes the next step's sub-steps from the
    /// tangent the last pass saw (StVK stiffens in stretch): the bound
    /// follows the deformation, sub-stepping whatever the policy (as for
    /// contact springs; a `refuse` policy refuses at start only).
    pub(super) fn follow_tangent(&mut self) {
        if let Some(large) = &self.large {
            let now = large.last().lambda;
            if !now.is_finite() {
                // A state that is no longer finite: more sub-steps cannot
                // save it, and the caller's divergence check reports it.
                return;
            }
            self.size.tangent_lambda = now.max(self.size.tangent_lambda * TANGENT_DECAY_PER_STEP);
            self.update_bound();
        }
    }

    pub(super) fn update_bound(&mut self) {
        let needed = self.needed_substeps(self.size.tangent_lambda);
        self.size.stable = self.stable_for(self.size.tangent_lambda);
        // Keeping the larger count for a while after the springs ease was
        // tried (to save the O(n) re-plans): the 250 Hz box stroke then
        // showed force steps of 0.07 N that the exact count does not.
        self.resubstep(needed);
    }

    /// The step bound with the nonlinear tangent at `tangent` (1/s^2) and
    /// the contact springs.
    pub(super) fn stable_for(&self, tangent: Real) -> StableStep {
        let rest = self.size.elastic_stable.omega_max_rad_s.powi(2);
        let lambda = rest.max(tangent) + self.size.contact_omega2;
        StableStep::from_lambda(lambda, self.size.elastic_stable.method)
    }

    /// Sub-steps per step that bound needs (sub-stepping whatever the
    /// policy, except `unchecked`), at most [`MAX_SUBSTEPS`].
    pub(super) fn needed_substeps(&self, tangent: Real) -> usize {
        let policy = match self.size.policy {
            DtPolicy::Unchecked => DtPolicy::Unchecked,
            _ => DtPolicy::Substep,
        };
        (substeps_for(self.size.dt_s, &self.stable_for(tangent), policy)
            .unwrap_or(self.size.substeps)
            .max(self.size.elastic_substeps)
            * self.size.substep_factor)
            .min(MAX_SUBSTEPS)
    }

    /// Splits each step into `factor` times the sub-steps stability needs
    /// (now and as contact springs come and go): to check a result
    /// against a finer integration.
    pub fn set_substep_factor(&mut self, factor: usize) {
        let factor = factor.max(1);
        let base = self.size.substeps / self.size.substep_factor;
        self.size.substep_factor = factor;
        self.resubstep(base * factor);
    }

    /// Sets the sub-step count (with multirate stepping, the fine one,
    /// rounded to a whole multiple of the coarse), keeping each vertex's
    /// velocity (U(t) - U(t-1)) / h.
    pub(super) fn resubstep(&mut self, n: usize) {
        let levels = self.levels_for(n);
        self.relevel(levels);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_that_needs_more_sub_steps_than_allowed_is_refused_not_run() {
        let stable = StableStep::from_lambda(4e6, BoundMethod::Element); // 1 ms
        assert_eq!(substeps_for(0.5e-3, &stable, DtPolicy::Substep), Ok(1));
        assert_eq!(substeps_for(2.5e-3, &stable, DtPolicy::Substep), Ok(3));
        let most = MAX_SUBSTEPS as Real * 1e-3;
        assert_eq!(
            substeps_for(most, &stable, DtPolicy::Substep),
            Ok(MAX_SUBSTEPS)
        );
        for dt_s in [most * 1.01, 1e300] {
            let err = substeps_for(dt_s, &stable, DtPolicy::Substep).unwrap_err();
            assert!(
                matches!(err, ExplicitError::TooManySubsteps { .. })
                    && err.to_string().contains("use dt_s <= 4.096e0 s"),
                "{err}"
            );
        }
        // Unchecked asks for none.
        assert_eq!(substeps_for(1e300, &stable, DtPolicy::Unchecked), Ok(1));
    }
}
