//! One tetrahedron: shape vectors, its stiffness blocks derived from the
//! energy, and the energy itself computed from the strain (an independent path
//! that the tests compare the blocks against).

use crate::material::{Elasticity, Material, Terms};
use crate::math::{Mat3, Real, Vec3, outer, tet_signed_volume};

/// Shape vectors m_k = grad(phi_k) (1/m) and volume (m^3) of a tetrahedron at rest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Geometry {
    /// Gradients of the barycentric coordinates.
    pub shape: [Vec3; 4],
    /// Volume (positive for a positively oriented tetrahedron).
    pub volume_m3: Real,
}

impl Geometry {
    /// From the four rest positions. Recomputed on demand rather than stored:
    /// the same inputs give bit-identical results, so a tetrahedron removed and
    /// added back contributes exactly what it contributed before.
    pub fn new(p: [Vec3; 4]) -> Self {
        let j = Mat3::from_cols(p[1] - p[0], p[2] - p[0], p[3] - p[0]);
        // Barycentric phi_1..3 = J^-1 (x - p0): their gradients are the rows of J^-1.
        let inv_t = j.inverse().transpose();
        let (m1, m2, m3) = (inv_t.x_axis, inv_t.y_axis, inv_t.z_axis);
        Self {
            shape: [-(m1 + m2 + m3), m1, m2, m3],
            volume_m3: tet_signed_volume(p[0], p[1], p[2], p[3]),
        }
    }
}

/// The elastic constants one tetrahedron uses, resolved from its material and
/// fibre: transverse Lame constants and, when anisotropic, the fibre and the
/// coefficients of the enabled terms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TetElastic {
    /// lambda (transverse, Pa).
    pub lambda_pa: Real,
    /// mu (transverse, Pa).
    pub mu_pa: Real,
    /// Anisotropy, if any.
    pub fiber: Option<FiberTerms>,
}

/// The anisotropic coefficients of one tetrahedron with the term switches folded in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FiberTerms {
    /// Unit fibre direction a.
    pub dir: Vec3,
    /// delta-lambda if the cross term is on, else 0.
    pub cross_pa: Real,
    /// delta-mu if the shear term is on, else 0.
    pub shear_pa: Real,
    /// Coefficient of (a.m_i)(a.m_j) a(x)a: stretch (dl + 2 dm) - 2 cross - 4 shear.
    pub aa_pa: Real,
    /// Stretch coefficient dl/2 + dm (0 when off), for the energy.
    pub stretch_pa: Real,
}

impl TetElastic {
    /// Resolves a material and a unit fibre direction (used only when anisotropic).
    pub fn new(material: &Material, fiber: Vec3) -> Self {
        match material.elasticity() {
            Elasticity::Isotropic(iso) => Self {
                lambda_pa: iso.lambda_pa(),
                mu_pa: iso.mu_pa(),
                fiber: None,
            },
            Elasticity::Transverse(t) => {
                let Terms {
                    stretch,
                    cross,
                    shear,
                } = t.terms();
                let (dl, dm) = (t.delta_lambda_pa(), t.delta_mu_pa());
                let on = |b: bool, v: Real| if b { v } else { 0.0 };
                let stretch_pa = on(stretch, dl / 2.0 + dm);
                let cross_pa = on(cross, dl);
                let shear_pa = on(shear, dm);
                Self {
                    lambda_pa: t.transverse().lambda_pa(),
                    mu_pa: t.transverse().mu_pa(),
                    fiber: Some(FiberTerms {
                        dir: fiber,
                        cross_pa,
                        shear_pa,
                        aa_pa: 2.0 * stretch_pa - 2.0 * cross_pa - 4.0 * shear_pa,
                        stretch_pa,
                    }),
                }
            }
        }
    }

    /// The stiffness block K_ij (3x3, N/m) of a tetrahedron for its local
    /// vertices i, j: the Hessian of V W(E) with respect to U_i and U_j, so
    /// that the elastic force is F_i = -sum_j K_ij U_j and K_ji = K_ij^T.
    /// This is paper.md's verified formula, not the paper's eqs 20-23.
    #[inline]
    pub fn block(&self, g: &Geometry, i: usize, j: usize) -> Mat3 {
        let (mi, mj) = (g.shape[i], g.shape[j]);
        let mij = mi.dot(mj);
        let mut k = outer(mi, mj) * self.lambda_pa
            + outer(mj, mi) * self.mu_pa
            + Mat3::from_diagonal(Vec3::splat(self.mu_pa * mij));
        if let Some(f) = &self.fiber {
            let a = f.dir;
            let (ai, aj) = (a.dot(mi), a.dot(mj));
            let aa = outer(a, a);
            k += (outer(mi, a) * aj + outer(a, mj) * ai) * f.cross_pa;
            k += (Mat3::from_diagonal(Vec3::splat(ai * aj))
                + outer(mj, a) * ai
                + outer(a, mi) * aj
                + aa * mij)
                * f.shear_pa;
            k += aa * (f.aa_pa * ai * aj);
        }
        k * g.volume_m3
    }

    /// The elastic energy V W(E) (J) of the tetrahedron under displacements
    /// `u` of its four vertices, computed from the strain invariants.
    pub fn energy_j(&self, g: &Geometry, u: [Vec3; 4]) -> Real {
        // grad U = sum_k U_k (x) m_k; E its symmetric part.
        let grad = (0..4).fold(Mat3::ZERO, |acc, k| acc + outer(u[k], g.shape[k]));
        g.volume_m3 * self.energy_density(&((grad + grad.transpose()) * 0.5))
    }

    /// The energy density W(E) (J/m^3) of a symmetric strain E: the paper's
    /// invariants, the same function whether E is the linearised strain, the
    /// Green-Lagrange strain (StVK) or the strain in a rotated frame.
    pub fn energy_density(&self, e: &Mat3) -> Real {
        let i1 = trace(e);
        let e2 = *e * *e;
        let mut w = 0.5 * self.lambda_pa * i1 * i1 + self.mu_pa * trace(&e2);
        if let Some(f) = &self.fiber {
            let a = f.dir;
            let i4 = a.dot(*e * a);
            let i5 = a.dot(e2 * a);
            w += f.stretch_pa * i4 * i4
                + f.cross_pa * (i1 * i4 - i4 * i4)
                + 2.0 * f.shear_pa * (i5 - i4 * i4);
        }
        w
    }

    /// The stress dW/dE (Pa) of a symmetric strain E: linear in E, so it is
    /// also the elasticity tensor applied to a strain increment.
    #[inline(always)]
    pub fn stress(&self, e: &Mat3) -> Mat3 {
        let i1 = trace(e);
        let mut s = Mat3::from_diagonal(Vec3::splat(self.lambda_pa * i1)) + *e * (2.0 * self.mu_pa);
        if let Some(f) = &self.fiber {
            let a = f.dir;
            let ea = *e * a;
            let i4 = a.dot(ea);
            let aa = outer(a, a);
            // d(I4)/dE = a(x)a, d(I5)/dE = a(x)Ea + Ea(x)a.
            s += aa
                * (2.0 * f.stretch_pa * i4 + f.cross_pa * (i1 - 2.0 * i4) - 4.0 * f.shear_pa * i4);
            s += Mat3::from_diagonal(Vec3::splat(f.cross_pa * i4));
            s += (outer(a, ea) + outer(ea, a)) * (2.0 * f.shear_pa);
        }
        s
    }
}

/// The trace of a 3x3 tensor.
#[inline]
pub fn trace(m: &Mat3) -> Real {
    m.x_axis.x + m.y_axis.y + m.z_axis.z
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shape_vectors_are_barycentric_gradients() {
        let p = [
            Vec3::new(0.1, 0.0, 0.0),
            Vec3::new(1.0, 0.2, 0.0),
            Vec3::new(0.0, 1.0, 0.3),
            Vec3::new(0.2, 0.1, 1.1),
        ];
        let g = Geometry::new(p);
        for k in 0..4 {
            for l in 0..4 {
                // phi_k(p_l) - phi_k(p_0) = m_k . (p_l - p_0)
                let expect = (k == l) as i32 as Real - (k == 0) as i32 as Real;
                assert!((g.shape[k].dot(p[l] - p[0]) - expect).abs() < 1e-12);
            }
        }
        assert!(g.volume_m3 > 0.0);
    }
}
