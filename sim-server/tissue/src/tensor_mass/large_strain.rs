//! The nonlinear (StVK, corotational) elements of an explicit simulation:
//! per-element rest data packed once, a force pass every sub-step, and the
//! bound of the current tangent for the stable step.
//!
//! The hot kernel keeps the linear tensors of *every* element (so contact
//! stiffness, the rest bound and cutting stay as they are); for each
//! nonlinear element this pass adds the difference between its nonlinear
//! force and its linear one, -V (P - sigma_lin) m_k. The pass writes each
//! element's four forces to its own slots and then sums them per vertex
//! (a gather over a vertex-to-slot list built once): threads own element
//! ranges and vertex ranges, no atomics, and the result does not depend on
//! the thread count.

use super::corotational_lanes::corotational_block;
use super::element::{Geometry, TetElastic};
use super::kernel::V3;
use super::lanes::{L, LaneBlock, Scalar};
use super::model::ElasticModel;
use super::nonlinear::{Law, barrier_piola, deformation_gradient, first_piola, in_barrier};
use super::stvk_lanes::stvk_block;
use crate::ids::TetId;
use crate::material::MaterialModel;
use crate::math::{Mat3, Real, Vec3};
use glam::DQuat;

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
    /// Elements kN..(k+1)N as lanes, and their forces.
    lanes: Lanes,
    rotations: Vec<DQuat>,
    /// Index of each tetrahedron's element (u32::MAX: linear).
    element_of: Vec<u32>,
    /// Vertices touched, and for each its slots (element * 4 + corner).
    vertices: Vec<u32>,
    slot_start: Vec<u32>,
    slots: Vec<u32>,
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
        let mesh = model.mesh();
        let mut element_of = vec![u32::MAX; mesh.tet_count()];
        let mut elements = Vec::new();
        let mut alive = Vec::new();
        // By model (StVK, then corotational), so that they fill whole blocks of
        // four lanes; within a model by their lowest vertex, so that the
        // elements around a vertex sit together in memory (the vertices are
        // in RCM order): the pass reads displacements and the gather reads
        // element forces nearly in sequence instead of across the mesh.
        let of_model = |m: MaterialModel| {
            let mut ts: Vec<TetId> = (0..mesh.tet_count())
                .map(TetId::from)
                .filter(|t| model.materials().material(*t).model() == m)
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
                model: material.model(),
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
        let mut slot_start = Vec::with_capacity(vertices.len() + 1);
        slot_start.push(0u32);
        let mut first = vec![0u32; mesh.vertex_count()];
        for &v in &vertices {
            let end = slot_start.last().copied().unwrap_or(0);
            first[v as usize] = end;
            slot_start.push(end + count[v as usize]);
        }
        let mut slots = vec![0u32; slot_start.last().copied().unwrap_or(0) as usize];
        for (i, e) in elements.iter().enumerate() {
            for (k, v) in e.vertices.iter().enumerate() {
                let at = &mut first[*v as usize];
                slots[*at as usize] = (4 * i + k) as u32;
                *at += 1;
            }
        }
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
            slot_start,
            slots,
            last: PassReport::default(),
        })
    }

    /// Number of nonlinear elements (live or not).
    pub fn len(&self) -> usize {
        self.elements.len()
    }

    /// Whether there are none (never: [`LargeStrain::new`] returns `None` then).
    pub fn is_empty(&self) -> bool {
        self.elements.is_empty()
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
            match &mut self.lanes {
                Lanes::F64(set) => set.store(i, &[[0.0; 3]; 4]),
                Lanes::F32(set) => set.store(i, &[[0.0; 3]; 4]),
            }
            self.rotations[i] = DQuat::IDENTITY;
        }
    }

    /// The pass: computes every live element's force correction at `u` and
    /// writes their sums into `out` at the touched vertices (overwritten;
    /// other vertices are left as they are). Runs on the current rayon
    /// pool's threads when called inside one.
    pub fn pass(&mut self, u: &[V3], out: &mut [V3], threads: usize) {
        let Self {
            elements,
            alive,
            lanes,
            rotations,
            vertices,
            slot_start,
            slots,
            ..
        } = self;
        let min = MIN_ELEMENTS_PER_TASK.max(elements.len() / threads.max(1) + 1);
        let slots = Slots {
            vertices,
            slot_start,
            slots,
        };
        self.last = match lanes {
            Lanes::F64(set) => set.pass(elements, alive, rotations, u, min, &slots, out),
            Lanes::F32(set) => set.pass(elements, alive, rotations, u, min, &slots, out),
        };
    }

    /// Element `i`'s four corner forces of the last pass (N).
    #[cfg(test)]
    fn element_forces(&self, i: usize) -> [V3; 4] {
        match &self.lanes {
            Lanes::F64(set) => set.load(i),
            Lanes::F32(set) => set.load(i),
        }
    }
}

/// Each touched vertex's slots (element * 4 + corner).
struct Slots<'a> {
    vertices: &'a [u32],
    slot_start: &'a [u32],
    slots: &'a [u32],
}

/// The scalar of the lanes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LanePrecision {
    /// Four f64 lanes (equal to the scalar path to round-off).
    F64,
    /// Eight f32 lanes.
    F32,
}

/// The lanes of one precision.
#[derive(Clone, Debug)]
enum Lanes {
    F64(LaneSet<f64, 4>),
    F32(LaneSet<f32, 8>),
}

/// One block's corner forces, lane-wise: `[corner][coordinate][lane]`.
type BlockForces<S, const N: usize> = [[L<S, N>; 3]; 4];

/// The elements as blocks of N lanes and their forces, block by block (the
/// pass stores each block's forces with a few vector writes; the gather
/// reads them per vertex).
#[derive(Clone, Debug)]
struct LaneSet<S: Scalar, const N: usize> {
    /// Block k holds elements kN..(k+1)N (a last, short block is scalar).
    blocks: Vec<Block<S, N>>,
    forces: Vec<BlockForces<S, N>>,
}

impl<S: Scalar, const N: usize> LaneSet<S, N> {
    fn of(elements: &[Element]) -> Self {
        let blocks: Vec<Block<S, N>> = elements.chunks(N).map(Block::of).collect();
        Self {
            forces: vec![[[[S::default(); N]; 3]; 4]; blocks.len()],
            blocks,
        }
    }

    /// Element `i`'s forces into its lane.
    fn store(&mut self, i: usize, f: &[V3; 4]) {
        let block = &mut self.forces[i / N];
        for (k, fk) in f.iter().enumerate() {
            for (c, x) in fk.iter().enumerate() {
                block[k][c][i % N] = S::of(*x);
            }
        }
    }

    /// Element `i`'s forces from its lane.
    #[cfg(test)]
    fn load(&self, i: usize) -> [V3; 4] {
        let block = &self.forces[i / N];
        std::array::from_fn(|k| std::array::from_fn(|c| block[k][c][i % N].real()))
    }

    /// The pass over all elements, then the per-vertex sums into `out`.
    #[allow(clippy::too_many_arguments)]
    fn pass(
        &mut self,
        elements: &[Element],
        alive: &[bool],
        rotations: &mut [DQuat],
        u: &[V3],
        min: usize,
        slots: &Slots<'_>,
        out: &mut [V3],
    ) -> PassReport {
        let range = Range {
            elements,
            alive,
            rotations,
            blocks: &self.blocks,
            forces: &mut self.forces,
        };
        let report = element_range(range, u, min);
        gather(slots, &self.forces, out);
        report
    }
}

/// N consecutive elements as lanes, when they share a model.
#[derive(Clone, Debug)]
enum Block<S: Scalar, const N: usize> {
    Stvk(LaneBlock<S, N>),
    Corotational(LaneBlock<S, N>),
    /// Mixed models: one element at a time.
    Scalar,
}

impl<S: Scalar, const N: usize> Block<S, N> {
    fn of(four: &[Element]) -> Self {
        let model = four[0].model;
        if four.len() < N || four.iter().any(|e| e.model != model) {
            return Block::Scalar;
        }
        match model {
            MaterialModel::Stvk => Block::Stvk(block(four)),
            MaterialModel::Corotational => Block::Corotational(block(four)),
            MaterialModel::Linear => Block::Scalar,
        }
    }
}

/// A contiguous range of whole blocks: their elements, blocks and buffers.
struct Range<'a, S: Scalar, const N: usize> {
    elements: &'a [Element],
    alive: &'a [bool],
    rotations: &'a mut [DQuat],
    blocks: &'a [Block<S, N>],
    forces: &'a mut [BlockForces<S, N>],
}

/// The elements of one range, split in halves (whole blocks) on the pool
/// down to `min`.
fn element_range<S: Scalar, const N: usize>(
    r: Range<'_, S, N>,
    u: &[V3],
    min: usize,
) -> PassReport {
    let half_blocks = r.blocks.len() / 2;
    let mid = half_blocks * N;
    if r.elements.len() > min && half_blocks > 0 {
        let (ea, eb) = r.elements.split_at(mid);
        let (la, lb) = r.alive.split_at(mid);
        let (ra, rb) = r.rotations.split_at_mut(mid);
        let (ba, bb) = r.blocks.split_at(half_blocks);
        let (fa, fb) = r.forces.split_at_mut(half_blocks);
        let (a, b) = rayon::join(
            || {
                let range = Range {
                    elements: ea,
                    alive: la,
                    rotations: ra,
                    blocks: ba,
                    forces: fa,
                };
                element_range(range, u, min)
            },
            || {
                let range = Range {
                    elements: eb,
                    alive: lb,
                    rotations: rb,
                    blocks: bb,
                    forces: fb,
                };
                element_range(range, u, min)
            },
        );
        return a.join(b);
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { leaf_avx2(r, u) };
    }
    leaf(r, u)
}

/// [`leaf`] compiled for AVX2 (the lanes become one 256-bit operation).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn leaf_avx2<S: Scalar, const N: usize>(r: Range<'_, S, N>, u: &[V3]) -> PassReport {
    leaf(r, u)
}

/// One task's blocks: N StVK or N corotational elements as lanes, the
/// others one at a time.
// A scalar block's element l indexes four parallel buffers and a lane.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn leaf<S: Scalar, const N: usize>(r: Range<'_, S, N>, u: &[V3]) -> PassReport {
    let mut report = PassReport::default();
    for (k, (block, forces)) in r.blocks.iter().zip(r.forces.iter_mut()).enumerate() {
        let i = k * N;
        let alive = || std::array::from_fn(|l| r.alive[i + l]);
        match &block {
            Block::Stvk(b) => {
                let (lambda, collapsed) = stvk_block(b, alive(), u, forces);
                report = report.join(PassReport { lambda, collapsed });
            }
            Block::Corotational(b) => {
                let q = &mut r.rotations[i..i + N];
                let lambda = corotational_block(b, alive(), q, u, forces);
                report = report.join(PassReport {
                    lambda,
                    collapsed: 0,
                });
            }
            Block::Scalar => {
                for l in 0..N.min(r.elements.len() - i) {
                    let mut f = [[0.0; 3]; 4];
                    if r.alive[i + l] {
                        let e = element(&r.elements[i + l], &mut r.rotations[i + l], &mut f, u);
                        report = report.join(e);
                    }
                    for (k, fk) in f.iter().enumerate() {
                        for (c, x) in fk.iter().enumerate() {
                            forces[k][c][l] = S::of(*x);
                        }
                    }
                }
            }
        }
    }
    report
}

/// N elements' rest data as lanes.
fn block<S: Scalar, const N: usize>(four: &[Element]) -> LaneBlock<S, N> {
    let lanes =
        |f: &dyn Fn(&Element) -> Real| -> [S; N] { std::array::from_fn(|k| S::of(f(&four[k]))) };
    let fiber = |e: &Element| e.elastic.fiber;
    LaneBlock {
        vertices: std::array::from_fn(|k| four[k].vertices),
        m: std::array::from_fn(|k| std::array::from_fn(|c| lanes(&|e| e.geom.shape[k + 1][c]))),
        volume: lanes(&|e| e.geom.volume_m3),
        lambda: lanes(&|e| e.elastic.lambda_pa),
        mu: lanes(&|e| e.elastic.mu_pa),
        dir: std::array::from_fn(|c| lanes(&|e| fiber(e).map_or(0.0, |f| f.dir[c]))),
        stretch: lanes(&|e| fiber(e).map_or(0.0, |f| f.stretch_pa)),
        cross: lanes(&|e| fiber(e).map_or(0.0, |f| f.cross_pa)),
        shear: lanes(&|e| fiber(e).map_or(0.0, |f| f.shear_pa)),
        rest_lambda: lanes(&|e| e.rest_lambda),
        geometric: lanes(&|e| e.geometric_per_pa),
    }
}

/// One element's force correction into `out`, and its bound.
#[inline]
fn element(e: &Element, q: &mut DQuat, out: &mut [V3; 4], u: &[V3]) -> PassReport {
    let du = e.vertices.map(|v| Vec3::from_array(u[v as usize]));
    let f = deformation_gradient(&e.geom, &du);
    let (d, lambda, barrier) = match Law::of(e.model) {
        Law::Stvk => stvk(e, &f),
        law => {
            // Corotational: the rotated rest tangent plus the rotation's
            // terms, which scale with the stress (an estimate, exact at rest).
            let p = first_piola(law, &e.elastic, &f, q);
            let lin = first_piola(Law::Linear, &e.elastic, &f, q);
            let lambda = e.rest_lambda + 2.0 * gershgorin_abs(&p) * e.geometric_per_pa;
            (p - lin, lambda, false)
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

/// out[v] = sum of v's element forces, for the touched vertices.
fn gather<S: Scalar, const N: usize>(
    slots: &Slots<'_>,
    forces: &[BlockForces<S, N>],
    out: &mut [V3],
) {
    for (i, &v) in slots.vertices.iter().enumerate() {
        let mut sum = [0.0; 3];
        let range = slots.slot_start[i] as usize..slots.slot_start[i + 1] as usize;
        for &s in &slots.slots[range] {
            let (element, corner) = (s as usize / 4, s as usize % 4);
            let f = &forces[element / N][corner];
            for d in 0..3 {
                sum[d] += f[d][element % N].real();
            }
        }
        out[v as usize] = sum;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Elasticity, Isotropic, Material, Terms, TransverselyIsotropic};
    use crate::material_map::TetMaterials;
    use crate::mesh::{BoxSpec, CellSize};

    /// A 2 x 1 x 1 cm block of `model` elements, a third of them
    /// anisotropic (fibres along (1, 0.3, 0.2)), tetrahedron 6 removed.
    fn mixed_block(model: MaterialModel) -> ElasticModel {
        let mesh = BoxSpec::new(Vec3::new(0.02, 0.01, 0.01), CellSize::EdgeM(0.005))
            .generate()
            .unwrap();
        let iso = Isotropic::from_young_poisson(4500.0, 0.4).unwrap();
        let aniso = TransverselyIsotropic::new(iso, 3000.0, 2500.0, Terms::ALL).unwrap();
        let material = |e| Material::new(e, 1000.0, 0.0).unwrap().with_model(model);
        let mut mats =
            TetMaterials::uniform(material(Elasticity::Isotropic(iso)), mesh.tet_count());
        let id = mats.add(material(Elasticity::Transverse(aniso))).unwrap();
        for t in (0..mesh.tet_count()).filter(|t| t % 3 == 1) {
            mats.assign(TetId::from(t), id).unwrap();
            mats.set_fiber(TetId::from(t), Vec3::new(1.0, 0.3, 0.2))
                .unwrap();
        }
        let mut model = ElasticModel::new(mesh, mats).unwrap();
        model.remove_tet(TetId(6)).unwrap();
        model
    }

    /// How close the lanes must be to the scalar path: f64 lanes to
    /// round-off; f32 lanes to f32's precision of the element's forces
    /// (relative to the linear force plus the correction: a small
    /// correction is a difference of larger terms).
    struct Tolerance {
        /// Of the largest element force.
        force: Real,
        /// Of 1 in |q . q'|.
        rotation: Real,
        /// Of the bound.
        lambda: Real,
    }

    fn tolerance(precision: LanePrecision) -> Tolerance {
        match precision {
            LanePrecision::F64 => Tolerance {
                force: 1e-12,
                rotation: 1e-12,
                lambda: 1e-9,
            },
            LanePrecision::F32 => Tolerance {
                force: 1e-6,
                rotation: 1e-6,
                lambda: 1e-5,
            },
        }
    }

    /// The largest element force of the linear model at `u` plus that of
    /// the pass's corrections: the scale the f32 lanes are judged against.
    fn force_scale(large: &LargeStrain, u: &[V3]) -> Real {
        let mut scale: Real = 0.0;
        for (i, e) in large.elements.iter().enumerate() {
            let du = e.vertices.map(|v| Vec3::from_array(u[v as usize]));
            let f = deformation_gradient(&e.geom, &du);
            let mut unused = DQuat::IDENTITY;
            let lin = first_piola(Law::Linear, &e.elastic, &f, &mut unused);
            for m in &e.geom.shape {
                scale = scale.max((lin * *m).abs().max_element() * e.geom.volume_m3);
            }
            let corrections = large.element_forces(i);
            scale = scale.max(
                corrections
                    .iter()
                    .flatten()
                    .fold(0.0, |m, x| m.max(x.abs())),
            );
        }
        scale
    }

    /// The StVK lane blocks (four f64 or eight f32) give the scalar path's
    /// forces and bound: isotropic and anisotropic lanes, a removed element,
    /// stretched and squeezed (barrier) states.
    #[test]
    fn lanes_equal_the_scalar_path() {
        stvk_lanes_equal_the_scalar_path(LanePrecision::F64);
        stvk_lanes_equal_the_scalar_path(LanePrecision::F32);
    }

    fn stvk_lanes_equal_the_scalar_path(precision: LanePrecision) {
        let tol = tolerance(precision);
        let model = mixed_block(MaterialModel::Stvk);
        let mut large = LargeStrain::with_precision(&model, precision).unwrap();
        let stvk_blocks = match &large.lanes {
            Lanes::F64(set) => set
                .blocks
                .iter()
                .filter(|b| matches!(b, Block::Stvk(_)))
                .count(),
            Lanes::F32(set) => set
                .blocks
                .iter()
                .filter(|b| matches!(b, Block::Stvk(_)))
                .count(),
        };
        assert!(stvk_blocks > 0);
        let p = model.mesh().positions_m();
        for squash in [1.0, 0.3] {
            let u: Vec<V3> = p
                .iter()
                .map(|x| {
                    [
                        0.4 * x.x + 0.1 * x.z,
                        (squash - 1.0) * x.y,
                        -0.2 * x.x * x.y / 0.01,
                    ]
                })
                .collect();
            let mut out = vec![[0.0; 3]; u.len()];
            large.pass(&u, &mut out, 1);
            let scale = force_scale(&large, &u);
            let mut lambda: Real = 0.0;
            let mut collapsed = 0;
            for (i, e) in large.elements.iter().enumerate() {
                let mut f = [[0.0; 3]; 4];
                if large.alive[i] {
                    let r = element(e, &mut DQuat::default(), &mut f, &u);
                    lambda = lambda.max(r.lambda);
                    collapsed += r.collapsed;
                }
                for (a, b) in f.iter().zip(&large.element_forces(i)) {
                    for d in 0..3 {
                        let bound = match precision {
                            LanePrecision::F64 => tol.force * (1.0 + a[d].abs()),
                            LanePrecision::F32 => tol.force * scale,
                        };
                        assert!(
                            (a[d] - b[d]).abs() <= bound,
                            "{precision:?} element {i}: {a:?} vs {b:?}"
                        );
                    }
                }
            }
            assert!((large.last().lambda - lambda).abs() <= tol.lambda * lambda);
            assert_eq!(large.last().collapsed, collapsed);
            assert_eq!(collapsed > 0, squash < 0.5, "squash {squash}");
        }
    }

    /// The corotational lane blocks (four f64 or eight f32) give the
    /// scalar path's forces, rotations and bound, warm-started from the
    /// rotations the previous pass left: isotropic and anisotropic lanes, a
    /// removed element, a small deformation, a large rotation (many
    /// iterations) and an inverted state (Mueller's steps).
    #[test]
    fn corotational_lanes_equal_the_scalar_path() {
        corotational_lanes_equal(LanePrecision::F64);
        corotational_lanes_equal(LanePrecision::F32);
    }

    fn corotational_lanes_equal(precision: LanePrecision) {
        let tol = tolerance(precision);
        // The rotation converges to 1e-6 rad, its error about the square.
        let corotational_force_tol = match precision {
            LanePrecision::F64 => 1e-10,
            LanePrecision::F32 => tol.force,
        };
        let model = mixed_block(MaterialModel::Corotational);
        let mut large = LargeStrain::with_precision(&model, precision).unwrap();
        let (lanes, width) = match &large.lanes {
            Lanes::F64(set) => (
                set.blocks
                    .iter()
                    .filter(|b| matches!(b, Block::Corotational(_)))
                    .count(),
                4,
            ),
            Lanes::F32(set) => (
                set.blocks
                    .iter()
                    .filter(|b| matches!(b, Block::Corotational(_)))
                    .count(),
                8,
            ),
        };
        assert_eq!(lanes, large.elements.len() / width);
        let p = model.mesh().positions_m();
        let turned = |angle: Real, shear: Real, flip: Real| -> Vec<V3> {
            let r = Mat3::from_rotation_z(angle) * Mat3::from_rotation_x(0.5 * angle);
            p.iter()
                .map(|x| {
                    let y = Vec3::new(x.x + shear * x.y / 0.01 * 0.002, x.y, flip * x.z);
                    (r * y - *x).to_array()
                })
                .collect()
        };
        for u in [
            turned(0.01, 0.1, 1.0),
            turned(0.02, 0.12, 1.0),
            turned(1.3, 0.3, 1.0),
            turned(0.4, 0.2, -0.3),
        ] {
            let before = large.rotations.clone();
            let mut out = vec![[0.0; 3]; u.len()];
            large.pass(&u, &mut out, 1);
            let mut lambda: Real = 0.0;
            let scale = match precision {
                LanePrecision::F64 => (0..large.len())
                    .flat_map(|i| large.element_forces(i))
                    .flatten()
                    .fold(0.0 as Real, |m, x| m.max(x.abs())),
                LanePrecision::F32 => force_scale(&large, &u),
            };
            for (i, e) in large.elements.iter().enumerate() {
                let mut f = [[0.0; 3]; 4];
                let mut q = before[i];
                if large.alive[i] {
                    lambda = lambda.max(element(e, &mut q, &mut f, &u).lambda);
                }
                assert!(
                    (q.dot(large.rotations[i]).abs() - 1.0).abs() < tol.rotation,
                    "{precision:?} element {i}: rotation {q:?} vs {:?}",
                    large.rotations[i]
                );
                for (a, b) in f.iter().zip(&large.element_forces(i)) {
                    for d in 0..3 {
                        assert!(
                            (a[d] - b[d]).abs() <= corotational_force_tol * scale,
                            "{precision:?} element {i}: {a:?} vs {b:?} (scale {scale}, q {q:?} vs {:?})",
                            large.rotations[i]
                        );
                    }
                }
            }
            assert!((large.last().lambda - lambda).abs() <= tol.lambda * lambda);
        }
    }
}
