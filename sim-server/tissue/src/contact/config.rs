//! How the tools touch the tissue: the contact law and its constants, from
//! the scene's `[contact]` section.

use crate::math::Real;

/// The contact law of the sliding contact (grips hold by prescribed
/// displacements under either law).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ContactLaw {
    /// Compliant Hunt-Crossley contact between the tool capsules and points
    /// on the surface triangles, evaluated every integrator sub-step
    /// ([`crate::contact::penalty::field`]): continuous in the tool pose. Needs a backend that
    /// integrates it (tensor-mass) or solves each step's equilibrium with
    /// it (precomputed, [`crate::backend`]).
    Penalty,
    /// The paper's law (4.1-4.2): the touched vertices are prescribed on a
    /// plane tangent to the tool. Exact non-penetration at vertices, but
    /// switches with the contact set (see [`crate::contact`]).
    Projection,
}

impl ContactLaw {
    /// The scene name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Penalty => "penalty",
            Self::Projection => "projection",
        }
    }
}

/// The largest `stiffness_factor` the linearly implicit springs take.
/// Measured with `hapbench extrapolation` (the 1 kHz truth on the 5 mm box
/// and on the liver): up to 1e4 the force converges as the factor grows
/// (box palpate peak 0.58 N at 64, 0.68 at 1e3, 0.72 at 1e4 and 3e4) with
/// no zero-force tick in contact and at most 0.01 N between sub-step
/// counts; at 1e5 both scenes drop the force to zero in contact and the
/// box's peak is 1.0 N, at 1e6 hundreds of newtons (the springs,
/// linearised once per sub-step, are then far stiffer than the explicit
/// parts of the step, the Hunt-Crossley damping and the normal's turning,
/// can follow). Explicit springs take any factor (their sub-steps grow
/// with it).
pub const MAX_IMPLICIT_STIFFNESS_FACTOR: Real = 1e4;

/// Contact settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactConfig {
    /// The law; `None`: penalty where the backend integrates it
    /// dynamically (tensor-mass), else projection (precomputed solves the
    /// penalty law when asked).
    pub law: Option<ContactLaw>,
    /// Penalty springs relative to the tissue's own vertex stiffness.
    pub stiffness_factor: Real,
    /// Hunt-Crossley alpha (s/m).
    pub damping_s_per_m: Real,
    /// Contact point spacing, as a fraction of the tool radius.
    pub point_spacing: Real,
    /// The simulated tool (proxy) follows the requested pose at most this
    /// fast (m/s): a glitch in the pose cannot throw it through the tissue.
    pub max_tool_speed_m_s: Real,
    /// ... and changes its velocity at most this fast (m/s^2).
    pub max_tool_accel_m_s2: Real,
    /// Near the tissue the proxy moves at most this much faster than the
    /// hand (m/s): a tool coming back to a still hand (after a let-go, a
    /// jump) enters the tissue at this speed, not at the speed limit.
    pub entry_speed_m_s: Real,
    /// The penalty springs are integrated linearly implicitly at the end
    /// of each sub-step (`contact::penalty::field::implicit`) instead of explicitly with
    /// the tissue's forces (which makes them size the sub-steps).
    pub implicit_springs: bool,
    /// The linear tetrahedra within this distance of a tool's tip (at
    /// their current positions) are corotational, the region following
    /// the tools (`follow_region.rs`); `None`: the model as the scene
    /// gives it. Needs a backend that can change its model while it runs
    /// (tensor-mass).
    pub corotational_radius_m: Option<Real>,
}

impl Default for ContactConfig {
    fn default() -> Self {
        Self {
            law: None,
            stiffness_factor: 64.0,
            damping_s_per_m: 3.0,
            point_spacing: 0.5,
            max_tool_speed_m_s: 1.0,
            max_tool_accel_m_s2: 100.0,
            entry_speed_m_s: 0.02,
            implicit_springs: true,
            corotational_radius_m: None,
        }
    }
}
