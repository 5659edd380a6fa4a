//! The hybrid backend (paper 3.5, after Cotin et al.): a large precomputed
//! part joined to a smaller tensor-mass part that can be cut, exchanging
//! positions and forces at the vertices they share.
//!
//! Each sub-step the tensor-mass part's shared vertices give their
//! displacements u_I to the precomputed part, which returns the force it
//! exerts on them, F_I = -S u_I + H^T f (its stiffness condensed on the
//! shared vertices plus what its loads and tool holds transmit; see
//! [`static_part`]); the explicit integrator then advances the tensor-mass
//! part with F_I as an external force. The precomputed part is massless and
//! static, so this coupling is exact: at rest the hybrid is the static
//! solution of the whole body. The shared vertices carry the whole body's
//! lumped mass (the precomputed part's share attached), so the element bound
//! of the whole mesh is a proven stable step for the coupled system (its
//! condensed stiffness is bounded by the uncondensed one); a second proven
//! bound (the tensor-mass part's elements plus the condensed stiffness over
//! the attached mass) is used when larger, e.g. when the stiffest elements
//! are precomputed.
//!
//! Cuts are confined to the tensor-mass part; a tetrahedron of the
//! precomputed part is refused with a message naming the region. The
//! precomputed part uses the membrane's linearisation.
//!
//! ```
//! use tissue::backend::{Backend, Hybrid, HybridConfig};
//! use tissue::prelude::*;
//! let mesh = BoxSpec::new(Vec3::new(0.04, 0.02, 0.02), CellSize::EdgeM(0.005)).generate().unwrap();
//! let tissue = Material::isotropic(5000.0, 0.45, 1000.0, 5.0).unwrap();
//! let model = ElasticModel::new(mesh.clone(), TetMaterials::uniform(tissue, mesh.tet_count())).unwrap();
//! let wall: Vec<VertexId> = (0..mesh.vertex_count())
//!     .filter(|&v| mesh.positions_m()[v].x < 1e-9).map(VertexId::from).collect();
//! // The free end (x > 3 cm) is tensor-mass and can be cut; the rest is precomputed.
//! let cuttable: Vec<TetId> = (0..mesh.tet_count()).map(TetId::from)
//!     .filter(|t| mesh.tet_points(*t)[0].x > 0.03).collect();
//! let mut sim = Hybrid::new(model, &wall, &cuttable, HybridConfig::new(0.001), |_, _| {}).unwrap();
//! sim.set_external_force(VertexId(mesh.vertex_count() as u32 - 1), Vec3::new(0.0, 0.0, -0.01));
//! sim.step();
//! assert!(sim.remove_tet(cuttable[0]).is_ok());
//! ```

mod static_part;

use super::{Backend, Capabilities};
use crate::ids::{TetId, VertexId};
use crate::math::{Real, Vec3};
use crate::membrane::MembraneModel;
use crate::static_solve::StaticError;
use crate::tensor_mass::{
    CutChange, CutError, DtPolicy, ElasticModel, Explicit, ExplicitConfig, ExplicitError,
    StableStep, SubmodelError, element_bound, substeps_for,
};
use static_part::StaticPart;
use std::path::PathBuf;
use thiserror::Error;

const NONE: u32 = u32::MAX;

/// Hybrid settings.
#[derive(Clone, Debug, PartialEq)]
pub struct HybridConfig {
    /// The step per [`Backend::step`] (s).
    pub dt_s: Real,
    /// Above the whole body's stable step: sub-step (default) or refuse.
    pub policy: DtPolicy,
    /// Where the precomputed part's responses are cached (none: not cached).
    pub cache_dir: Option<PathBuf>,
}

impl HybridConfig {
    /// Sub-stepping, no cache.
    pub fn new(dt_s: Real) -> Self {
        Self {
            dt_s,
            policy: DtPolicy::Substep,
            cache_dir: None,
        }
    }
}

/// Why the hybrid could not be set up.
#[derive(Debug, Error)]
pub enum HybridError {
    /// The tensor-mass region is empty or covers the whole body.
    #[error(
        "the tensor-mass region selects {selected} of {total} tetrahedra; a hybrid needs both parts (use the tensor-mass or precomputed backend instead)"
    )]
    Split {
        /// Tetrahedra selected.
        selected: usize,
        /// In the body.
        total: usize,
    },
    /// A part could not be made.
    #[error("cannot split the body: {0}")]
    Part(SubmodelError),
    /// The precomputed part could not be factorized.
    #[error("precomputed part: {0}")]
    Static(StaticError),
    /// The precomputed part is too large to keep its responses.
    #[error("precomputed part: {0}")]
    TooLarge(super::cache::TooManyResponses),
    /// The tensor-mass part's integrator refused.
    #[error("tensor-mass part: {0}")]
    Explicit(ExplicitError),
}

// The part's error is in the message, not a separate `source()`, so that
// a chain of causes (anyhow's "Caused by") does not say it twice.
impl From<SubmodelError> for HybridError {
    fn from(e: SubmodelError) -> Self {
        Self::Part(e)
    }
}
impl From<StaticError> for HybridError {
    fn from(e: StaticError) -> Self {
        Self::Static(e)
    }
}
impl From<super::cache::TooManyResponses> for HybridError {
    fn from(e: super::cache::TooManyResponses) -> Self {
        Self::TooLarge(e)
    }
}
impl From<ExplicitError> for HybridError {
    fn from(e: ExplicitError) -> Self {
        Self::Explicit(e)
    }
}

/// The hybrid backend.
pub struct Hybrid {
    full: ElasticModel,
    tm: Explicit<f64>,
    part: StaticPart,
    /// Local vertex in each part, per body vertex (NONE: not in it).
    tm_of: Vec<u32>,
    part_of: Vec<u32>,
    /// Body vertex of each local vertex.
    tm_vertices: Vec<VertexId>,
    part_vertices: Vec<VertexId>,
    /// Tensor-mass tetrahedron of each body tetrahedron (NONE: precomputed).
    tm_tet: Vec<u32>,
    /// Shared (free) vertices: tensor-mass local index, and the external
    /// force the scene puts on them.
    shared_tm: Vec<u32>,
    /// Per tensor-mass local vertex: its index in `shared_tm` (NONE: not
    /// shared).
    shared_of_tm: Vec<u32>,
    shared_fext: Vec<Vec3>,
    u: Vec<[Real; 3]>,
    u_shared: Vec<Vec3>,
    f_shared: Vec<Vec3>,
    u_part: Vec<Vec3>,
    stable: StableStep,
    dt_s: Real,
    substeps: usize,
}

impl Hybrid {
    /// Refuses nonlinear material models in the precomputed part (the
    /// tetrahedra `in_tm` does not accept); the scene checks with this too.
    pub fn check_model(
        model: &ElasticModel,
        in_tm: impl Fn(TetId) -> bool,
    ) -> Result<(), crate::tensor_mass::LinearOnly> {
        model.require_linear(
            "hybrid backend's precomputed part",
            "its responses are solved once for the linear stiffness; [hybrid] select must cover the nonlinear tetrahedra",
            |t| !in_tm(t),
        )
    }

    /// Splits `model` into the tensor-mass part `tm_tets` (cuttable) and a
    /// precomputed rest with `fixed` held at rest, and precomputes the rest
    /// (`progress` gets (done, total) solves).
    pub fn new(
        model: ElasticModel,
        fixed: &[VertexId],
        tm_tets: &[TetId],
        config: HybridConfig,
        progress: impl FnMut(usize, usize),
    ) -> Result<Self, HybridError> {
        let dt_s = config.dt_s;
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(ExplicitError::BadDt(dt_s).into());
        }
        let total = model.topology().alive_count();
        let mut is_tm = vec![false; model.mesh().tet_count()];
        for t in tm_tets {
            if let Some(x) = is_tm.get_mut(t.idx()) {
                *x = true;
            }
        }
        let tm_list: Vec<TetId> = (0..is_tm.len())
            .map(TetId::from)
            .filter(|t| is_tm[t.idx()] && model.topology().is_alive(*t))
            .collect();
        let part_list: Vec<TetId> = (0..is_tm.len())
            .map(TetId::from)
            .filter(|t| !is_tm[t.idx()] && model.topology().is_alive(*t))
            .collect();
        Self::check_model(&model, |t| is_tm[t.idx()]).map_err(StaticError::from)?;
        if tm_list.is_empty() || part_list.is_empty() {
            return Err(HybridError::Split {
                selected: tm_list.len(),
                total,
            });
        }
        let n = model.vertex_count();
        let mut tm = model.submodel(&tm_list, None)?;
        let part = model.submodel(&part_list, Some(MembraneModel::Linear))?;
        let local = |vs: &[VertexId]| {
            let mut of = vec![NONE; n];
            for (l, v) in vs.iter().enumerate() {
                of[v.idx()] = l as u32;
            }
            of
        };
        let (tm_of, part_of) = (local(&tm.vertices), local(&part.vertices));
        let mut is_fixed = vec![false; n];
        for v in fixed {
            is_fixed[v.idx()] = true;
        }
        let shared: Vec<VertexId> = (0..n)
            .map(VertexId::from)
            .filter(|v| tm_of[v.idx()] != NONE && part_of[v.idx()] != NONE && !is_fixed[v.idx()])
            .collect();
        // The shared vertices carry the precomputed part's share of mass.
        let mut shared_mass = Vec::with_capacity(shared.len());
        for v in &shared {
            let l = part_of[v.idx()] as usize;
            let (m, c) = (part.model.masses_kg()[l], part.model.damping_kg_s()[l]);
            tm.model.attach_mass(VertexId(tm_of[v.idx()]), m, c);
            shared_mass.push(m);
        }
        let to_part = |v: &VertexId| VertexId(part_of[v.idx()]);
        let part_fixed: Vec<VertexId> = fixed
            .iter()
            .filter(|v| part_of[v.idx()] != NONE)
            .map(to_part)
            .collect();
        let part_shared: Vec<VertexId> = shared.iter().map(to_part).collect();
        let static_part = StaticPart::new(
            &part.model,
            &part_fixed,
            &part_shared,
            config.cache_dir.as_deref(),
            progress,
        )?;
        // Two proven bounds on omega_max^2; the smaller wins. The whole
        // body's element bound (the condensed stiffness is below the
        // uncondensed one, the masses are the whole body's), and, by Weyl's
        // inequality, the tensor-mass part's element bound plus a Gershgorin
        // bound of the condensed stiffness over the precomputed part's share
        // of mass alone. Both survive cuts (elements only leave; the shared
        // vertices never weigh less than that share), and the second lets
        // the step grow when the stiff elements are in the precomputed part.
        let whole = element_bound(&model);
        let split = element_bound(&tm.model).omega_max_rad_s.powi(2)
            + static_part.condensed_lambda(&shared_mass);
        let stable = if split < whole.omega_max_rad_s.powi(2) {
            StableStep::from_lambda(split, whole.method)
        } else {
            whole
        };
        let substeps = substeps_for(dt_s, &stable, config.policy)?;
        // The bound is the coupled system's, checked above: the part's own
        // (without the condensed stiffness) must not sub-step it again.
        let mut explicit = Explicit::new(
            tm.model,
            ExplicitConfig {
                dt_s: dt_s / substeps as Real,
                policy: DtPolicy::Unchecked,
                ..ExplicitConfig::new(dt_s)
            },
        )?;
        for v in fixed {
            if tm_of[v.idx()] != NONE {
                explicit.fix(VertexId(tm_of[v.idx()]));
            }
        }
        let mut tm_tet = vec![NONE; is_tm.len()];
        for (l, t) in tm.tets.iter().enumerate() {
            tm_tet[t.idx()] = l as u32;
        }
        let ni = shared.len();
        let shared_tm: Vec<u32> = shared.iter().map(|v| tm_of[v.idx()]).collect();
        let mut shared_of_tm = vec![NONE; tm.vertices.len()];
        for (i, &l) in shared_tm.iter().enumerate() {
            shared_of_tm[l as usize] = i as u32;
        }
        Ok(Self {
            tm: explicit,
            part: static_part,
            shared_tm,
            shared_of_tm,
            shared_fext: vec![Vec3::ZERO; ni],
            tm_of,
            part_of,
            tm_vertices: tm.vertices,
            u_part: vec![Vec3::ZERO; part.vertices.len()],
            part_vertices: part.vertices,
            tm_tet,
            u: vec![[0.0; 3]; n],
            u_shared: vec![Vec3::ZERO; ni],
            f_shared: vec![Vec3::ZERO; ni],
            stable,
            dt_s,
            substeps,
            full: model,
        })
    }

    /// Whether the responses came from the disk cache.
    pub fn from_cache(&self) -> bool {
        self.part.from_cache
    }

    /// Vertices shared by the two parts (free ones).
    pub fn shared_len(&self) -> usize {
        self.shared_tm.len()
    }

    /// Tetrahedra in the tensor-mass part (cut ones included).
    pub fn tensor_mass_tets(&self) -> usize {
        self.tm.model().mesh().tet_count()
    }

    /// Force sources of the precomputed part (its free surface vertices).
    pub fn precomputed_sources(&self) -> usize {
        self.part.source_count()
    }

    /// Whether a displacement can be imposed on, or a force applied to,
    /// `v`: any vertex of the tensor-mass part, or a free surface vertex of
    /// the precomputed part (its responses cover forces on the surface only).
    pub fn can_load(&self, v: VertexId) -> bool {
        match (self.tm_of.get(v.idx()), self.part_of.get(v.idx())) {
            (Some(&l), _) if l != NONE => true,
            (_, Some(&p)) if p != NONE => self.part.is_source(p as usize),
            _ => false,
        }
    }

    /// The whole body's stable step (enforced).
    pub fn stable_step(&self) -> StableStep {
        self.stable
    }

    /// Sub-steps per step.
    pub fn substeps(&self) -> usize {
        self.substeps
    }

    /// The tensor-mass part's integrator.
    pub fn tensor_mass(&self) -> &Explicit<f64> {
        &self.tm
    }

    fn gather_shared(&mut self) {
        for (u, &l) in self.u_shared.iter_mut().zip(&self.shared_tm) {
            *u = self.tm.displacement(VertexId(l));
        }
    }
}

impl Backend for Hybrid {
    fn capabilities(&self) -> Capabilities {
        Capabilities::dynamic("hybrid")
    }
    fn on_step_workers(&self, f: &(dyn Fn() + Sync)) -> usize {
        self.tm.on_step_workers(f)
    }
    fn large_strain(&self) -> Option<crate::tensor_mass::large_strain::PassReport> {
        self.tm.large_strain().map(|l| l.last())
    }
    /// The tensor-mass part's nonlinear force at `v` (its elements are the
    /// only nonlinear ones: the precomputed part is refused otherwise). A
    /// correction is the same in the whole body's terms; a whole force
    /// covers the tensor-mass elements only, so at a vertex shared with
    /// the precomputed part that part's force there is added (at a fixed
    /// one, which the precomputed part does not report, `None`: the
    /// linear force). Before, a hybrid gave `None` everywhere and a tool
    /// holding nonlinear tissue felt the linear -(K U).
    fn nonlinear_force_n(
        &self,
        v: VertexId,
    ) -> Option<crate::tensor_mass::large_strain::VertexForce> {
        use crate::tensor_mass::large_strain::VertexForce;
        let l = *self.tm_of.get(v.idx())?;
        if l == NONE {
            return None;
        }
        match self.tm.nonlinear_force_n(VertexId(l))? {
            VertexForce::Whole(f) if self.part_of[v.idx()] != NONE => {
                let i = self.shared_of_tm[l as usize];
                if i == NONE {
                    return None;
                }
                Some(VertexForce::Whole(f + self.f_shared[i as usize]))
            }
            force => Some(force),
        }
    }
    fn model(&self) -> &ElasticModel {
        &self.full
    }
    fn dt_s(&self) -> Real {
        self.dt_s
    }

    fn step(&mut self) {
        for _ in 0..self.substeps {
            self.gather_shared();
            self.part.shared_forces(&self.u_shared, &mut self.f_shared);
            for ((&l, f), fext) in self
                .shared_tm
                .iter()
                .zip(&self.f_shared)
                .zip(&self.shared_fext)
            {
                self.tm.set_external_force(VertexId(l), *f + *fext);
            }
            self.tm.step();
        }
        self.gather_shared();
        self.part.displacements(&self.u_shared, &mut self.u_part);
        for (v, u) in self.part_vertices.iter().zip(&self.u_part) {
            self.u[v.idx()] = u.to_array();
        }
        for (v, u) in self.tm_vertices.iter().zip(self.tm.displacements()) {
            self.u[v.idx()] = *u;
        }
    }

    fn displacement(&self, v: VertexId) -> Vec3 {
        Vec3::from_array(self.u[v.idx()])
    }
    fn displacements(&self) -> &[[Real; 3]] {
        &self.u
    }
    fn prescribe(&mut self, v: VertexId, d_m: Vec3) {
        match (self.tm_of[v.idx()], self.part_of[v.idx()]) {
            (NONE, NONE) => {}
            (NONE, p) => self.part.hold(p as usize, Some(d_m)),
            (l, _) => self.tm.prescribe(VertexId(l), d_m),
        }
    }
    fn release(&mut self, v: VertexId) {
        match (self.tm_of[v.idx()], self.part_of[v.idx()]) {
            (NONE, NONE) => {}
            (NONE, p) => self.part.hold(p as usize, None),
            (l, _) => self.tm.release(VertexId(l)),
        }
    }
    fn set_external_force(&mut self, v: VertexId, f_n: Vec3) {
        match (self.tm_of[v.idx()], self.part_of[v.idx()]) {
            (NONE, NONE) => {}
            (NONE, p) => self.part.set_force(p as usize, f_n),
            (l, NONE) => self.tm.set_external_force(VertexId(l), f_n),
            (l, _) => match self.shared_of_tm[l as usize] {
                // A fixed shared vertex: the force goes to the support.
                NONE => self.tm.set_external_force(VertexId(l), f_n),
                i => self.shared_fext[i as usize] = f_n,
            },
        }
    }
    fn can_cut(&self, t: TetId) -> bool {
        self.tm_tet.get(t.idx()).is_some_and(|&l| l != NONE)
    }
    fn remove_tet(&mut self, t: TetId) -> Result<CutChange, CutError> {
        if t.idx() >= self.tm_tet.len() {
            return Err(CutError::NoSuchTet(t.0));
        }
        if !self.full.topology().is_alive(t) {
            return Err(CutError::AlreadyRemoved(t.0));
        }
        let l = self.tm_tet[t.idx()];
        if l == NONE {
            return Err(CutError::Unsupported {
                backend: "hybrid",
                why: "this tetrahedron is in the precomputed part; cuts are confined to the tensor-mass region the scene's [hybrid] section selects",
            });
        }
        self.tm.remove_tet(TetId(l))?;
        self.full.remove_tet(t)
    }
}

#[cfg(test)]
mod tests;
