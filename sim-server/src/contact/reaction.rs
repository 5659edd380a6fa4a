//! What the tool feels: the force the tissue exerts on the vertices a tool
//! constrains, and the contact stiffness around it, from the model's f64
//! tensors on those vertices' rows only.

use crate::ids::{EdgeId, VertexId};
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

/// Edges around each vertex (compressed rows), built once: the edge list of
/// a model never changes under cutting (orphaned edges keep zero tensors).
#[derive(Clone, Debug)]
pub(crate) struct VertexEdges {
    offsets: Vec<u32>,
    edges: Vec<EdgeId>,
}

impl VertexEdges {
    pub(crate) fn new(model: &ElasticModel) -> Self {
        let edges = model.topology().edges();
        let n = model.vertex_count();
        let mut offsets = vec![0u32; n + 1];
        for [a, b] in edges {
            offsets[a.idx() + 1] += 1;
            offsets[b.idx() + 1] += 1;
        }
        for i in 0..n {
            offsets[i + 1] += offsets[i];
        }
        let mut fill = offsets.clone();
        let mut list = vec![EdgeId(0); offsets[n] as usize];
        for (e, [a, b]) in edges.iter().enumerate() {
            for v in [a, b] {
                list[fill[v.idx()] as usize] = EdgeId::from(e);
                fill[v.idx()] += 1;
            }
        }
        Self {
            offsets,
            edges: list,
        }
    }

    /// The elastic force -(K U)_v (N) at vertex `v`, given displacements.
    pub(crate) fn elastic_force_n(
        &self,
        model: &ElasticModel,
        v: VertexId,
        displacement: impl Fn(VertexId) -> Vec3,
    ) -> Vec3 {
        let mut ku = model.vertex_tensors()[v.idx()] * displacement(v);
        let range = self.offsets[v.idx()] as usize..self.offsets[v.idx() + 1] as usize;
        let edges = model.topology().edges();
        let tensors = model.edge_tensors();
        for e in &self.edges[range] {
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
}

/// The stiffness K_vv restricted to the direction `n`: n (n^T K n) n^T.
pub(crate) fn along(k: &Mat3, n: Vec3) -> Mat3 {
    outer(n, n) * n.dot(*k * n)
}
