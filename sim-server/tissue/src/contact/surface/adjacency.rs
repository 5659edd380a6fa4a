//! What each vertex touches, in compressed rows, built once per scene and
//! shared by every tool: its edges (for the elastic force on one vertex,
//! [`crate::contact::response::reaction::elastic_force_n`])
//! and its tetrahedra (for cutting and for the surface normals around it).
//! Neither list changes under cutting: removed tetrahedra are skipped by
//! their users, orphaned edges keep zero tensors.

use crate::ids::{EdgeId, TetId, VertexId};
use crate::tensor_mass::ElasticModel;

/// Per-vertex lists of `T` (compressed rows).
#[derive(Clone, Debug)]
struct PerVertex<T> {
    offsets: Vec<u32>,
    items: Vec<T>,
}

impl<T: Copy> PerVertex<T> {
    /// From (vertex, item) pairs; `pairs` is called twice (count, fill).
    fn build<I: Iterator<Item = (VertexId, T)>>(n: usize, pairs: impl Fn() -> I, blank: T) -> Self {
        let mut offsets = vec![0u32; n + 1];
        for (v, _) in pairs() {
            offsets[v.idx() + 1] += 1;
        }
        for i in 0..n {
            offsets[i + 1] += offsets[i];
        }
        let mut fill = offsets.clone();
        let mut items = vec![blank; offsets[n] as usize];
        for (v, item) in pairs() {
            items[fill[v.idx()] as usize] = item;
            fill[v.idx()] += 1;
        }
        Self { offsets, items }
    }

    fn of(&self, v: VertexId) -> &[T] {
        &self.items[self.offsets[v.idx()] as usize..self.offsets[v.idx() + 1] as usize]
    }
}

/// The edges and tetrahedra around each vertex.
#[derive(Clone, Debug)]
pub(crate) struct Adjacency {
    edges: PerVertex<EdgeId>,
    tets: PerVertex<TetId>,
}

impl Adjacency {
    pub(crate) fn new(model: &ElasticModel) -> Self {
        let n = model.vertex_count();
        let edges = model.topology().edges();
        let tets = model.mesh().tets();
        Self {
            edges: PerVertex::build(
                n,
                || {
                    edges
                        .iter()
                        .enumerate()
                        .flat_map(|(e, [a, b])| [(*a, EdgeId::from(e)), (*b, EdgeId::from(e))])
                },
                EdgeId(0),
            ),
            tets: PerVertex::build(
                n,
                || {
                    tets.iter()
                        .enumerate()
                        .flat_map(|(t, tet)| tet.map(|v| (v, TetId::from(t))))
                },
                TetId(0),
            ),
        }
    }

    /// The tetrahedra that use `v` (removed ones included).
    pub(crate) fn tets_of(&self, v: VertexId) -> &[TetId] {
        self.tets.of(v)
    }

    /// The edges that use `v`.
    pub(crate) fn edges_of(&self, v: VertexId) -> &[EdgeId] {
        self.edges.of(v)
    }
}
