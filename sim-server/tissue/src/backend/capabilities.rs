//! What a backend can do, in one record ([`Capabilities`]), so that the
//! contact set-up, the run loop and the reports ask one question instead of
//! a trait method per capability.

/// What a [`super::Backend`] can do. Fixed for a backend's life: read once
/// at set-up (cold), never per step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Capabilities {
    /// The backend's name in scenes and reports (`tensor-mass`, `implicit`,
    /// `precomputed`, `hybrid`).
    pub name: &'static str,
    /// Whether it integrates inertia (false: quasi-static, each step an
    /// equilibrium).
    pub dynamic: bool,
    /// Whether it is stable at any step (implicit integration), so that a
    /// step longer than the real-time one is a remedy for steps that take
    /// longer than they simulate.
    pub stable_at_any_step: bool,
    /// Whether [`super::Backend::step_with_contact`] evaluates the penalty
    /// contact (the penalty law needs it): at every sub-step of a dynamic
    /// backend, or as each step's equilibrium on a static one.
    pub integrates_contact: bool,
    /// Whether its linear tetrahedra can be made corotational from one step
    /// to the next ([`super::Backend::set_corotational_region`]): the
    /// region that follows the tools. A backend whose model is fixed when
    /// it starts (implicit, precomputed, hybrid) cannot.
    pub corotational_region: bool,
}

impl Capabilities {
    /// A dynamic backend that can do nothing else: the base the
    /// implementations add to.
    pub const fn dynamic(name: &'static str) -> Self {
        Self {
            name,
            dynamic: true,
            stable_at_any_step: false,
            integrates_contact: false,
            corotational_region: false,
        }
    }
}
