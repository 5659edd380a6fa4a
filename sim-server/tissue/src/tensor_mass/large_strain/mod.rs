//! The nonlinear (StVK, corotational) elements of an explicit simulation:
//! per-element rest data packed once, a force pass every sub-step, and the
//! bound of the current tangent for the stable step.
//!
//! In a model with linear elements the hot kernel keeps the linear
//! tensors of *every* element (so contact stiffness, the rest bound and
//! cutting stay as they are) and for each nonlinear element this pass adds
//! the difference between its nonlinear force and its linear one,
//! -V (P - sigma_lin) m_k. When every element is nonlinear the kernel
//! carries no element tensors (only a linear capsule membrane's springs,
//! if the model has one: [`super::Kernel::beside_whole_forces`]) and the
//! pass computes the whole force, -V P m_k
//! ([`LargeStrain::computing_whole_forces`]). On several threads the pass
//! writes each element's four forces to its own slots (threads own element
//! ranges, no atomics), then one sequential sweep adds the slots to their
//! vertices in element order: every vertex sums its forces in the same
//! order whatever the thread count, and the sweep reads the slots as they
//! lie in memory (a per-vertex gather read them across the array and, past
//! the cache at 1M tetrahedra, cost more than the elements). One task of
//! eight f32 lanes on an AVX2 CPU skips the slots: each block's forces go
//! straight to per-vertex accumulators in the same order (the same sums
//! to the bit; `lanes::avx2`).

use super::corotational_lanes::Q;
use super::element::{Geometry, TetElastic};
pub use super::kernel::LanePrecision;
use super::kernel::V3;
use super::lanes::Scalar;
use super::model::ElasticModel;
use super::nonlinear::{Law, barrier_piola, deformation_gradient, first_piola, in_barrier};
use crate::ids::TetId;
use crate::material::MaterialModel;
use crate::math::{Mat3, Real, Vec3};
use glam::DQuat;
use lane_set::{Block, BlockForces, LaneSet};

/// Elements per task below which a range is not split further.
const MIN_ELEMENTS_PER_TASK: usize = 2048;

/// One nonlinear element's rest data.
#[derive(Clone, Debug)]
struct Element {
    vertices: [u32; 4],
    geom: Geometry,
    elastic: TetElastic,
    model: MaterialModel,
    /// Irons' rest bound of the element, lambda_max(K_e, M_e) (1/s^2).
    rest_lambda: Real,
    /// V sum_k |m_k|^2 / (rho V / 4) (1/(s^2 Pa)): times a stress, a bound
    /// on the geometric term's contribution to lambda.
    geometric_per_pa: Real,
}

/// The nonlinear pass's force at one vertex after the last pass (N).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VertexForce {
    /// To be added to the linear force -(K U) there (models with linear
    /// elements or a linear capsule: the step keeps the linear tensors).
    Correction(Vec3),
    /// The whole elastic force there (every element nonlinear).
    Whole(Vec3),
}

/// What one pass found, besides the forces.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PassReport {
    /// Upper estimate of lambda_max(M^-1 K_T) over the nonlinear elements at
    /// the state the pass saw (1/s^2).
    pub lambda: Real,
    /// StVK elements compressed into the volume barrier (det F below
    /// [`super::nonlinear::STVK_BARRIER_J`]).
    pub collapsed: usize,
}

impl PassReport {
    fn join(self, other: Self) -> Self {
        Self {
            lambda: self.lambda.max(other.lambda),
            collapsed: self.collapsed + other.collapsed,
        }
    }
}

/// The nonlinear elements of a model and their per-step buffers.
#[derive(Clone, Debug)]
pub struct LargeStrain {
    elements: Vec<Element>,
    /// Per element: whether its tetrahedron is in the mesh.
    alive: Vec<bool>,
    /// Elements kN..(k+1)N as lanes, their forces and (corotational
    /// blocks) their rotations.
    lanes: Lanes,
    /// Per element: the rotation of a corotational element in a scalar
    /// block (mixed models, or the short last block); lane blocks keep
    /// theirs in [`LaneSet`]'s `quats`.
    rotations: Vec<DQuat>,
    /// Index of each tetrahedron's element (u32::MAX: linear).
    element_of: Vec<u32>,
    /// Vertices touched (their sums are overwritten).
    vertices: Vec<u32>,
    /// The pass computes each element's whole elastic force, not its
    /// difference from the linear one (see [`LargeStrain::computing_whole_forces`]).
    whole: bool,
    last: PassReport,
}

impl LargeStrain {
    /// The nonlinear elements of `model` in f64 lanes of four, or `None`
    /// when it has none (a linear scene pays nothing).
    pub fn new(model: &ElasticModel) -> Option<Self> {
        Self::with_precision(model, LanePrecision::F64)
    }

    /// The same in lanes of `precision` (f32: eight to a 256-bit register,
    /// half the rest data; the explicit step with f32 storage).
    pub fn with_precision(model: &ElasticModel, precision: LanePrecision) -> Option<Self> {
        Self::with_region(model, precision, &[])
    }

    /// [`LargeStrain::with_precision`] with the linear tetrahedra flagged
    /// in `corotational` (per tetrahedron; missing: false) made
    /// corotational too: the region round a tool that follows it (a
    /// linear surface wrapped round a narrow tip slips off it; the
    /// corotational one holds).
    pub fn with_region(
        model: &ElasticModel,
        precision: LanePrecision,
        corotational: &[bool],
    ) -> Option<Self> {
        let mesh = model.mesh();
        let model_of = |t: TetId| match model.materials().material(t).model() {
            MaterialModel::Linear if corotational.get(t.idx()) == Some(&true) => {
                MaterialModel::Corotational
            }
            m => m,
        };
        let mut element_of = vec![u32::MAX; mesh.tet_count()];
        let mut elements = Vec::new();
        let mut alive = Vec::new();
        // By model (StVK, then corotational), so that they fill whole blocks of
        // lanes; within a model by their lowest vertex, so that the elements
        // around a vertex sit together in memory (the vertices are in RCM
        // order): the pass reads displacements and the sweep adds element
        // forces to vertices nearly in sequence instead of across the mesh.
        let of_model = |m: MaterialModel| {
            let mut ts: Vec<TetId> = (0..mesh.tet_count())
                .map(TetId::from)
                .filter(|t| model_of(*t) == m)
                .collect();
            ts.sort_by_key(|t| mesh.tets()[t.idx()].iter().map(|v| v.0).min());
            ts
        };
        let stvk_first = of_model(MaterialModel::Stvk)
            .into_iter()
            .chain(of_model(MaterialModel::Corotational));
        for t in stvk_first {
            let material = model.materials().material(t);
            let (elastic, geom) = model.element(t);
            let quarter_mass = material.density_kg_m3() * geom.volume_m3 / 4.0;
            let shape2: Real = geom.shape.iter().map(|m| m.length_squared()).sum();
            element_of[t.idx()] = elements.len() as u32;
            elements.push(Element {
                vertices: mesh.tets()[t.idx()].map(|v| v.0),
                geom,
                elastic,
                model: model_of(t),
                rest_lambda: model.element_lambdas()[t.idx()],
                geometric_per_pa: geom.volume_m3 * shape2 / quarter_mass,
            });
            alive.push(model.topology().is_alive(t));
        }
        if elements.is_empty() {
            return None;
        }
        let mut count = vec![0u32; mesh.vertex_count()];
        for e in &elements {
            for v in e.vertices {
                count[v as usize] += 1;
            }
        }
        let vertices: Vec<u32> = (0..count.len() as u32)
            .filter(|v| count[*v as usize] > 0)
            .collect();
        let lanes = match precision {
            LanePrecision::F64 => Lanes::F64(LaneSet::of(&elements)),
            LanePrecision::F32 => Lanes::F32(LaneSet::of(&elements)),
        };
        Some(Self {
            lanes,
            rotations: vec![DQuat::IDENTITY; elements.len()],
            alive,
            elements,
            element_of,
            vertices,
            whole: false,
            last: PassReport::default(),
        })
    }

    /// Whether the pass computes whole forces (see
    /// [`LargeStrain::computing_whole_forces`]), not corrections.
    pub fn computes_whole_forces(&self) -> bool {
        self.whole
    }

    /// Whether every tetrahedron of the model is nonlinear.
    pub fn covers_every_tetrahedron(&self) -> bool {
        self.elements.len() == self.element_of.len()
    }

    /// The same pass computing each element's whole elastic force, P
    /// instead of P - sigma_lin: for a model whose every tetrahedron is
    /// nonlinear, run beside a kernel without the elements' tensors
    /// ([`super::Kernel::beside_whole_forces`]), which then no longer
    /// streams the linear tensors only for the pass to cancel them.
    pub fn computing_whole_forces(mut self) -> Self {
        self.whole = true;
        self
    }

    /// Number of nonlinear elements (live or not).
    pub fn len(&self) -> usize {
        self.elements.len()
    }

    /// Whether there are none (never: [`LargeStrain::new`] returns `None` then).
    pub fn is_empty(&self) -> bool {
        self.elements.is_empty()
    }

    /// The vertices the nonlinear elements touch, ascending.
    pub fn vertices(&self) -> &[u32] {
        &self.vertices
    }

    /// What the last pass found.
    pub fn last(&self) -> PassReport {
        self.last
    }

    /// The rest bound of the nonlinear elements, the largest
    /// [`PassReport::lambda`] at zero displacement.
    pub fn rest_lambda(&self) -> Real {
        self.elements
            .iter()
            .zip(&self.alive)
            .filter(|(_, alive)| **alive)
            .map(|(e, _)| e.rest_lambda)
            .fold(0.0, Real::max)
    }

    /// Follows a removal or restoration of tetrahedron `t` (its element
    /// then contributes nothing, or again what it did).
    pub fn set_alive(&mut self, t: TetId, alive: bool) {
        if let Some(&i) = self.element_of.get(t.idx())
            && i != u32::MAX
        {
            let i = i as usize;
            self.alive[i] = alive;
            self.rotations[i] = DQuat::IDENTITY;
            match &mut self.lanes {
                Lanes::F64(set) => set.forget(i),
                Lanes::F32(set) => set.forget(i),
            }
        }
    }

    /// Bytes the pass streams: the blocks' rest data, forces and rotations
    /// (besides the displacements and vertex forces the step counts).
    pub fn bytes(&self) -> usize {
        // Eight f32 lanes in one task skip the force slots (counted as
        // such: on several threads they are written and read again).
        fn of<S: Scalar, const N: usize>(set: &LaneSet<S, N>) -> usize {
            let slots = if set.acc.is_empty() {
                std::mem::size_of::<BlockForces<S, N>>()
            } else {
                0
            };
            set.blocks.len()
                * (std::mem::size_of::<Block<S, N>>() + slots + std::mem::size_of::<Q<S, N>>())
        }
        match &self.lanes {
            Lanes::F64(set) => of(set),
            Lanes::F32(set) => of(set),
        }
    }

    /// The pass: computes every live element's force correction (or whole
    /// force, see [`LargeStrain::computing_whole_forces`]) at `u` and
    /// writes their sums into `out` at the touched vertices (overwritten;
    /// other vertices are left as they are). Runs on the current rayon
    /// pool's threads when called inside one.
    pub fn pass(&mut self, u: &[V3], out: &mut [V3], threads: usize) {
        let min = MIN_ELEMENTS_PER_TASK.max(self.elements.len() / threads.max(1) + 1);
        self.pass_in_tasks(u, out, min);
    }

    /// The pass with tasks of at least `min` elements.
    fn pass_in_tasks(&mut self, u: &[V3], out: &mut [V3], min: usize) {
        let Self {
            elements,
            alive,
            lanes,
            rotations,
            vertices,
            whole,
            ..
        } = self;
        let whole = *whole;
        self.last = match lanes {
            Lanes::F64(set) => set.pass(elements, alive, rotations, u, min, whole, vertices, out),
            Lanes::F32(set) => set.pass(elements, alive, rotations, u, min, whole, vertices, out),
        };
    }

    /// The pass in tasks of one block (on the current pool), so that each
    /// element's forces stay in their slots for [`LargeStrain::element_forces`]
    /// (one task adds them to the vertices as they come).
    #[cfg(test)]
    fn pass_keeping_element_forces(&mut self, u: &[V3], out: &mut [V3]) {
        self.pass_in_tasks(u, out, 0);
    }

    /// Element `i`'s rotation (corotational elements; identity otherwise).
    #[cfg(test)]
    fn rotation(&self, i: usize) -> DQuat {
        let lanes = match &self.lanes {
            Lanes::F64(set) => set.rotation(i),
            Lanes::F32(set) => set.rotation(i),
        };
        lanes.unwrap_or(self.rotations[i])
    }

    /// Every element's rotation.
    #[cfg(test)]
    fn rotations(&self) -> Vec<DQuat> {
        (0..self.len()).map(|i| self.rotation(i)).collect()
    }

    /// Element `i`'s four corner forces of the last pass in tasks (N).
    #[cfg(test)]
    fn element_forces(&self, i: usize) -> [V3; 4] {
        match &self.lanes {
            Lanes::F64(set) => set.load(i),
            Lanes::F32(set) => set.load(i),
        }
    }
}

/// The lanes of one precision.
#[derive(Clone, Debug)]
enum Lanes {
    F64(LaneSet<f64, 4>),
    F32(LaneSet<f32, 8>),
}

/// One element's force correction into `out` (its whole elastic force
/// when `whole`), and its bound.
#[inline]
fn element(e: &Element, q: &mut DQuat, out: &mut [V3; 4], u: &[V3], whole: bool) -> PassReport {
    let du = e.vertices.map(|v| Vec3::from_array(u[v as usize]));
    let f = deformation_gradient(&e.geom, &du);
    let (d, lambda, barrier) = match Law::of(e.model) {
        Law::Stvk => {
            let (d, lambda, barrier) = stvk(e, &f);
            let d = if whole {
                d + first_piola(Law::Linear, &e.elastic, &f, q)
            } else {
                d
            };
            (d, lambda, barrier)
        }
        law => {
            // Corotational: the rotated rest tangent plus the rotation's
            // terms, which scale with the stress (an estimate, exact at rest).
            let p = first_piola(law, &e.elastic, &f, q);
            let lambda = e.rest_lambda + 2.0 * gershgorin_abs(&p) * e.geometric_per_pa;
            let d = if whole {
                p
            } else {
                p - first_piola(Law::Linear, &e.elastic, &f, q)
            };
            (d, lambda, false)
        }
    };
    let d = d * (-e.geom.volume_m3);
    for (o, m) in out.iter_mut().zip(&e.geom.shape) {
        *o = (d * *m).to_array();
    }
    PassReport {
        lambda,
        collapsed: barrier as usize,
    }
}

/// StVK's P - sigma_lin, written so the linear stress is not computed
/// twice: with H = F - I, E = sym H + H^T H / 2 and the stress linear in E,
/// S = sigma(sym H) + sigma(H^T H / 2) and F S - sigma(sym H) = H S +
/// sigma(H^T H / 2). Also the tangent bound: the material part is at most
/// sigma_max(F)^2 (F^T F = I + 2E) times the rest tangent's largest
/// eigenvalue, the geometric part at most V max(0, lambda_max(S))
/// sum |m_k|^2; in the barrier the whole stress bounds both.
#[inline]
fn stvk(e: &Element, f: &Mat3) -> (Mat3, Real, bool) {
    let h = *f - Mat3::IDENTITY;
    let lin = (h + h.transpose()) * 0.5;
    let quad = h.transpose() * h * 0.5;
    let sigma_quad = e.elastic.stress(&quad);
    let s = e.elastic.stress(&lin) + sigma_quad;
    let mut d = h * s + sigma_quad;
    let stretch = gershgorin(&(Mat3::IDENTITY + (lin + quad) * 2.0));
    let barrier = in_barrier(f);
    let lambda = if barrier {
        let b = barrier_piola(&e.elastic, f);
        d += b;
        stretch.max(1.0) * e.rest_lambda + 4.0 * gershgorin_abs(&(*f * s + b)) * e.geometric_per_pa
    } else {
        stretch * e.rest_lambda + gershgorin(&s).max(0.0) * e.geometric_per_pa
    };
    (d, lambda, barrier)
}

/// Gershgorin's upper bound on the largest eigenvalue of a symmetric 3x3.
#[inline]
fn gershgorin(m: &Mat3) -> Real {
    let r = |i: usize| {
        let row = m.row(i);
        row[i]
            + (0..3)
                .filter(|j| *j != i)
                .map(|j| row[j].abs())
                .sum::<Real>()
    };
    r(0).max(r(1)).max(r(2))
}

/// The largest absolute row sum (an upper bound on the spectral norm of a
/// symmetric matrix, and on |P| in the same way).
#[inline]
fn gershgorin_abs(m: &Mat3) -> Real {
    (0..3)
        .map(|i| m.row(i).abs().element_sum())
        .fold(0.0, Real::max)
}

mod lane_set;

#[cfg(test)]
mod tests;
