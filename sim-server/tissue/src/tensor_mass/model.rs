//! The assembled tensor-mass model in double precision: per-vertex tensors
//! K_ii, per-edge tensors K_ij, lumped masses and damping, kept current under
//! cutting by local updates (paper section 3.4). This is the reference the
//! hot kernel is copied from and checked against.

use super::element::{Geometry, TetElastic};
use crate::ids::{EdgeId, TetId, VertexId};
use crate::material_map::{AssignError, TetMaterials};
use crate::math::{Mat3, Real, Vec3};
use crate::membrane::{Membrane, MembraneModel};
use crate::mesh::{TET_EDGES, TetMesh};
use crate::topology::{Orphans, Topology};
use thiserror::Error;

/// Why a model could not be built.
#[derive(Debug, Error, PartialEq)]
pub enum ModelError {
    /// The material map does not cover the mesh.
    #[error("materials cover {materials} tetrahedra but the mesh has {tets}")]
    MaterialCount {
        /// Covered.
        materials: usize,
        /// In the mesh.
        tets: usize,
    },
    /// A material assignment problem.
    #[error(transparent)]
    Assign(#[from] AssignError),
    /// The membrane coefficient is not a finite non-negative number.
    #[error("membrane alpha must be a finite number >= 0 (N/m^2), got {0}")]
    MembraneAlpha(Real),
    /// More than two tetrahedra share a face: the mesh overlaps itself.
    #[error(
        "the face of vertices {vertices:?} is shared by {count} tetrahedra ({tets:?}): a face of a volume mesh joins at most two, so the mesh overlaps itself there (a duplicated or folded element); fix the mesh (`sim-server check` counts such faces)",
        vertices = .0.vertices.map(|v| v.0),
        count = .0.tets.len(),
        tets = .0.tets.iter().map(|t| t.0).collect::<Vec<_>>()
    )]
    OversharedFace(crate::topology::OversharedFace),
}

/// Why a cut (removal or restoration) was refused.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum CutError {
    /// No such tetrahedron.
    #[error("tetrahedron {0} does not exist")]
    NoSuchTet(u32),
    /// Removing a tetrahedron that is already removed.
    #[error("tetrahedron {0} is already removed")]
    AlreadyRemoved(u32),
    /// Restoring a tetrahedron that is present.
    #[error("tetrahedron {0} is present; only removed tetrahedra can be added back")]
    AlreadyPresent(u32),
    /// The backend cannot cut.
    #[error("the {backend} backend cannot cut: {why}")]
    Unsupported {
        /// Which backend.
        backend: &'static str,
        /// Why, and what to use instead.
        why: &'static str,
    },
}

/// A backend or solver that runs the linear model only was given
/// tetrahedra with a nonlinear material model.
#[derive(Clone, Debug, Error, PartialEq, Eq)]
#[error(
    "the {who} runs the linear model only ({why}); {tets} tetrahedra use model = \"{model}\": use the tensor-mass backend, or model = \"linear\""
)]
pub struct LinearOnly {
    /// Which backend or solver.
    pub who: &'static str,
    /// Why it cannot run the others.
    pub why: &'static str,
    /// Nonlinear tetrahedra it would have to run.
    pub tets: usize,
    /// The first one's model name.
    pub model: &'static str,
}

/// What a cut changed: the tetrahedron's 4 vertices and 6 edges (whose
/// tensors were updated) and those it left orphaned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CutChange {
    /// The tetrahedron.
    pub tet: TetId,
    /// Its vertices.
    pub vertices: [VertexId; 4],
    /// Its edges.
    pub edges: [EdgeId; 6],
}

/// The tensor-mass model: mesh, materials, topology and assembled tensors.
#[derive(Clone, Debug)]
pub struct ElasticModel {
    mesh: TetMesh,
    materials: TetMaterials,
    topo: Topology,
    vertex_k: Vec<Mat3>,
    edge_k: Vec<Mat3>,
    mass_kg: Vec<Real>,
    damping_kg_s: Vec<Real>,
    membrane: Option<Membrane>,
    /// Mass and damping attached to vertices from outside the model (a
    /// hybrid's static part); kept when the vertex loses its last
    /// tetrahedron. Empty unless [`ElasticModel::attach_mass`] was called.
    attached: Vec<(Real, Real)>,
    orphans: Orphans,
    topology_changes: u64,
    /// Each tetrahedron's Irons eigenvalue, computed on first use
    /// ([`ElasticModel::element_lambdas`]).
    pub(super) element_lambdas: std::sync::OnceLock<std::sync::Arc<[Real]>>,
}

impl ElasticModel {
    /// Assembles the model. Materials must cover every tetrahedron and every
    /// anisotropic tetrahedron needs a fibre direction.
    pub fn new(mesh: TetMesh, materials: TetMaterials) -> Result<Self, ModelError> {
        if materials.len() != mesh.tet_count() {
            return Err(ModelError::MaterialCount {
                materials: materials.len(),
                tets: mesh.tet_count(),
            });
        }
        materials.validate()?;
        let topo = Topology::new(&mesh);
        if let Some(face) = topo.overshared_face() {
            return Err(ModelError::OversharedFace(face.clone()));
        }
        let n = mesh.vertex_count();
        let mut model = Self {
            vertex_k: vec![Mat3::ZERO; n],
            edge_k: vec![Mat3::ZERO; topo.edges().len()],
            mass_kg: vec![0.0; n],
            damping_kg_s: vec![0.0; n],
            mesh,
            materials,
            topo,
            membrane: None,
            attached: Vec::new(),
            orphans: Orphans::default(),
            topology_changes: 0,
            element_lambdas: std::sync::OnceLock::new(),
        };
        for t in 0..model.mesh.tet_count() {
            model.accumulate(TetId::from(t), 1.0);
        }
        Ok(model)
    }

    /// Adds the surface membrane (paper 3.7) on the current surface. With
    /// [`MembraneModel::Linear`] its springs are folded into the tensors here.
    pub fn with_membrane(
        self,
        alpha_n_per_m2: Real,
        model: MembraneModel,
    ) -> Result<Self, ModelError> {
        self.with_membrane_on(alpha_n_per_m2, model, |_, _| true)
    }

    /// Adds the membrane on the surface faces `keep` accepts (see
    /// [`Membrane::on_faces`]).
    pub fn with_membrane_on(
        mut self,
        alpha_n_per_m2: Real,
        model: MembraneModel,
        keep: impl Fn(TetId, usize) -> bool,
    ) -> Result<Self, ModelError> {
        if !(alpha_n_per_m2.is_finite() && alpha_n_per_m2 >= 0.0) {
            return Err(ModelError::MembraneAlpha(alpha_n_per_m2));
        }
        assert!(self.membrane.is_none(), "the membrane is set once");
        let membrane = Membrane::on_faces(&self.mesh, &self.topo, alpha_n_per_m2, model, keep);
        if model == MembraneModel::Linear {
            let rest = self.mesh.positions_m();
            for (e, &k) in membrane.stiffness_n_per_m().iter().enumerate() {
                if k != 0.0 {
                    let [a, b] = self.topo.edges()[e];
                    let t = Membrane::linear_tensor(rest, a, b, k);
                    self.vertex_k[a.idx()] += t;
                    self.vertex_k[b.idx()] += t;
                    self.edge_k[e] -= t;
                }
            }
        }
        self.membrane = Some(membrane);
        // The capsule springs belong to their tetrahedra's elements.
        self.element_lambdas = std::sync::OnceLock::new();
        Ok(self)
    }

    /// Adds mass (kg) and damping (kg/s) to vertex `v` from outside the
    /// model: a hybrid gives the vertices it shares with its static part
    /// that part's share, so they keep their inertia (and the explicit
    /// bound of the whole body holds) even once cuts orphan them here.
    pub fn attach_mass(&mut self, v: VertexId, mass_kg: Real, damping_kg_s: Real) {
        if self.attached.is_empty() {
            self.attached = vec![(0.0, 0.0); self.mass_kg.len()];
        }
        self.attached[v.idx()].0 += mass_kg;
        self.attached[v.idx()].1 += damping_kg_s;
        self.mass_kg[v.idx()] += mass_kg;
        self.damping_kg_s[v.idx()] += damping_kg_s;
    }

    /// Counts removals and restorations: a reader that cached something
    /// derived from the topology (the surface vertex set) rebuilds it only
    /// when this changes.
    pub fn topology_changes(&self) -> u64 {
        self.topology_changes
    }

    /// The membrane, if the model has one.
    pub fn membrane(&self) -> Option<&Membrane> {
        self.membrane.as_ref()
    }

    /// Adds or removes the capsule faces of `t` (after its element
    /// contribution), folding linear springs into the tensors.
    fn accumulate_membrane(&mut self, t: TetId, sign: Real) {
        let Some(membrane) = self.membrane.as_mut() else {
            return;
        };
        let delta = membrane.apply_tet(&self.topo, t, sign);
        if membrane.model() == MembraneModel::Linear {
            let rest = self.mesh.positions_m();
            for (l, e) in self.topo.tet_edges(t).iter().enumerate() {
                if delta[l] != 0.0 {
                    let [a, b] = self.topo.edges()[e.idx()];
                    let m = Membrane::linear_tensor(rest, a, b, delta[l]);
                    self.vertex_k[a.idx()] += m;
                    self.vertex_k[b.idx()] += m;
                    self.edge_k[e.idx()] -= m;
                }
            }
        }
    }

    /// The same model with every material's strain model set to `model`
    /// (the assembled linear tensors do not depend on it).
    pub fn with_model(mut self, model: crate::material::MaterialModel) -> Self {
        self.materials = self.materials.with_model(model);
        self
    }

    /// Live tetrahedra with a nonlinear material model.
    pub fn nonlinear_tets(&self) -> usize {
        (0..self.mesh.tet_count())
            .map(TetId::from)
            .filter(|t| {
                self.topo.is_alive(*t) && self.materials.material(*t).model().is_nonlinear()
            })
            .count()
    }

    /// Refuses (naming `who` and `why`) when a live tetrahedron that
    /// `in_part` accepts has a nonlinear material model.
    pub fn require_linear(
        &self,
        who: &'static str,
        why: &'static str,
        in_part: impl Fn(TetId) -> bool,
    ) -> Result<(), LinearOnly> {
        let mut found = (0..self.mesh.tet_count())
            .map(TetId::from)
            .filter(|t| self.topo.is_alive(*t) && in_part(*t))
            .map(|t| self.materials.material(t).model())
            .filter(|m| m.is_nonlinear());
        let Some(first) = found.next() else {
            return Ok(());
        };
        Err(LinearOnly {
            who,
            why,
            tets: 1 + found.count(),
            model: first.name(),
        })
    }

    /// The constants and geometry of tetrahedron `t`.
    pub fn element(&self, t: TetId) -> (TetElastic, Geometry) {
        let elastic = TetElastic::new(self.materials.material(t), self.materials.fiber(t));
        (elastic, Geometry::new(self.mesh.tet_points(t)))
    }

    /// Adds (`sign` = 1) or subtracts (-1) the contribution of `t` to its 4
    /// vertex tensors, 6 edge tensors, masses and damping: the paper's 10
    /// local updates.
    fn accumulate(&mut self, t: TetId, sign: Real) {
        let (elastic, geom) = self.element(t);
        let tet = self.mesh.tets()[t.idx()];
        for (k, v) in tet.iter().enumerate() {
            self.vertex_k[v.idx()] += elastic.block(&geom, k, k) * sign;
        }
        let edges = self.topo.tet_edges(t);
        for (l, [i, j]) in TET_EDGES.iter().enumerate() {
            // Edge tensors are stored as K_ab with a < b in vertex numbering.
            let block = if tet[*i] < tet[*j] {
                elastic.block(&geom, *i, *j)
            } else {
                elastic.block(&geom, *j, *i)
            };
            self.edge_k[edges[l].idx()] += block * sign;
        }
        let material = self.materials.material(t);
        let quarter_mass = material.density_kg_m3() * geom.volume_m3 / 4.0;
        for v in tet {
            self.mass_kg[v.idx()] += sign * quarter_mass;
            self.damping_kg_s[v.idx()] += sign * material.damping_per_s() * quarter_mass;
        }
    }

    fn check_tet(&self, t: TetId) -> Result<(), CutError> {
        if t.idx() < self.mesh.tet_count() {
            Ok(())
        } else {
            Err(CutError::NoSuchTet(t.0))
        }
    }

    fn change(&self, t: TetId) -> CutChange {
        CutChange {
            tet: t,
            vertices: self.mesh.tets()[t.idx()],
            edges: self.topo.tet_edges(t),
        }
    }

    /// Removes tetrahedron `t`: subtracts its contribution, zeroes the tensors
    /// of edges and vertices it leaves orphaned (so no round-off residue
    /// remains) and updates the surface.
    pub fn remove_tet(&mut self, t: TetId) -> Result<CutChange, CutError> {
        self.check_tet(t)?;
        if !self.topo.is_alive(t) {
            return Err(CutError::AlreadyRemoved(t.0));
        }
        self.accumulate(t, -1.0);
        self.accumulate_membrane(t, -1.0);
        let mut orphans = std::mem::take(&mut self.orphans);
        self.topo.remove(t, self.mesh.tets()[t.idx()], &mut orphans);
        for e in &orphans.edges {
            self.edge_k[e.idx()] = Mat3::ZERO;
        }
        for v in &orphans.vertices {
            let (m, c) = self.attached.get(v.idx()).copied().unwrap_or_default();
            self.vertex_k[v.idx()] = Mat3::ZERO;
            self.mass_kg[v.idx()] = m;
            self.damping_kg_s[v.idx()] = c;
        }
        self.orphans = orphans;
        self.topology_changes += 1;
        Ok(self.change(t))
    }

    /// Adds a removed tetrahedron back.
    pub fn restore_tet(&mut self, t: TetId) -> Result<CutChange, CutError> {
        self.check_tet(t)?;
        if self.topo.is_alive(t) {
            return Err(CutError::AlreadyPresent(t.0));
        }
        self.topo.revive(t, self.mesh.tets()[t.idx()]);
        self.accumulate(t, 1.0);
        self.accumulate_membrane(t, 1.0);
        self.topology_changes += 1;
        Ok(self.change(t))
    }

    /// Elastic forces F = -K U (N) for displacements `u` (m), by a plain loop
    /// over the vertex and edge tensors in double precision. This includes a
    /// linear membrane (folded into K) but not a nonlinear one: see
    /// [`ElasticModel::membrane_forces`].
    pub fn elastic_forces(&self, u: &[Vec3], out: &mut [Vec3]) {
        assert_eq!(u.len(), self.vertex_count());
        assert_eq!(out.len(), self.vertex_count());
        for (f, (k, ui)) in out.iter_mut().zip(self.vertex_k.iter().zip(u)) {
            *f = -(*k * *ui);
        }
        for ([a, b], k) in self.topo.edges().iter().zip(&self.edge_k) {
            out[a.idx()] -= *k * u[b.idx()];
            out[b.idx()] -= k.transpose() * u[a.idx()];
        }
    }

    /// Adds the nonlinear membrane's forces (eq 29) at displacements `u` to
    /// `out`; nothing for a linear membrane (already in K) or none.
    pub fn membrane_forces(&self, u: &[[Real; 3]], out: &mut [[Real; 3]]) {
        if let Some(m) = &self.membrane
            && m.model() == MembraneModel::Nonlinear
        {
            m.add_forces(u, out);
        }
    }

    /// Total energy (J) of displacements `u`: the live tetrahedra's strain
    /// energy (computed from their strains, independent of the assembled
    /// tensors) plus the membrane's spring energy in its model.
    pub fn energy_j(&self, u: &[Vec3]) -> Real {
        let membrane = self
            .membrane
            .as_ref()
            .map_or(0.0, |m| m.energy_j(&self.topo, self.mesh.positions_m(), u));
        membrane + self.strain_energy_j(u)
    }

    /// Strain energy (J) of the live tetrahedra alone, each in its
    /// material's model (linear, StVK, corotational).
    pub fn strain_energy_j(&self, u: &[Vec3]) -> Real {
        (0..self.mesh.tet_count())
            .map(TetId::from)
            .filter(|t| self.topo.is_alive(*t))
            .map(|t| {
                let (elastic, geom) = self.element(t);
                let ut = self.mesh.tets()[t.idx()].map(|v| u[v.idx()]);
                match self.materials.material(t).model() {
                    crate::material::MaterialModel::Linear => elastic.energy_j(&geom, ut),
                    model => super::nonlinear::element_energy_j(
                        model,
                        &elastic,
                        &geom,
                        &ut,
                        &mut glam::DQuat::default(),
                    ),
                }
            })
            .sum()
    }

    /// The rest mesh.
    pub fn mesh(&self) -> &TetMesh {
        &self.mesh
    }

    /// The material map.
    pub fn materials(&self) -> &TetMaterials {
        &self.materials
    }

    /// Live topology and surface.
    pub fn topology(&self) -> &Topology {
        &self.topo
    }

    /// Number of vertices (including orphans).
    pub fn vertex_count(&self) -> usize {
        self.mesh.vertex_count()
    }

    /// K_ii of every vertex.
    pub fn vertex_tensors(&self) -> &[Mat3] {
        &self.vertex_k
    }

    /// K_ab (a < b) of every edge, in [`Topology::edges`] order.
    pub fn edge_tensors(&self) -> &[Mat3] {
        &self.edge_k
    }

    /// Lumped masses (kg); zero for orphaned vertices.
    pub fn masses_kg(&self) -> &[Real] {
        &self.mass_kg
    }

    /// Damping coefficients c_i (kg/s).
    pub fn damping_kg_s(&self) -> &[Real] {
        &self.damping_kg_s
    }

    /// The full stiffness as a dense 3n x 3n row-major matrix (tests and small meshes only).
    pub fn dense_stiffness(&self) -> Vec<Real> {
        let n3 = 3 * self.vertex_count();
        let mut k = vec![0.0; n3 * n3];
        let mut put = |a: usize, b: usize, m: &Mat3| {
            for r in 0..3 {
                for c in 0..3 {
                    k[(3 * a + r) * n3 + 3 * b + c] += m.col(c)[r];
                }
            }
        };
        for (v, m) in self.vertex_k.iter().enumerate() {
            put(v, v, m);
        }
        for ([a, b], m) in self.topo.edges().iter().zip(&self.edge_k) {
            put(a.idx(), b.idx(), m);
            put(b.idx(), a.idx(), &m.transpose());
        }
        k
    }
}
