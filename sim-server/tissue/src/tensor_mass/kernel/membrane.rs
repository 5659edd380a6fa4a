//! A kernel holding only the linear capsule membrane's springs, for a
//! model whose every element is nonlinear: the nonlinear pass then
//! computes the elements' whole force, and the kernel adds the capsule's
//! (paper 3.7, folded into the model's tensors as k d d^T per capsule
//! edge). Before this the capsule kept the elements' linear tensors in the
//! kernel, and the pass computed each element's difference from its linear
//! force: on the embedded liver a step cost 17% more that way with
//! `model = "corotational"` and 32% more with `"stvk"` (medians of five
//! interleaved rounds, docs/results/large-strain.md). A part of [`super`], which owns the
//! kernel's storage.

use super::storage::pack;
use super::{EdgeBlock, Holds, Kernel, Storage, V3};
use super::{LowerRows, row_product};
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
    /// Per slot: its topology edge.
    edge_of: Vec<u32>,
    /// The kernel's edges seen from their column (the predicted step's
    /// view), for each vertex's springs and its row's product.
    lower: LowerRows,
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
        let mut capsule: Vec<u32> = membrane.capsule_edges().iter().map(|e| e.0).collect();
        capsule.sort_unstable();
        capsule.dedup();
        let mut row_start = vec![0u32; n + 1];
        let mut slot_of = vec![u32::MAX; edges.len()];
        for (slot, &e) in capsule.iter().enumerate() {
            row_start[edges[e as usize][0].idx() + 1] += 1;
            slot_of[e as usize] = slot as u32;
        }
        for i in 0..n {
            row_start[i + 1] += row_start[i];
        }
        let blocks = capsule.iter().map(|&e| EdgeBlock {
            k: pack(&-spring(model, membrane, e as usize)),
            col: edges[e as usize][1].0,
        });
        let mut kernel = Self {
            diag: collect_huge(n, std::iter::repeat_n([S::default(); 9], n)),
            row_start,
            edges: collect_huge(capsule.len(), blocks),
            span: (capsule.iter())
                .map(|&e| (edges[e as usize][1].0 - edges[e as usize][0].0) as usize)
                .max()
                .unwrap_or(0),
            holds: Holds::Nothing,
        };
        let rows = MembraneRows {
            slot_of,
            edge_of: capsule,
            lower: LowerRows::new(&kernel),
        };
        for v in 0..n {
            kernel.diag[v] = pack(&kernel.capsule_vertex_tensor(&rows, model, membrane, v));
        }
        kernel.holds = Holds::Membrane(rows);
        kernel
    }

    /// The kernel's own force at vertex `v`, -(K u)_v (N), when it holds
    /// only the capsule's springs (the elements' whole force is the
    /// nonlinear pass's; summed as the step's pass sums it); `None` when it
    /// holds the elements' tensors too, zero when it holds nothing.
    pub fn capsule_force_n(&self, v: VertexId, u: &[V3]) -> Option<V3> {
        match &self.holds {
            Holds::Elastic => None,
            Holds::Nothing => Some([0.0; 3]),
            Holds::Membrane(rows) => Some(row_product(self, &rows.lower, u, v.idx()).map(|x| -x)),
        }
    }

    /// Rewrites the capsule springs a cut changed (its tetrahedron's
    /// edges and vertices), from the membrane's stiffness after the cut.
    pub(super) fn update_capsule(&mut self, model: &ElasticModel, change: &CutChange) {
        let (Holds::Membrane(rows), Some(membrane)) = (&self.holds, model.membrane()) else {
            return;
        };
        for e in change.edges {
            let slot = rows.slot_of[e.idx()];
            if slot != u32::MAX {
                self.edges[slot as usize].k = pack(&-spring(model, membrane, e.idx()));
            }
        }
        for v in change.vertices {
            let t = self.capsule_vertex_tensor(rows, model, membrane, v.idx());
            self.diag[v.idx()] = pack(&t);
        }
    }

    /// Vertex `v`'s tensor: the sum of its capsule springs (its row's
    /// edges, then those reaching it from lower rows), in a fixed order (a
    /// cut and its restoration give back the same sum).
    fn capsule_vertex_tensor(
        &self,
        rows: &MembraneRows,
        model: &ElasticModel,
        membrane: &Membrane,
        v: usize,
    ) -> Mat3 {
        let lower = rows.lower.of(v).iter().map(|&[_, slot]| slot as usize);
        (self.row(v).chain(lower)).fold(Mat3::ZERO, |sum, slot| {
            sum + spring(model, membrane, rows.edge_of[slot] as usize)
        })
    }
}
