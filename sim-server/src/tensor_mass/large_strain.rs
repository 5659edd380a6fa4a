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

use super::element::{Geometry, TetElastic};
use super::kernel::V3;
use super::model::ElasticModel;
use super::nonlinear::{Law, barrier_piola, deformation_gradient, first_piola, in_barrier};
use super::stability::element_lambda;
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
        for t in (0..mesh.tet_count()).map(TetId::from) {
            let material = model.materials().material(t);
            if !material.model().is_nonlinear() {
                continue;
            }
            let (elastic, geom) = model.element(t);
            let quarter_mass = material.density_kg_m3() * geom.volume_m3 / 4.0;
            let shape2: Real = geom.shape.iter().map(|m| m.length_squared()).sum();
            element_of[t.idx()] = elements.len() as u32;
            elements.push(Element {
                vertices: mesh.tets()[t.idx()].map(|v| v.0),
                geom,
                elastic,
                model: material.model(),
                rest_lambda: element_lambda(model, t),
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
        Some(Self {
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
            rotations,
            forces,
            vertices,
            slot_start,
            slots,
            ..
        } = self;
        let min = MIN_ELEMENTS_PER_TASK.max(elements.len() / threads.max(1) + 1);
        self.last = element_range(elements, rotations, forces, u, min);
        gather(vertices, slot_start, slots, forces, out);
    }
}

/// The elements of one range, split in halves on the pool down to `min`.
fn element_range(
    elements: &[Element],
    rotations: &mut [DQuat],
    forces: &mut [[V3; 4]],
    u: &[V3],
    min: usize,
) -> PassReport {
    if elements.len() > min {
        let mid = elements.len() / 2;
        let (ea, eb) = elements.split_at(mid);
        let (ra, rb) = rotations.split_at_mut(mid);
        let (fa, fb) = forces.split_at_mut(mid);
        let (a, b) = rayon::join(
            || element_range(ea, ra, fa, u, min),
            || element_range(eb, rb, fb, u, min),
        );
        return a.join(b);
    }
    let mut report = PassReport::default();
    for ((e, q), f) in elements.iter().zip(rotations).zip(forces) {
        if e.alive {
            report = report.join(element(e, q, f, u));
        }
    }
    report
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
