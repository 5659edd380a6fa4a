//! What a tool is, as a scene declares it: the contact code's input, so
//! that the core does not depend on the scene format (which builds these
//! from its `[[tool]]` tables).

use crate::contact::penalty::friction::Friction;
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
