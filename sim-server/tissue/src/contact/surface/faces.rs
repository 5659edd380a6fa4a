//! The live surface triangles around a set of vertices, each visited once
//! per pass: how the point sampler and the tips' surface test
//! ([`crate::contact::surface::crossing`]) go from the [`crate::contact::SurfaceIndex`]'s
//! candidate vertices to triangles.

use crate::contact::surface::adjacency::Adjacency;
use crate::ids::VertexId;
use crate::mesh::TET_FACES;
use crate::tensor_mass::ElasticModel;

/// Which (tetrahedron, face) pairs a pass has visited.
pub(in crate::contact) struct SurfaceFaces {
    /// Per (tet, face): the stamp of the last pass that visited it.
    visited: Vec<u32>,
    stamp: u32,
}

impl SurfaceFaces {
    /// For `model`'s tetrahedra, nothing visited.
    pub(in crate::contact) fn new(model: &ElasticModel) -> Self {
        Self {
            visited: vec![0; 4 * model.mesh().tet_count()],
            stamp: 0,
        }
    }

    /// Starts a pass: every face unvisited.
    pub(in crate::contact) fn begin(&mut self) {
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            // Wrapped (after 2^32 passes): old stamps must not match.
            self.visited.fill(0);
            self.stamp = 1;
        }
    }

    /// Calls `f` with the vertices (outward order, [`TET_FACES`]) of each
    /// live surface triangle through `v` not yet visited in this pass.
    pub(in crate::contact) fn around(
        &mut self,
        model: &ElasticModel,
        adj: &Adjacency,
        v: VertexId,
        mut f: impl FnMut([VertexId; 3]),
    ) {
        let topo = model.topology();
        let tets = model.mesh().tets();
        for &t in adj.tets_of(v) {
            if !topo.is_alive(t) {
                continue;
            }
            let tet = tets[t.idx()];
            for (k, face) in TET_FACES.iter().enumerate() {
                let id = 4 * t.idx() + k;
                // Face k is the one opposite vertex k: not through v.
                if tet[k] == v || self.visited[id] == self.stamp {
                    continue;
                }
                self.visited[id] = self.stamp;
                if topo.is_surface_face(t, k) {
                    f(face.map(|l| tet[l]));
                }
            }
        }
    }
}
