//! The stable time step of central differences: dt <= 2 / omega_max with
//! omega_max^2 the largest eigenvalue of M^-1 K (paper.md section 2; damping
//! centred in time does not lower it).
//!
//! Two estimates:
//! - [`element_bound`]: a proven upper bound on omega_max (Irons' theorem:
//!   with lumped mass M = sum of the element masses, the largest eigenvalue of
//!   (K, M) is at most the largest eigenvalue of any element's (K_e, M_e)).
//!   It depends on each element alone, so removing or restoring tetrahedra
//!   never invalidates it; this is what the integrator enforces by default.
//! - [`power_iteration`]: the tight value from the assembled model, a lower
//!   estimate of omega_max that converges from below, reported with a
//!   residual-based upper value. Valid for the mesh as it is: a cut that
//!   leaves a small vertex mass can raise omega_max above it.

use super::element::{Geometry, TetElastic};
use super::model::ElasticModel;
use crate::ids::TetId;
use crate::math::{Real, Vec3};

/// Which estimate the integrator enforces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoundMethod {
    /// Irons' element bound: proven, and still valid after any cut.
    Element,
    /// Power iteration on the assembled model (with its residual bound): tighter, valid until the next cut.
    PowerIteration,
}

impl BoundMethod {
    /// Name used in reports and on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            BoundMethod::Element => "element",
            BoundMethod::PowerIteration => "power-iteration",
        }
    }
}

/// A bound on the highest angular frequency and the step it allows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StableStep {
    /// omega_max (rad/s) the bound uses.
    pub omega_max_rad_s: Real,
    /// 2 / omega_max (s).
    pub dt_max_s: Real,
    /// How it was obtained.
    pub method: BoundMethod,
}

impl StableStep {
    /// The step for omega_max^2 = `lambda`.
    pub fn from_lambda(lambda: Real, method: BoundMethod) -> Self {
        let omega = lambda.max(0.0).sqrt();
        Self {
            omega_max_rad_s: omega,
            dt_max_s: if omega > 0.0 {
                2.0 / omega
            } else {
                Real::INFINITY
            },
            method,
        }
    }
}

impl ElasticModel {
    /// Each tetrahedron's largest eigenvalue of (K_e, M_e) (1/s^2, Irons'
    /// element bound; removed tetrahedra included), computed once on first
    /// use, in parallel, and kept with the model (clones share it): the
    /// explicit integrator's bound, the scene's default step and the
    /// nonlinear elements' rest bound all read it, instead of each solving
    /// the 12 x 12 eigenproblems again (seconds on a million tetrahedra).
    /// Cuts do not change an element's own value.
    pub fn element_lambdas(&self) -> &[Real] {
        use rayon::prelude::*;
        self.element_lambdas.get_or_init(|| {
            (0..self.mesh().tet_count())
                .into_par_iter()
                .map(|t| element_lambda(self, TetId::from(t)))
                .collect::<Vec<Real>>()
                .into()
        })
    }
}

/// Largest eigenvalue of a live element's (K_e, M_e), M_e = rho V / 4 per vertex.
pub fn element_lambda(model: &ElasticModel, t: TetId) -> Real {
    let (elastic, geom) = model.element(t);
    let mut k = element_stiffness(&elastic, &geom);
    // The capsule springs of this tetrahedron's surface faces belong to its
    // element: K = sum over tets of (K_e + springs_e) and M = sum of M_e, so
    // Irons' bound still holds with them (and survives cuts).
    if let Some(membrane) = model.membrane() {
        let rest = model.mesh().positions_m();
        let tet = model.mesh().tets()[t.idx()];
        for (a, b, kf) in membrane.tet_springs(t) {
            let s = crate::membrane::Membrane::linear_tensor(rest, tet[a], tet[b], kf);
            for r in 0..3 {
                for c in 0..3 {
                    let v = s.col(c)[r];
                    k[(3 * a + r, 3 * a + c)] += v;
                    k[(3 * b + r, 3 * b + c)] += v;
                    k[(3 * a + r, 3 * b + c)] -= v;
                    k[(3 * b + r, 3 * a + c)] -= v;
                }
            }
        }
    }
    let quarter_mass = model.materials().material(t).density_kg_m3() * geom.volume_m3 / 4.0;
    k.symmetric_eigenvalues().max() / quarter_mass
}

/// Largest eigenvalue of one tetrahedron's (K_e, M_e) on its own (no
/// capsule springs): what [`element_lambda`] gives for an element of a
/// model without a membrane. For tools that move vertices and need the
/// bound before any model exists (the mesher's quality pass).
pub fn isolated_element_lambda(elastic: &TetElastic, geom: &Geometry, density_kg_m3: Real) -> Real {
    let k = element_stiffness(elastic, geom);
    k.symmetric_eigenvalues().max() / (density_kg_m3 * geom.volume_m3 / 4.0)
}

/// The element's 12 x 12 stiffness matrix from its blocks.
fn element_stiffness(elastic: &TetElastic, geom: &Geometry) -> nalgebra::SMatrix<Real, 12, 12> {
    let mut k = nalgebra::SMatrix::<Real, 12, 12>::zeros();
    for i in 0..4 {
        for j in i..4 {
            let b = elastic.block(geom, i, j);
            for r in 0..3 {
                for c in 0..3 {
                    k[(3 * i + r, 3 * j + c)] = b.col(c)[r];
                    k[(3 * j + c, 3 * i + r)] = b.col(c)[r];
                }
            }
        }
    }
    k
}

/// Irons' proven bound over the live tetrahedra (the element values are
/// the model's, [`ElasticModel::element_lambdas`]).
pub fn element_bound(model: &ElasticModel) -> StableStep {
    let lambda = model
        .element_lambdas()
        .iter()
        .enumerate()
        .filter(|(t, _)| model.topology().is_alive(TetId::from(*t)))
        .map(|(_, l)| *l)
        .fold(0.0, Real::max);
    StableStep::from_lambda(lambda, BoundMethod::Element)
}

/// The live tetrahedra whose own stable step is far below the median
/// element's ([`step_outliers`]): slivers that set the whole organ's
/// explicit step.
#[derive(Clone, Debug, PartialEq)]
pub struct StepOutliers {
    /// The median live element's own stable step (s).
    pub median_dt_s: Real,
    /// How many live elements lie below the threshold.
    pub count: usize,
    /// The shortest ones, (tetrahedron, its own stable step in s),
    /// shortest first.
    pub shortest: Vec<(TetId, Real)>,
}

/// The live tetrahedra of `model` whose own stable step (Irons' element
/// bound, [`ElasticModel::element_lambdas`]) is below the median live
/// element's divided by `factor`, the `list` shortest of them named;
/// `None` when there are none. Each element's step is what it alone
/// allows: the explicit step is the shortest, so one sliver at a tenth of
/// the median makes the whole organ take ten times the sub-steps.
pub fn step_outliers(model: &ElasticModel, factor: Real, list: usize) -> Option<StepOutliers> {
    let lambdas = model.element_lambdas();
    let dt = |l: Real| StableStep::from_lambda(l, BoundMethod::Element).dt_max_s;
    let mut live: Vec<(TetId, Real)> = (0..lambdas.len())
        .map(TetId::from)
        .filter(|t| model.topology().is_alive(*t) && lambdas[t.idx()] > 0.0)
        .map(|t| (t, dt(lambdas[t.idx()])))
        .collect();
    if live.is_empty() {
        return None;
    }
    live.sort_by(|a, b| a.1.total_cmp(&b.1));
    let median_dt_s = live[live.len() / 2].1;
    let count = live
        .iter()
        .take_while(|(_, d)| *d * factor < median_dt_s)
        .count();
    (count > 0).then(|| StepOutliers {
        median_dt_s,
        count,
        shortest: live[..count.min(list)].to_vec(),
    })
}

/// The result of [`power_iteration`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PowerEstimate {
    /// Rayleigh quotient: a lower estimate of lambda_max(M^-1 K) (1/s^2).
    pub lambda: Real,
    /// lambda plus the residual norm: an upper value once the iteration has
    /// locked onto the top mode.
    pub lambda_upper: Real,
    /// Iterations used.
    pub iterations: usize,
    /// The step from `lambda_upper`.
    pub step: StableStep,
}

/// Power iteration on M^-1/2 K M^-1/2 over vertices with mass, from a fixed
/// pseudo-random start (deterministic), until the Rayleigh quotient changes by
/// less than `rel_tol` or `max_iter` is reached.
pub fn power_iteration(model: &ElasticModel, rel_tol: Real, max_iter: usize) -> PowerEstimate {
    let n = model.vertex_count();
    let inv_sqrt_m: Vec<Real> = model
        .masses_kg()
        .iter()
        .map(|&m| if m > 0.0 { 1.0 / m.sqrt() } else { 0.0 })
        .collect();
    let mut seed = 0x9E37_79B9_7F4A_7C15u64;
    let mut rnd = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as Real / (1u64 << 53) as Real - 0.5
    };
    let mut x: Vec<Vec3> = (0..n)
        .map(|i| Vec3::new(rnd(), rnd(), rnd()) * (inv_sqrt_m[i] > 0.0) as u8 as Real)
        .collect();
    let norm = |v: &[Vec3]| v.iter().map(|a| a.length_squared()).sum::<Real>().sqrt();
    let mut tmp = vec![Vec3::ZERO; n];
    let mut y = vec![Vec3::ZERO; n];
    let apply = |x: &[Vec3], tmp: &mut Vec<Vec3>, y: &mut Vec<Vec3>| {
        for i in 0..n {
            tmp[i] = x[i] * inv_sqrt_m[i];
        }
        model.elastic_forces(tmp, y);
        for i in 0..n {
            y[i] *= -inv_sqrt_m[i];
        }
    };
    let mut lambda = 0.0;
    let mut iterations = 0;
    let n0 = norm(&x);
    x.iter_mut().for_each(|v| *v /= n0);
    for it in 1..=max_iter {
        iterations = it;
        apply(&x, &mut tmp, &mut y);
        let next: Real = x.iter().zip(&y).map(|(a, b)| a.dot(*b)).sum();
        let ny = norm(&y);
        if ny == 0.0 {
            break;
        }
        for (xi, yi) in x.iter_mut().zip(&y) {
            *xi = *yi / ny;
        }
        let done = (next - lambda).abs() <= rel_tol * next.abs();
        lambda = next;
        if done {
            break;
        }
    }
    apply(&x, &mut tmp, &mut y);
    let rq: Real = x.iter().zip(&y).map(|(a, b)| a.dot(*b)).sum();
    let residual = x
        .iter()
        .zip(&y)
        .map(|(a, b)| (*b - *a * rq).length_squared())
        .sum::<Real>()
        .sqrt();
    let lambda_upper = rq + residual;
    PowerEstimate {
        lambda: rq,
        lambda_upper,
        iterations,
        step: StableStep::from_lambda(lambda_upper, BoundMethod::PowerIteration),
    }
}
