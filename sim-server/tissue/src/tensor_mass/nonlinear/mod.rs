//! One tetrahedron under large displacements: St Venant-Kirchhoff and
//! corotational forces, energies and tangents, from the deformation gradient.
//!
//! Both models keep the paper's constants and energy terms
//! ([`TetElastic::energy_density`]); only the strain changes:
//! - **StVK** (Picinbono, Delingette, Ayache, "Non-linear anisotropic
//!   elasticity for real-time surgery simulation", Graphical Models 2003):
//!   the Green-Lagrange strain E = (F^T F - I) / 2, second Piola-Kirchhoff
//!   stress S = dW/dE, nodal forces f_k = -V F S m_k. The 2003 paper expands
//!   these forces into tensors on vertices, edges, triangles and tetrahedra
//!   (cubic in U); evaluating them through F is the same function of U
//!   (tested against the gradient of the energy) at fewer operations per
//!   tetrahedron and with one rest array per element instead of four.
//! - **Corotational** (Felippa; Mueller and Gross 2004; SOFA's
//!   TetrahedronFEMForceField "polar"): the element's rotation R from the
//!   polar decomposition F = R S_p, the linear stress of the rotated strain
//!   S_p - I, nodal forces f_k = -V R sigma m_k (= R K_e (R^T x - X)). For an
//!   isotropic material these are minus the gradient of V W(S_p - I); for an
//!   anisotropic one the term of the fibre turning is dropped, as in SOFA.
//!
//! The rotation is found by maximising tr(R^T F) over rotations (Mueller,
//! Bender, Chentanez, Macklin, "A robust method to extract the rotational part
//! of deformations", MIG 2016), warm-started from the element's last rotation:
//! one or two iterations per step, and it returns a proper rotation when the
//! element is inverted (det F < 0), where S_p is then indefinite and pushes
//! the element back out.
//!
//! StVK softens in compression and is not invertible: a flattened element
//! has almost no restoring force and an inverted one has a force-free
//! mirror state (W depends on F^T F only). The StVK energy here therefore
//! carries a barrier on the volume ratio J = det F below [`STVK_BARRIER_J`]:
//! W_b = k (J_b - J)^3 with k = [`STVK_BARRIER_SCALE`] (lambda + 2 mu), zero
//! with its first two derivatives at J_b, so the force stays the gradient
//! of one energy (conservative, continuous: switching to another force law
//! below a threshold was tried and pumped energy into the body at each
//! crossing). Tissue compressed to half its volume is outside the model's
//! use; the step reports how many elements are in the barrier.

use super::element::{Geometry, TetElastic, trace};
use crate::material::MaterialModel;
use crate::math::{Mat3, Real, Vec3, outer};
use glam::DQuat;

/// Volume ratio det F below which the StVK barrier acts.
pub const STVK_BARRIER_J: Real = 0.5;
/// The barrier's k in units of lambda + 2 mu: at J = 0 it pushes with 3/4
/// of k, three times the uniaxial modulus.
pub const STVK_BARRIER_SCALE: Real = 4.0;

/// Convergence of the rotation: a Newton step below this (rad) is the
/// last one; the rotation is then accurate to about its square, 1e-12
/// (quadratic convergence). Warm-started, an element takes 1.7 iterations
/// per step on the benchmark box (2.1 with 1e-9, 3 with 1e-13).
pub(super) const ROTATION_TOL_RAD: Real = 1e-6;
/// Iterations at most per extraction (warm-started: usually 1-3).
pub(super) const ROTATION_MAX_ITER: usize = 40;

/// F = I + sum_k u_k (x) m_k.
#[inline]
pub fn deformation_gradient(g: &Geometry, u: &[Vec3; 4]) -> Mat3 {
    Mat3::IDENTITY
        + outer(u[0], g.shape[0])
        + outer(u[1], g.shape[1])
        + outer(u[2], g.shape[2])
        + outer(u[3], g.shape[3])
}

/// The rotation R maximising tr(R^T F), refined from `q` in place: the
/// polar rotation where F is not inverted, a proper rotation where it is.
///
/// Each iteration turns R by omega (in R's frame) so that R^T F becomes
/// symmetric: Newton's step omega = 2 (tr S I - S)^-1 axial(skew(R^T F))
/// with S = sym(R^T F), which converges quadratically once (tr S I - S) is
/// positive definite (it is at the maximum); elsewhere Mueller et al.'s
/// step, which replaces that matrix by tr S and converges from anywhere
/// but only linearly (a factor 3 per iteration near rest: 30 iterations to
/// round-off, where Newton takes 2-3).
#[inline]
pub fn extract_rotation(f: &Mat3, q: &mut DQuat) {
    for _ in 0..ROTATION_MAX_ITER {
        let a = Mat3::from_quat(*q).transpose() * *f;
        let axial = Vec3::new(
            a.y_axis.z - a.z_axis.y,
            a.z_axis.x - a.x_axis.z,
            a.x_axis.y - a.y_axis.x,
        );
        let s = (a + a.transpose()) * 0.5;
        let m = Mat3::from_diagonal(Vec3::splat(trace(&s))) - s;
        let omega = if positive_definite(&m) {
            m.inverse() * axial
        } else {
            axial / (trace(&s).abs() + 1e-12)
        };
        let w = omega.length();
        // NaN (a NaN state) stops too: the caller's divergence check sees it.
        if w.is_nan() {
            break;
        }
        // (1, omega/2) is the rotation by omega to second order: no trigonometry.
        let half = omega * 0.5;
        *q = (*q * DQuat::from_xyzw(half.x, half.y, half.z, 1.0)).normalize();
        if w <= ROTATION_TOL_RAD {
            break;
        }
    }
}

/// Sylvester's criterion for a symmetric 3x3, with a margin against a
/// nearly singular Newton step.
#[inline]
fn positive_definite(m: &Mat3) -> bool {
    let scale = trace(m).abs() + 1e-300;
    let m00 = m.x_axis.x;
    let minor = m00 * m.y_axis.y - m.y_axis.x * m.x_axis.y;
    m00 > 1e-3 * scale
        && minor > 1e-6 * scale * scale
        && m.determinant() > 1e-9 * scale * scale * scale
}

/// Which force law an element uses at its current state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    /// The linear model (P = sigma(sym grad U)).
    Linear,
    /// StVK.
    Stvk,
    /// Corotational.
    Corotational,
}

impl Law {
    /// The law of `model`.
    #[inline]
    pub fn of(model: MaterialModel) -> Self {
        match model {
            MaterialModel::Linear => Law::Linear,
            MaterialModel::Corotational => Law::Corotational,
            MaterialModel::Stvk => Law::Stvk,
        }
    }
}

/// The first Piola-Kirchhoff stress P (Pa) of the law at F (rotation in `q`
/// for the corotational law, refined in place): the nodal forces are
/// f_k = -V P m_k.
#[inline]
pub fn first_piola(law: Law, el: &TetElastic, f: &Mat3, q: &mut DQuat) -> Mat3 {
    match law {
        Law::Linear => el.stress(&(((*f + f.transpose()) * 0.5) - Mat3::IDENTITY)),
        Law::Stvk => *f * el.stress(&green_strain(f)) + barrier_piola(el, f),
        Law::Corotational => {
            extract_rotation(f, q);
            let r = Mat3::from_quat(*q);
            r * el.stress(&rotated_strain(&r, f))
        }
    }
}

/// The barrier's k (Pa).
#[inline]
fn barrier_k(el: &TetElastic) -> Real {
    STVK_BARRIER_SCALE * (el.lambda_pa + 2.0 * el.mu_pa)
}

/// cof(F) = det(F) F^-T = d(det F)/dF, columns f2 x f3, f3 x f1, f1 x f2.
#[inline]
pub fn cofactor(f: &Mat3) -> Mat3 {
    Mat3::from_cols(
        f.y_axis.cross(f.z_axis),
        f.z_axis.cross(f.x_axis),
        f.x_axis.cross(f.y_axis),
    )
}

/// dW_b/dF = -3 k (J_b - J)^2 cof(F) below J_b, else 0.
#[inline]
pub(super) fn barrier_piola(el: &TetElastic, f: &Mat3) -> Mat3 {
    let gap = STVK_BARRIER_J - f.determinant();
    if gap > 0.0 {
        cofactor(f) * (-3.0 * barrier_k(el) * gap * gap)
    } else {
        Mat3::ZERO
    }
}

/// W_b = k (J_b - J)^3 below J_b (J/m^3).
#[inline]
fn barrier_energy(el: &TetElastic, f: &Mat3) -> Real {
    let gap = (STVK_BARRIER_J - f.determinant()).max(0.0);
    barrier_k(el) * gap * gap * gap
}

/// Whether an StVK element at `f` is in the barrier (det F < J_b).
#[inline]
pub fn in_barrier(f: &Mat3) -> bool {
    f.determinant() < STVK_BARRIER_J
}

/// E = (F^T F - I) / 2.
#[inline]
fn green_strain(f: &Mat3) -> Mat3 {
    (f.transpose() * *f - Mat3::IDENTITY) * 0.5
}

/// sym(R^T F) - I (R^T F is symmetric once R is converged).
#[inline]
fn rotated_strain(r: &Mat3, f: &Mat3) -> Mat3 {
    let s = r.transpose() * *f;
    (s + s.transpose()) * 0.5 - Mat3::IDENTITY
}

/// Nodal forces (N) of one element for displacements `u` of its vertices.
pub fn element_forces(
    model: MaterialModel,
    el: &TetElastic,
    g: &Geometry,
    u: &[Vec3; 4],
    q: &mut DQuat,
) -> [Vec3; 4] {
    let f = deformation_gradient(g, u);
    let p = first_piola(Law::of(model), el, &f, q) * (-g.volume_m3);
    g.shape.map(|m| p * m)
}

/// The element's energy (J): V W of the law's strain.
pub fn element_energy_j(
    model: MaterialModel,
    el: &TetElastic,
    g: &Geometry,
    u: &[Vec3; 4],
    q: &mut DQuat,
) -> Real {
    let f = deformation_gradient(g, u);
    let w = match Law::of(model) {
        Law::Linear => el.energy_density(&(((f + f.transpose()) * 0.5) - Mat3::IDENTITY)),
        Law::Stvk => el.energy_density(&green_strain(&f)) + barrier_energy(el, &f),
        Law::Corotational => {
            extract_rotation(&f, q);
            el.energy_density(&rotated_strain(&Mat3::from_quat(*q), &f))
        }
    };
    g.volume_m3 * w
}

/// dP for an increment dF at F (the law's exact derivative; `r` the
/// converged rotation for the corotational law).
fn piola_increment(law: Law, el: &TetElastic, f: &Mat3, r: &Mat3, df: &Mat3) -> Mat3 {
    match law {
        Law::Linear => el.stress(&((*df + df.transpose()) * 0.5)),
        Law::Stvk => {
            let de = (f.transpose() * *df + df.transpose() * *f) * 0.5;
            *df * el.stress(&green_strain(f)) + *f * el.stress(&de) + barrier_increment(el, f, df)
        }
        Law::Corotational => {
            // F = R S_p: R^T dF = Omega S_p + dS_p with Omega = [w]x skew
            // and dS_p symmetric, so axial(skew(R^T dF)) = (tr S_p I - S_p) w / 2.
            let sp = r.transpose() * *f;
            let sp = (sp + sp.transpose()) * 0.5;
            let rdf = r.transpose() * *df;
            let skew = (rdf - rdf.transpose()) * 0.5;
            let axial = Vec3::new(skew.y_axis.z, skew.z_axis.x, skew.x_axis.y);
            let a = Mat3::from_diagonal(Vec3::splat(trace(&sp))) - sp;
            let w = a.inverse() * axial * 2.0;
            let omega = Mat3::from_cols(
                Vec3::new(0.0, w.z, -w.y),
                Vec3::new(-w.z, 0.0, w.x),
                Vec3::new(w.y, -w.x, 0.0),
            );
            let dsp = rdf - omega * sp;
            let sigma = el.stress(&(sp - Mat3::IDENTITY));
            *r * (omega * sigma + el.stress(&((dsp + dsp.transpose()) * 0.5)))
        }
    }
}

/// d(dW_b/dF) for an increment dF: 6 k g (cof : dF) cof - 3 k g^2 d cof,
/// g = J_b - J, d cof the derivative of the cross products.
fn barrier_increment(el: &TetElastic, f: &Mat3, df: &Mat3) -> Mat3 {
    let gap = STVK_BARRIER_J - f.determinant();
    if gap <= 0.0 {
        return Mat3::ZERO;
    }
    let k = barrier_k(el);
    let cof = cofactor(f);
    let dj = (0..3).map(|c| cof.col(c).dot(df.col(c))).sum::<Real>();
    let dcof = Mat3::from_cols(
        df.y_axis.cross(f.z_axis) + f.y_axis.cross(df.z_axis),
        df.z_axis.cross(f.x_axis) + f.z_axis.cross(df.x_axis),
        df.x_axis.cross(f.y_axis) + f.x_axis.cross(df.y_axis),
    );
    cof * (6.0 * k * gap * dj) - dcof * (3.0 * k * gap * gap)
}

/// The element's tangent stiffness blocks K_ij = -d f_i / d u_j (N/m) at
/// displacements `u`: the exact derivative of [`element_forces`].
pub fn element_tangent(
    model: MaterialModel,
    el: &TetElastic,
    g: &Geometry,
    u: &[Vec3; 4],
    q: &mut DQuat,
) -> [[Mat3; 4]; 4] {
    let f = deformation_gradient(g, u);
    let law = Law::of(model);
    if law == Law::Corotational {
        extract_rotation(&f, q);
    }
    let r = Mat3::from_quat(*q);
    let mut k = [[Mat3::ZERO; 4]; 4];
    for (j, mj) in g.shape.iter().enumerate() {
        let mut cols = [[Vec3::ZERO; 3]; 4];
        for (c, axis) in [Vec3::X, Vec3::Y, Vec3::Z].into_iter().enumerate() {
            let dp = piola_increment(law, el, &f, &r, &outer(axis, *mj));
            for (col, mi) in cols.iter_mut().zip(&g.shape) {
                col[c] = dp * *mi * g.volume_m3;
            }
        }
        for (row, col) in k.iter_mut().zip(&cols) {
            row[j] = Mat3::from_cols(col[0], col[1], col[2]);
        }
    }
    k
}

#[cfg(test)]
mod tests;
