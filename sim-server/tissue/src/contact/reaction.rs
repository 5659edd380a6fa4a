//! What the tool feels, the reaction physics in one place: the elastic
//! force -(K U)_v the tissue exerts at a vertex (from the model's f64
//! tensors on that vertex's row only), the force on a tool (the penalty
//! field's force on its parts plus that elastic force at every vertex it
//! constrains), and the contact stiffness beside it.

use super::adjacency::Adjacency;
use super::{Constraint, ConstraintKind};
use crate::backend::Backend;
use crate::ids::VertexId;
use crate::math::{Mat3, Vec3, outer};
use crate::tensor_mass::ElasticModel;

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
fn along(k: &Mat3, n: Vec3) -> Mat3 {
    outer(n, n) * n.dot(*k * n)
}

/// The elastic force -(K U)_v (N) at vertex `v`, given displacements: the
/// vertex tensor and the tensors of the edges around it (`adj`).
pub(crate) fn elastic_force_n(
    adj: &Adjacency,
    model: &ElasticModel,
    v: VertexId,
    displacement: impl Fn(VertexId) -> Vec3,
) -> Vec3 {
    let mut ku = model.vertex_tensors()[v.idx()] * displacement(v);
    let edges = model.topology().edges();
    let tensors = model.edge_tensors();
    for e in adj.edges_of(v) {
        let [a, b] = edges[e.idx()];
        let k = tensors[e.idx()];
        // Stored as K_ab with a < b; row b uses K_ba = K_ab^T.
        ku += if a == v {
            k * displacement(b)
        } else {
            k.transpose() * displacement(a)
        };
    }
    -ku
}

/// One tool's reaction after a step: `penalty` (the penalty field's force
/// on the tool and the contact stiffness computed for it), if the tool
/// uses that law, plus, at every vertex it constrains, the elastic force
/// there and the vertex's own stiffness (along the contact normal for
/// the tip and shaft, whole for a grip).
pub(crate) fn tool_reaction<B: Backend + ?Sized>(
    sim: &B,
    adj: &Adjacency,
    constraints: &[Constraint],
    penalty: Option<(Vec3, Mat3)>,
) -> Reaction {
    let model = sim.model();
    let mut out = Reaction::NONE;
    if let Some((force_n, stiffness_n_per_m)) = penalty {
        out.force_n = force_n;
        out.stiffness_n_per_m = stiffness_n_per_m;
    }
    for c in constraints {
        let v = c.vertex;
        out.force_n += elastic_force_n(adj, model, v, |w| sim.displacement(w));
        let k = &model.vertex_tensors()[v.idx()];
        out.stiffness_n_per_m += match c.kind {
            ConstraintKind::Tip(n) | ConstraintKind::Shaft(n) => along(k, n),
            ConstraintKind::Grip => *k,
        };
    }
    out
}
