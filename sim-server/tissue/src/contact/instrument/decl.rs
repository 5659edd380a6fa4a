//! What a tool is, as a scene declares it: the contact code's input, so
//! that the core does not depend on the scene format (which builds these
//! from its `[[tool]]` tables).

use crate::math::Real;
use serde::{Deserialize, Serialize};

/// Tool kinds.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ToolKind {
    /// Jaws: grips, and cuts when closed on tissue.
    Grasper,
    /// A hook: pushes and pulls.
    Hook,
    /// Removes every tetrahedron touching its tip.
    Cavitron,
}

/// A declared tool: its kind and geometry.
#[derive(Clone, Debug, Serialize)]
pub struct ToolDecl {
    /// Unique name.
    pub name: String,
    /// Kind.
    pub kind: ToolKind,
    /// Insertion point (m).
    pub fulcrum_m: [Real; 3],
    /// Shaft length (m).
    pub length_m: Real,
    /// Shaft radius (m).
    pub radius_m: Real,
    /// Tip segment length (m).
    pub tip_length_m: Real,
    /// Coulomb friction of its sliding contact (penalty law only; the
    /// projection law's prescribed vertices already stick).
    pub friction: Friction,
}

/// A tool's Coulomb coefficients (zero: frictionless, the default).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Friction {
    /// Static coefficient mu_s: a sticking point holds up to mu_s times
    /// its normal force.
    pub static_coefficient: Real,
    /// Dynamic (kinetic) coefficient mu_d <= mu_s: a sliding point is
    /// dragged with mu_d times its normal force.
    pub dynamic_coefficient: Real,
}

impl Friction {
    /// No friction at all.
    pub const NONE: Self = Self {
        static_coefficient: 0.0,
        dynamic_coefficient: 0.0,
    };

    /// Whether this tool has friction.
    pub fn is_active(&self) -> bool {
        self.static_coefficient > 0.0
    }

    /// Why these coefficients cannot serve, if they cannot: both finite and
    /// non-negative, static at least dynamic.
    pub fn check(&self) -> Result<(), String> {
        let (s, d) = (self.static_coefficient, self.dynamic_coefficient);
        if !(s.is_finite() && s >= 0.0) {
            return Err(format!(
                "friction_static must be a finite number >= 0, got {s}"
            ));
        }
        if !(d.is_finite() && d >= 0.0) {
            return Err(format!(
                "friction_dynamic must be a finite number >= 0, got {d}"
            ));
        }
        if d > s {
            return Err(format!(
                "friction_dynamic ({d}) exceeds friction_static ({s}): a sliding contact cannot hold more than a sticking one"
            ));
        }
        Ok(())
    }
}
