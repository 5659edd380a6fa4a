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
use super::lanes::{L, LaneBlock};
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
    alive: bool,
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
    /// Elements 4k..4k+4 as lanes where they share a model.
    blocks: Vec<Block>,
    rotations: Vec<DQuat>,
    forces: Vec<[V3; 4]>,
    /// Index of each tetrahedron's element (u32::MAX: linear).
    element_of: Vec<u32>,
    /// Vertices touched, and for each its slots (element * 4 + corner).
    vertices: Vec<u32>,
    slot_start: Vec<u32>,
    slots: Vec<u32>,
    last: PassReport,
}

impl LargeStrain {
    /// The nonlinear elements of `model`, or `None` when it has none (a
    /// linear scene pays nothing).
    pub fn new(model: &ElasticModel) -> Option<Self> {
        let mesh = model.mesh();
        let mut element_of = vec![u32::MAX; mesh.tet_count()];
        let mut elements = Vec::new();
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
                alive: model.topology().is_alive(t),
            });
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
        let blocks = elements.chunks_exact(4).map(Block::of).collect();
        Some(Self {
            blocks,
            rotations: vec![DQuat::IDENTITY; elements.len()],
            forces: vec![[[0.0; 3]; 4]; elements.len()],
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
            .filter(|e| e.alive)
            .map(|e| e.rest_lambda)
            .fold(0.0, Real::max)
    }

    /// Follows a removal or restoration of tetrahedron `t` (its element
    /// then contributes nothing, or again what it did).
    pub fn set_alive(&mut self, t: TetId, alive: bool) {
        if let Some(&i) = self.element_of.get(t.idx())
            && i != u32::MAX
        {
            let i = i as usize;
            self.elements[i].alive = alive;
            self.forces[i] = [[0.0; 3]; 4];
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
            blocks,
            rotations,
            forces,
            vertices,
            slot_start,
            slots,
            ..
        } = self;
        let min = MIN_ELEMENTS_PER_TASK.max(elements.len() / threads.max(1) + 1);
        let range = Range {
            elements,
            rotations,
            forces,
            offset: 0,
        };
        self.last = element_range(range, blocks, u, min);
        gather(vertices, slot_start, slots, forces, out);
    }
}

/// Four consecutive elements as lanes, when they share a model.
#[derive(Clone, Debug)]
enum Block {
    Stvk(LaneBlock),
    Corotational(LaneBlock),
    /// Mixed models: one element at a time.
    Scalar,
}

impl Block {
    fn of(four: &[Element]) -> Self {
        let model = four[0].model;
        if four.iter().any(|e| e.model != model) {
            return Block::Scalar;
        }
        match model {
            MaterialModel::Stvk => Block::Stvk(block(four)),
            MaterialModel::Corotational => Block::Corotational(block(four)),
            MaterialModel::Linear => Block::Scalar,
        }
    }
}

/// A contiguous range of elements and their buffers; `offset` is the
/// first one's index (a multiple of four).
struct Range<'a> {
    elements: &'a [Element],
    rotations: &'a mut [DQuat],
    forces: &'a mut [[V3; 4]],
    offset: usize,
}

/// The elements of one range, split in halves (at multiples of four, so
/// blocks stay whole) on the pool down to `min`.
fn element_range(r: Range<'_>, blocks: &[Block], u: &[V3], min: usize) -> PassReport {
    let mid = (r.elements.len() / 2) & !3;
    if r.elements.len() > min && mid > 0 {
        let (ea, eb) = r.elements.split_at(mid);
        let (ra, rb) = r.rotations.split_at_mut(mid);
        let (fa, fb) = r.forces.split_at_mut(mid);
        let (a, b) = rayon::join(
            || {
                let range = Range {
                    elements: ea,
                    rotations: ra,
                    forces: fa,
                    offset: r.offset,
                };
                element_range(range, blocks, u, min)
            },
            || {
                let range = Range {
                    elements: eb,
                    rotations: rb,
                    forces: fb,
                    offset: r.offset + mid,
                };
                element_range(range, blocks, u, min)
            },
        );
        return a.join(b);
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { leaf_avx2(r, blocks, u) };
    }
    leaf(r, blocks, u)
}

/// [`leaf`] compiled for AVX2 (the lanes become one 256-bit operation).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn leaf_avx2(r: Range<'_>, blocks: &[Block], u: &[V3]) -> PassReport {
    leaf(r, blocks, u)
}

/// One task's elements: blocks of four StVK or four corotational elements
/// as lanes, the others one at a time.
#[inline(always)]
fn leaf(r: Range<'_>, blocks: &[Block], u: &[V3]) -> PassReport {
    let mut report = PassReport::default();
    let mut i = 0;
    while i < r.elements.len() {
        let g = r.offset + i;
        let lanes = match blocks.get(g / 4) {
            Some(b) if g.is_multiple_of(4) && i + 4 <= r.elements.len() => b,
            _ => &Block::Scalar,
        };
        let alive = || std::array::from_fn(|k| r.elements[i + k].alive);
        if let Block::Stvk(b) = lanes {
            let (lambda, collapsed) = stvk_block(b, alive(), u, &mut r.forces[i..i + 4]);
            report = report.join(PassReport { lambda, collapsed });
            i += 4;
        } else if let Block::Corotational(b) = lanes {
            let q = &mut r.rotations[i..i + 4];
            let lambda = corotational_block(b, alive(), q, u, &mut r.forces[i..i + 4]);
            report = report.join(PassReport {
                lambda,
                collapsed: 0,
            });
            i += 4;
        } else {
            if r.elements[i].alive {
                let e = element(&r.elements[i], &mut r.rotations[i], &mut r.forces[i], u);
                report = report.join(e);
            }
            i += 1;
        }
    }
    report
}

/// Four elements' rest data as lanes.
fn block(four: &[Element]) -> LaneBlock {
    let lanes = |f: &dyn Fn(&Element) -> Real| -> L { std::array::from_fn(|k| f(&four[k])) };
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
fn gather(vertices: &[u32], slot_start: &[u32], slots: &[u32], forces: &[[V3; 4]], out: &mut [V3]) {
    for (i, &v) in vertices.iter().enumerate() {
        let mut sum = [0.0; 3];
        for &s in &slots[slot_start[i] as usize..slot_start[i + 1] as usize] {
            let f = forces[s as usize / 4][s as usize % 4];
            for d in 0..3 {
                sum[d] += f[d];
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

    /// The four-lane StVK blocks give the scalar path's forces and bound:
    /// isotropic and anisotropic lanes, a removed element, stretched and
    /// squeezed (barrier) states.
    #[test]
    fn lanes_equal_the_scalar_path() {
        let model = mixed_block(MaterialModel::Stvk);
        let mut large = LargeStrain::new(&model).unwrap();
        assert!(!large.blocks.is_empty());
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
            let mut lambda: Real = 0.0;
            let mut collapsed = 0;
            for (i, e) in large.elements.iter().enumerate() {
                let mut f = [[0.0; 3]; 4];
                if e.alive {
                    let r = element(e, &mut DQuat::default(), &mut f, &u);
                    lambda = lambda.max(r.lambda);
                    collapsed += r.collapsed;
                }
                for (a, b) in f.iter().zip(&large.forces[i]) {
                    for d in 0..3 {
                        assert!(
                            (a[d] - b[d]).abs() <= 1e-12 * (1.0 + a[d].abs()),
                            "element {i}: {a:?} vs {b:?}"
                        );
                    }
                }
            }
            assert!((large.last().lambda - lambda).abs() <= 1e-9 * lambda);
            assert_eq!(large.last().collapsed, collapsed);
            assert_eq!(collapsed > 0, squash < 0.5, "squash {squash}");
        }
    }

    /// The four-lane corotational blocks give the scalar path's forces,
    /// rotations and bound, warm-started from the rotations the previous
    /// pass left: isotropic and anisotropic lanes, a removed element, a
    /// small deformation, a large rotation (many iterations) and an
    /// inverted state (Mueller's steps).
    #[test]
    fn corotational_lanes_equal_the_scalar_path() {
        let model = mixed_block(MaterialModel::Corotational);
        let mut large = LargeStrain::new(&model).unwrap();
        let lanes = large
            .blocks
            .iter()
            .filter(|b| matches!(b, Block::Corotational(_)))
            .count();
        assert_eq!(lanes, large.elements.len() / 4);
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
            let scale = large
                .forces
                .iter()
                .flatten()
                .flatten()
                .fold(0.0 as Real, |m, x| m.max(x.abs()));
            for (i, e) in large.elements.iter().enumerate() {
                let mut f = [[0.0; 3]; 4];
                let mut q = before[i];
                if e.alive {
                    lambda = lambda.max(element(e, &mut q, &mut f, &u).lambda);
                }
                assert!(
                    (q.dot(large.rotations[i]).abs() - 1.0).abs() < 1e-12,
                    "element {i}: rotation {q:?} vs {:?}",
                    large.rotations[i]
                );
                for (a, b) in f.iter().zip(&large.forces[i]) {
                    for d in 0..3 {
                        assert!(
                            (a[d] - b[d]).abs() <= 1e-10 * scale,
                            "element {i}: {a:?} vs {b:?}"
                        );
                    }
                }
            }
            assert!((large.last().lambda - lambda).abs() <= 1e-9 * lambda);
        }
    }
}
