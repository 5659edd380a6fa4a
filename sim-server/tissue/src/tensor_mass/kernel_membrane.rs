//! A kernel holding only the linear capsule membrane's springs, for a
//! model whose every element is nonlinear: the nonlinear pass then
//! computes the elements' whole force, and the kernel adds the capsule's
//! (paper 3.7, folded into the model's tensors as k d d^T per capsule
//! edge). Before this the capsule kept the elements' linear tensors in the
//! kernel, and the pass computed each element's difference from its linear
//! force: on the embedded liver a step cost 17% more that way with
//! `model = "corotational"` and 32% more with `"stvk"` (medians of five
//! interleaved rounds, README). A part of [`super`], which owns the
//! kernel's storage.

use super::storage::pack;
use super::{EdgeBlock, Holds, Kernel, Storage, V3, mul, mul_t};
use crate::ids::VertexId;
use crate::math::Mat3;
use crate::membrane::{Membrane, MembraneModel};
use crate::tensor_mass::huge_pages::collect_huge;
use crate::tensor_mass::model::{CutChange, ElasticModel};

/// Where the capsule's springs sit in the kernel, to rewrite them after a
/// cut changed their stiffness.
#[derive(Clone, Debug)]
pub(super) struct MembraneRows {
    /// Per topology edge: its slot among the kernel's edges, or `u32::MAX`
    /// (not a capsule edge).
    slot_of: Vec<u32>,
    /// Per vertex: where its capsule edges start in `incident`.
    incident_start: Vec<u32>,
    /// The capsule edges at each vertex: (topology edge, the other vertex).
    incident: Vec<(u32, u32)>,
}

/// The capsule spring of topology edge `e`: k d d^T (N/m), added to both
/// vertices' tensors and subtracted from the edge's (as the model folds it).
fn spring(model: &ElasticModel, membrane: &Membrane, e: usize) -> Mat3 {
    let [a, b] = model.topology().edges()[e];
    let k = membrane.stiffness_n_per_m()[e];
    Membrane::linear_tensor(model.mesh().positions_m(), a, b, k)
}

impl<S: Storage> Kernel<S> {
    /// The kernel of a model whose every element is nonlinear: the linear
    /// capsule membrane's springs when it has one, else no tensors at all
    /// ([`Kernel::without_elastic`]).
    pub fn beside_whole_forces(model: &ElasticModel) -> Self {
        let n = model.vertex_count();
        let Some(membrane) = model
            .membrane()
            .filter(|m| m.model() == MembraneModel::Linear)
        else {
            return Self::without_elastic(n);
        };
        let edges = model.topology().edges();
        // Edge ids are sorted by (a, b): in id order the capsule edges come
        // row by row, as the kernel stores them.
        let mut capsule: Vec<usize> = membrane.capsule_edges().iter().map(|e| e.idx()).collect();
        capsule.sort_unstable();
        capsule.dedup();
        let mut row_start = vec![0u32; n + 1];
        let mut incident_start = vec![0u32; n + 1];
        for &e in &capsule {
            let [a, b] = edges[e];
            row_start[a.idx() + 1] += 1;
            incident_start[a.idx() + 1] += 1;
            incident_start[b.idx() + 1] += 1;
        }
        for i in 0..n {
            row_start[i + 1] += row_start[i];
            incident_start[i + 1] += incident_start[i];
        }
        let mut slot_of = vec![u32::MAX; edges.len()];
        let mut incident = vec![(0, 0); incident_start[n] as usize];
        let mut fill = incident_start.clone();
        for (slot, &e) in capsule.iter().enumerate() {
            slot_of[e] = slot as u32;
            let [a, b] = edges[e];
            for (v, other) in [(a, b), (b, a)] {
                incident[fill[v.idx()] as usize] = (e as u32, other.0);
                fill[v.idx()] += 1;
            }
        }
        let rows = MembraneRows {
            slot_of,
            incident_start,
            incident,
        };
        let blocks = capsule.iter().map(|&e| EdgeBlock {
            k: pack(&-spring(model, membrane, e)),
            col: edges[e][1].0,
        });
        let diag = (0..n).map(|v| pack(&rows.vertex_tensor(model, membrane, v)));
        Self {
            diag: collect_huge(n, diag),
            row_start,
            edges: collect_huge(capsule.len(), blocks),
            span: (capsule.iter())
                .map(|&e| (edges[e][1].0 - edges[e][0].0) as usize)
                .max()
                .unwrap_or(0),
            holds: Holds::Membrane(rows),
        }
    }

    /// The kernel's own force at vertex `v`, -(K u)_v (N), when it holds
    /// only the capsule's springs (the elements' whole force is the
    /// nonlinear pass's); `None` when it holds the elements' tensors too,
    /// zero when it holds nothing.
    pub fn capsule_force_n(&self, v: VertexId, u: &[V3]) -> Option<V3> {
        match &self.holds {
            Holds::Elastic => None,
            Holds::Nothing => Some([0.0; 3]),
            Holds::Membrane(rows) => {
                let i = v.idx();
                let mut ku = mul(&self.diag[i], &u[i]);
                let range = rows.incident_start[i] as usize..rows.incident_start[i + 1] as usize;
                for &(e, other) in &rows.incident[range] {
                    // Stored as K_ab with a < b; row b uses K_ba = K_ab^T.
                    let k = &self.edges[rows.slot_of[e as usize] as usize].k;
                    let w = &u[other as usize];
                    let d = if (v.0) < other {
                        mul(k, w)
                    } else {
                        mul_t(k, w)
                    };
                    for c in 0..3 {
                        ku[c] += d[c];
                    }
                }
                Some(ku.map(|x| -x))
            }
        }
    }

    /// Rewrites the capsule springs a cut changed (its tetrahedron's
    /// edges and vertices), from the membrane's stiffness after the cut.
    pub(super) fn update_capsule(&mut self, model: &ElasticModel, change: &CutChange) {
        let Holds::Membrane(rows) = &self.holds else {
            return;
        };
        let Some(membrane) = model.membrane() else {
            return;
        };
        for e in change.edges {
            let slot = rows.slot_of[e.idx()];
            if slot != u32::MAX {
                self.edges[slot as usize].k = pack(&-spring(model, membrane, e.idx()));
            }
        }
        for v in change.vertices {
            self.diag[v.idx()] = pack(&rows.vertex_tensor(model, membrane, v.idx()));
        }
    }
}

impl MembraneRows {
    /// Vertex `v`'s tensor: the sum of its capsule springs, in a fixed order
    /// (a cut and its restoration give back the same sum).
    fn vertex_tensor(&self, model: &ElasticModel, membrane: &Membrane, v: usize) -> Mat3 {
        let range = self.incident_start[v] as usize..self.incident_start[v + 1] as usize;
        (self.incident[range].iter()).fold(Mat3::ZERO, |sum, &(e, _)| {
            sum + spring(model, membrane, e as usize)
        })
    }
}
