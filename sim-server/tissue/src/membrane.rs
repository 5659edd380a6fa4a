//! The surface membrane of paper section 3.7 (the liver capsule): springs on
//! the edges of the organ's outer surface with stiffness k = alpha * h, h the
//! sum of the altitudes onto the edge of its (one or two) surface triangles
//! (eq 30), force on V_j = k (l - l0) / l (V_k - V_j) (eq 29).
//!
//! The capsule covers the surface the organ had when it was built: faces
//! opened by cutting are raw tissue and get no membrane, and a capsule face
//! disappears with its tetrahedron (and comes back if it is restored). So a
//! cut changes k only on the 6 edges of the removed tetrahedron.
//!
//! Two models:
//! - [`MembraneModel::Linear`]: the spring linearised about the rest state,
//!   k d(x)d on the edge (d the rest direction), folded into the tensor-mass
//!   tensors: it costs nothing per step, matching the linear elasticity.
//! - [`MembraneModel::Nonlinear`]: eq 29 as written, evaluated every step from
//!   the current positions (invariant to rigid rotations of the surface).

use crate::ids::{EdgeId, TetId, VertexId};
use crate::math::{Real, Vec3};
use crate::mesh::{TET_EDGES, TET_FACES, TetMesh};
use crate::topology::Topology;

/// How the membrane springs enter the simulation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MembraneModel {
    /// Linearised springs folded into the stiffness tensors (no per-step cost).
    Linear,
    /// Paper eq 29 with the current lengths, computed every step.
    Nonlinear,
}

/// One capsule face's contribution: for each of its 3 edges (local to the
/// tetrahedron, index into [`TET_EDGES`]) the altitude onto that edge.
#[derive(Clone, Copy, Debug)]
struct CapsuleFace {
    tet: TetId,
    local_edges: [u8; 3],
    altitude_m: [Real; 3],
}

/// The capsule: per-edge spring stiffness kept current under cutting.
#[derive(Clone, Debug)]
pub struct Membrane {
    alpha_n_per_m2: Real,
    model: MembraneModel,
    faces: Vec<CapsuleFace>,
    /// Capsule faces of each tetrahedron (index range into `faces` by tet,
    /// via `face_start`), so a cut finds its own in O(1).
    face_start: Vec<u32>,
    /// Spring stiffness per mesh edge (N/m), 0 off the capsule.
    k_n_per_m: Vec<Real>,
    /// Capsule faces present on each edge: at 0 the stiffness is set to
    /// exactly zero, so no round-off residue survives a cut.
    faces_on_edge: Vec<u8>,
    /// Edges that carry a spring at build time (the only ones that ever can).
    capsule_edges: Vec<EdgeId>,
    /// The same springs packed for the per-step loop of the nonlinear model.
    springs: Vec<Spring>,
    /// Index into `springs` of each edge (u32::MAX off the capsule).
    spring_of_edge: Vec<u32>,
}

/// One capsule spring, laid out for the per-step loop: no lookups of the
/// topology or rest positions, no square root for the rest length.
#[derive(Clone, Copy, Debug)]
struct Spring {
    a: u32,
    b: u32,
    k_n_per_m: Real,
    rest_l0_m: Real,
    /// Rest vector b - a (m).
    rest_ab_m: [Real; 3],
}

impl Membrane {
    /// Builds the capsule on the current surface of `topo`.
    pub fn new(
        mesh: &TetMesh,
        topo: &Topology,
        alpha_n_per_m2: Real,
        model: MembraneModel,
    ) -> Self {
        Self::on_faces(mesh, topo, alpha_n_per_m2, model, |_, _| true)
    }

    /// Builds the capsule on the surface faces of `topo` that `keep` accepts
    /// (a part of a larger body keeps only the faces on the body's surface,
    /// not those where it meets the other parts).
    pub fn on_faces(
        mesh: &TetMesh,
        topo: &Topology,
        alpha_n_per_m2: Real,
        model: MembraneModel,
        keep: impl Fn(TetId, usize) -> bool,
    ) -> Self {
        let mut per_tet: Vec<Vec<CapsuleFace>> = vec![Vec::new(); mesh.tet_count()];
        for (t, k) in topo.surface_faces().filter(|&(t, k)| keep(t, k)) {
            let tet = mesh.tets()[t.idx()];
            let f = TET_FACES[k];
            let p = f.map(|l| mesh.positions_m()[tet[l].idx()]);
            let twice_area = (p[1] - p[0]).cross(p[2] - p[0]).length();
            let mut local_edges = [0u8; 3];
            let mut altitude_m = [0.0; 3];
            for s in 0..3 {
                let (a, b) = (f[s], f[(s + 1) % 3]);
                let e = TET_EDGES
                    .iter()
                    .position(|&[x, y]| (x, y) == (a.min(b), a.max(b)))
                    .expect("a face edge is a tet edge");
                local_edges[s] = e as u8;
                altitude_m[s] = twice_area / p[s].distance(p[(s + 1) % 3]);
            }
            per_tet[t.idx()].push(CapsuleFace {
                tet: t,
                local_edges,
                altitude_m,
            });
        }
        let mut faces = Vec::new();
        let mut face_start = Vec::with_capacity(mesh.tet_count() + 1);
        for list in per_tet {
            face_start.push(faces.len() as u32);
            faces.extend(list);
        }
        face_start.push(faces.len() as u32);
        let mut membrane = Self {
            alpha_n_per_m2,
            model,
            faces,
            face_start,
            k_n_per_m: vec![0.0; topo.edges().len()],
            faces_on_edge: vec![0; topo.edges().len()],
            capsule_edges: Vec::new(),
            springs: Vec::new(),
            spring_of_edge: vec![u32::MAX; topo.edges().len()],
        };
        for t in 0..mesh.tet_count() {
            membrane.apply_tet(topo, TetId::from(t), 1.0);
        }
        membrane.capsule_edges = (0..topo.edges().len())
            .filter(|&e| membrane.k_n_per_m[e] > 0.0)
            .map(EdgeId::from)
            .collect();
        let rest = mesh.positions_m();
        for (i, e) in membrane.capsule_edges.iter().enumerate() {
            let [a, b] = topo.edges()[e.idx()];
            let ab = rest[b.idx()] - rest[a.idx()];
            membrane.springs.push(Spring {
                a: a.0,
                b: b.0,
                k_n_per_m: membrane.k_n_per_m[e.idx()],
                rest_l0_m: ab.length(),
                rest_ab_m: ab.to_array(),
            });
            membrane.spring_of_edge[e.idx()] = i as u32;
        }
        membrane
    }

    /// Adds (`sign` 1) or removes (-1) the capsule faces of `t`; returns
    /// the stiffness change of each of its 6 edges.
    pub(crate) fn apply_tet(&mut self, topo: &Topology, t: TetId, sign: Real) -> [Real; 6] {
        let mut delta = [0.0; 6];
        let mut count = [0i32; 6];
        let range = self.face_start[t.idx()] as usize..self.face_start[t.idx() + 1] as usize;
        for face in &self.faces[range] {
            debug_assert_eq!(face.tet, t);
            for s in 0..3 {
                let l = face.local_edges[s] as usize;
                delta[l] += sign * self.alpha_n_per_m2 * face.altitude_m[s];
                count[l] += sign as i32;
            }
        }
        let edges = topo.tet_edges(t);
        for l in 0..6 {
            let e = edges[l].idx();
            self.faces_on_edge[e] = (self.faces_on_edge[e] as i32 + count[l]) as u8;
            if self.faces_on_edge[e] == 0 {
                delta[l] = -self.k_n_per_m[e];
                self.k_n_per_m[e] = 0.0;
            } else {
                self.k_n_per_m[e] += delta[l];
            }
            if let Some(s) = self.springs.get_mut(self.spring_of_edge[e] as usize) {
                s.k_n_per_m = self.k_n_per_m[e];
            }
        }
        delta
    }

    /// The springs that the capsule faces of `t` contribute, as (local vertex
    /// a, local vertex b, stiffness N/m); none once `t` is removed.
    pub fn tet_springs(&self, t: TetId) -> impl Iterator<Item = (usize, usize, Real)> + '_ {
        let range = self.face_start[t.idx()] as usize..self.face_start[t.idx() + 1] as usize;
        self.faces[range].iter().flat_map(move |f| {
            (0..3).map(move |s| {
                let [a, b] = TET_EDGES[f.local_edges[s] as usize];
                (a, b, self.alpha_n_per_m2 * f.altitude_m[s])
            })
        })
    }

    /// alpha (N/m^2).
    pub fn alpha_n_per_m2(&self) -> Real {
        self.alpha_n_per_m2
    }

    /// Linear or nonlinear.
    pub fn model(&self) -> MembraneModel {
        self.model
    }

    /// Spring stiffness of every mesh edge (N/m).
    pub fn stiffness_n_per_m(&self) -> &[Real] {
        &self.k_n_per_m
    }

    /// Edges that had a spring when the capsule was built.
    pub fn capsule_edges(&self) -> &[EdgeId] {
        &self.capsule_edges
    }

    /// Number of capsule faces still present.
    pub fn face_count(&self, topo: &Topology) -> usize {
        self.faces.iter().filter(|f| topo.is_alive(f.tet)).count()
    }

    /// Adds the nonlinear spring forces (eq 29) at displacements `u` to `out`
    /// (N). Allocation-free; one square root and one division per spring.
    pub fn add_forces(&self, u: &[[Real; 3]], out: &mut [[Real; 3]]) {
        for s in &self.springs {
            if s.k_n_per_m == 0.0 {
                continue;
            }
            let (a, b) = (s.a as usize, s.b as usize);
            let (ua, ub) = (u[a], u[b]);
            let d = [
                s.rest_ab_m[0] + ub[0] - ua[0],
                s.rest_ab_m[1] + ub[1] - ua[1],
                s.rest_ab_m[2] + ub[2] - ua[2],
            ];
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if l <= 0.0 {
                continue;
            }
            // Force on a: k (l - l0) / l (pb - pa); on b the opposite.
            let c = s.k_n_per_m * (1.0 - s.rest_l0_m / l);
            for i in 0..3 {
                out[a][i] += c * d[i];
                out[b][i] -= c * d[i];
            }
        }
    }

    /// Membrane energy (J) at displacements `u`, in this membrane's model.
    pub fn energy_j(&self, topo: &Topology, rest: &[Vec3], u: &[Vec3]) -> Real {
        let edges = topo.edges();
        self.capsule_edges
            .iter()
            .map(|&e| {
                let k = self.k_n_per_m[e.idx()];
                let [a, b] = edges[e.idx()];
                let (ra, rb) = (rest[a.idx()], rest[b.idx()]);
                let stretch = match self.model {
                    MembraneModel::Nonlinear => {
                        (rb + u[b.idx()]).distance(ra + u[a.idx()]) - ra.distance(rb)
                    }
                    MembraneModel::Linear => (rb - ra).normalize().dot(u[b.idx()] - u[a.idx()]),
                };
                0.5 * k * stretch * stretch
            })
            .sum()
    }

    /// The linearised tensor of edge `(a, b)` with stiffness k: k d(x)d, d the unit
    /// rest direction; it adds to K_aa and K_bb and subtracts from K_ab.
    pub fn linear_tensor(rest: &[Vec3], a: VertexId, b: VertexId, k: Real) -> crate::math::Mat3 {
        let d = (rest[b.idx()] - rest[a.idx()]).normalize();
        crate::math::outer(d, d) * k
    }
}
