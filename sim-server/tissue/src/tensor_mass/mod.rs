//! Tensor-mass elasticity (paper sections 3.1-3.4): element tensors
//! derived from the energy, the assembled model with local cutting updates,
//! the hot kernel, explicit integration and its stability bound; and the
//! large-strain models (StVK, corotational) as a per-element pass beside it.

mod corotational_lanes;
pub mod element;
pub mod explicit;
pub mod force_term;
pub mod huge_pages;
pub mod kernel;
mod lanes;
pub mod large_strain;
pub mod model;
pub mod nonlinear;
pub mod stability;
mod stvk_lanes;
pub mod submodel;

pub use element::{Geometry, TetElastic};
pub use explicit::{
    DtPolicy, Explicit, ExplicitConfig, ExplicitError, MultirateError, MultirateReport,
    substeps_for,
};
pub use force_term::{ForcePoint, ForceTerm, NoForce, SubStep};
pub use kernel::{Kernel, Storage};
pub use model::{CutChange, CutError, ElasticModel, LinearOnly, ModelError};
pub use stability::{
    BoundMethod, PowerEstimate, StableStep, StepOutliers, element_bound, power_iteration,
    step_outliers,
};
pub use submodel::{Submodel, SubmodelError};
