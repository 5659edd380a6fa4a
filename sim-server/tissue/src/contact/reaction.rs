//! What the tool feels: the force the tissue exerts on the vertices a tool
//! constrains, and the contact stiffness around it, from the model's f64
//! tensors on those vertices' rows only.

use crate::math::{Mat3, Vec3, outer};

/// Force and stiffness one tool feels after a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reaction {
    /// Force the tissue exerts on the tool (N): the sum over the constrained
    /// vertices of their elastic forces F_i = -(K U)_i. A tool pressing into
    /// tissue is pushed back out of it.
    pub force_n: Vec3,
    /// Contact stiffness (N/m), symmetric positive semidefinite: how the
    /// force on the tool grows when the tool moves by dx is about
    /// `-stiffness * dx` (see [`crate::contact`] for the approximation).
    pub stiffness_n_per_m: Mat3,
}

impl Reaction {
    /// No contact.
    pub const NONE: Self = Self {
        force_n: Vec3::ZERO,
        stiffness_n_per_m: Mat3::ZERO,
    };

    /// The stiffness as rows (`[row][column]`), as the force sample carries it.
    pub fn stiffness_rows(&self) -> [[f64; 3]; 3] {
        self.stiffness_n_per_m.transpose().to_cols_array_2d()
    }
}

/// The stiffness K_vv restricted to the direction `n`: n (n^T K n) n^T.
pub(crate) fn along(k: &Mat3, n: Vec3) -> Mat3 {
    outer(n, n) * n.dot(*k * n)
}
