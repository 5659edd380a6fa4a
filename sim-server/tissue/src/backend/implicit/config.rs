//! The implicit backend's settings ([`ImplicitConfig`], [`Preconditioner`])
//! and why it refuses a model ([`ImplicitError`]).

use crate::math::Real;

/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImplicitConfig {
    /// The step (s).
    pub dt_s: Real,
    /// Relative residual at which the CG stops.
    pub tolerance: Real,
    /// CG iteration limit per step.
    pub max_iterations: usize,
    /// With a Cholesky factor, at most this many CG iterations a step (see
    /// `backend/implicit/mod.rs`); `None` (the default) iterates to the tolerance or
    /// `max_iterations`. The Jacobi preconditioner ignores it.
    pub step_iterations: Option<usize>,
    /// How the CG is preconditioned.
    pub preconditioner: Preconditioner,
    /// Rebuild the Cholesky factor on a worker thread, the steps using the
    /// old one meanwhile (default); `false` rebuilds inline, in the step
    /// that needs it, so that runs are reproducible step for step (the
    /// trajectories agree either way, to the CG tolerance, as long as no
    /// `step_iterations` budget stops a step short: a capped step's answer
    /// depends on which factor is in use, so on when the worker finished).
    pub background_rebuild: bool,
}

/// The CG preconditioner of the implicit backend.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preconditioner {
    /// The diagonal of A: no set-up, many iterations on stiff or
    /// nearly incompressible tissue.
    Jacobi,
    /// A sparse Cholesky factor of A (see `backend/implicit/mod.rs`); falls back to
    /// Jacobi if it cannot be built.
    Cholesky,
}

/// The Cholesky preconditioner is rebuilt once the CG iterations beyond one
/// per step since it was built exceed this: one factorisation costs about
/// 50 preconditioner solves on the meshes measured (docs/guide/backends.md).
pub const REFACTOR_BUDGET: usize = 50;

impl ImplicitConfig {
    /// Step `dt_s`, residual 1e-9, at most 1000 iterations, Cholesky
    /// preconditioner rebuilt in the background, no per-step budget.
    pub fn new(dt_s: Real) -> Self {
        Self {
            dt_s,
            tolerance: 1e-9,
            max_iterations: 1000,
            step_iterations: None,
            preconditioner: Preconditioner::Cholesky,
            background_rebuild: true,
        }
    }
}

/// Why the implicit backend cannot run a model.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ImplicitError {
    /// The step is not a positive number.
    #[error("the implicit backend's dt_s must be positive and finite, got {0}")]
    BadDt(Real),
    /// The nonlinear membrane is not linear in u.
    #[error(
        "the implicit backend supports the linear membrane only (its forces are in K); use model = \"linear\" or the tensor-mass backend"
    )]
    NonlinearMembrane,
    /// A nonlinear material model.
    #[error(transparent)]
    LinearOnly(#[from] crate::tensor_mass::LinearOnly),
}
