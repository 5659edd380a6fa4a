//! Transversally isotropic constants in the paper's 4-parameter form, their
//! positive-definiteness check and engineering constants.

use super::{Isotropic, MaterialError, Terms};
use crate::math::Real;

/// Transversally isotropic constants in the paper's form: the transverse
/// (isotropic-plane) Lame constants and the differences along the fibre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransverselyIsotropic {
    pub(super) transverse: Isotropic,
    pub(super) delta_lambda_pa: Real,
    pub(super) delta_mu_pa: Real,
    pub(super) terms: Terms,
}

/// The engineering constants of a transversally isotropic material, computed
/// from its compliance (so they are the moduli a uniaxial test would measure).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EngineeringConstants {
    /// Young's modulus along the fibre (Pa).
    pub young_fiber_pa: Real,
    /// Young's modulus across the fibre (Pa).
    pub young_transverse_pa: Real,
    /// Contraction across the fibre under stretch along it.
    pub poisson_fiber_transverse: Real,
    /// Contraction across the fibre (other transverse axis) under transverse stretch.
    pub poisson_transverse: Real,
    /// Contraction along the fibre under transverse stretch.
    pub poisson_transverse_fiber: Real,
    /// Shear modulus in planes containing the fibre (Pa).
    pub shear_fiber_pa: Real,
}

impl TransverselyIsotropic {
    /// The paper's parameters: transverse constants plus delta-lambda and
    /// delta-mu (Pa), with the chosen energy terms.
    pub fn new(
        transverse: Isotropic,
        delta_lambda_pa: Real,
        delta_mu_pa: Real,
        terms: Terms,
    ) -> Result<Self, MaterialError> {
        for (field, value) in [
            ("delta_lambda_pa", delta_lambda_pa),
            ("delta_mu_pa", delta_mu_pa),
        ] {
            if !value.is_finite() {
                return Err(MaterialError::NonFinite { field, value });
            }
        }
        let (lambda, mu) = (transverse.lambda_pa, transverse.mu_pa);
        let (ts, tc, th) = terms.factors();
        if th > 0.0 && mu + delta_mu_pa <= 0.0 {
            return Err(MaterialError::DeltaMu {
                delta_mu_pa,
                min_pa: -mu,
            });
        }
        // The normal block of the Voigt matrix (fibre = z) is PD iff
        // (lambda + mu) C33 > C13^2 (mu > 0 and lambda + mu > 0 already hold).
        // With C13 = lambda + tc dl and C33 = lambda + 2 mu + ts (dl + 2 dm),
        // that is a2 dl^2 + a1 dl + a0 < 0:
        let a2 = tc;
        let a1 = 2.0 * lambda * tc - (lambda + mu) * ts;
        let a0 = lambda * lambda - (lambda + mu) * (lambda + 2.0 * mu + 2.0 * ts * delta_mu_pa);
        let (min_pa, max_pa) = negative_interval(a2, a1, a0);
        let dl = delta_lambda_pa;
        if !(dl > min_pa && dl < max_pa) {
            return Err(MaterialError::DeltaLambda {
                delta_lambda_pa,
                delta_mu_pa,
                min_pa,
                max_pa,
                terms,
            });
        }
        Ok(Self {
            transverse,
            delta_lambda_pa,
            delta_mu_pa,
            terms,
        })
    }

    /// From engineering constants: the transverse constants, Young's modulus
    /// along the fibre and the shear modulus in planes containing the fibre
    /// (all three terms enabled). Only 4 of the 5 constants of a general
    /// transversally isotropic solid are free in the paper's model, so the
    /// Poisson ratio along the fibre follows; refused with the representable
    /// range of `young_fiber_pa` when no delta-lambda matches.
    pub fn from_engineering(
        transverse: Isotropic,
        young_fiber_pa: Real,
        shear_fiber_pa: Real,
    ) -> Result<Self, MaterialError> {
        let (lambda, mu) = (transverse.lambda_pa, transverse.mu_pa);
        let e_t = transverse.young_pa();
        let delta_mu = shear_fiber_pa - mu;
        // E_L = E_T + 2 dm - dl (dl + lambda - mu) / (lambda + mu), a parabola in
        // dl opening downwards; its maximum over dl bounds what is reachable, and
        // its value at the ends of the PD interval bounds it from below.
        let e_l = |dl: Real| e_t + 2.0 * delta_mu - dl * (dl + lambda - mu) / (lambda + mu);
        let dl_peak = -(lambda - mu) / 2.0;
        let (lo, hi) = negative_interval(
            1.0,
            lambda - mu,
            lambda * lambda - (lambda + mu) * (lambda + 2.0 * mu + 2.0 * delta_mu),
        );
        let out_of_range = |min_pa: Real, max_pa: Real| MaterialError::Engineering {
            young_fiber_pa,
            shear_fiber_pa,
            min_pa,
            max_pa,
        };
        if !(shear_fiber_pa.is_finite() && shear_fiber_pa > 0.0 && lo < hi) {
            return Err(out_of_range(Real::NAN, Real::NAN));
        }
        let max_pa = e_l(dl_peak.clamp(lo, hi));
        let min_pa = e_l(lo).max(e_l(hi)).max(0.0);
        if !(young_fiber_pa.is_finite() && young_fiber_pa > min_pa && young_fiber_pa <= max_pa) {
            return Err(out_of_range(min_pa, max_pa));
        }
        // Roots of dl^2 + (lambda - mu) dl + (lambda + mu)(E_L - E_T - 2 dm) = 0;
        // take the one inside the PD interval closest to zero (least anisotropy).
        let c = (lambda + mu) * (young_fiber_pa - e_t - 2.0 * delta_mu);
        let b = lambda - mu;
        let disc = (b * b - 4.0 * c).max(0.0).sqrt();
        let roots = [(-b - disc) / 2.0, (-b + disc) / 2.0];
        let dl = roots
            .into_iter()
            .filter(|r| *r > lo && *r < hi)
            .min_by(|a, b| a.abs().total_cmp(&b.abs()))
            .ok_or_else(|| out_of_range(min_pa, max_pa))?;
        Self::new(transverse, dl, delta_mu, Terms::ALL)
    }

    /// The transverse Lame constants.
    pub fn transverse(&self) -> Isotropic {
        self.transverse
    }

    /// lambda_L - lambda_T (Pa).
    pub fn delta_lambda_pa(&self) -> Real {
        self.delta_lambda_pa
    }

    /// mu_L - mu_T (Pa).
    pub fn delta_mu_pa(&self) -> Real {
        self.delta_mu_pa
    }

    /// The enabled energy terms.
    pub fn terms(&self) -> Terms {
        self.terms
    }

    /// The 6x6 Voigt stiffness for a fibre along z (order xx yy zz yz xz xy,
    /// engineering shear strains), with only the enabled terms.
    pub fn voigt_fiber_z(&self) -> [[Real; 6]; 6] {
        let (l, m) = (self.transverse.lambda_pa, self.transverse.mu_pa);
        let (ts, tc, th) = self.terms.factors();
        let (dl, dm) = (self.delta_lambda_pa, self.delta_mu_pa);
        let c13 = l + tc * dl;
        let c33 = l + 2.0 * m + ts * (dl + 2.0 * dm);
        let c44 = m + th * dm;
        [
            [l + 2.0 * m, l, c13, 0.0, 0.0, 0.0],
            [l, l + 2.0 * m, c13, 0.0, 0.0, 0.0],
            [c13, c13, c33, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, c44, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, c44, 0.0],
            [0.0, 0.0, 0.0, 0.0, 0.0, m],
        ]
    }

    /// Engineering constants from the compliance (inverse of the normal block).
    pub fn engineering(&self) -> EngineeringConstants {
        let c = self.voigt_fiber_z();
        let s = invert3([
            [c[0][0], c[0][1], c[0][2]],
            [c[1][0], c[1][1], c[1][2]],
            [c[2][0], c[2][1], c[2][2]],
        ]);
        EngineeringConstants {
            young_fiber_pa: 1.0 / s[2][2],
            young_transverse_pa: 1.0 / s[0][0],
            poisson_fiber_transverse: -s[0][2] / s[2][2],
            poisson_transverse: -s[1][0] / s[0][0],
            poisson_transverse_fiber: -s[2][0] / s[0][0],
            shear_fiber_pa: c[3][3],
        }
    }
}

/// The open interval where a2 x^2 + a1 x + a0 < 0 (a2 >= 0), as (lo, hi);
/// empty intervals come back with lo >= hi.
fn negative_interval(a2: Real, a1: Real, a0: Real) -> (Real, Real) {
    if a2 > 0.0 {
        let disc = a1 * a1 - 4.0 * a2 * a0;
        if disc <= 0.0 {
            return (0.0, 0.0);
        }
        let s = disc.sqrt();
        ((-a1 - s) / (2.0 * a2), (-a1 + s) / (2.0 * a2))
    } else if a1 > 0.0 {
        (Real::NEG_INFINITY, -a0 / a1)
    } else if a1 < 0.0 {
        (-a0 / a1, Real::INFINITY)
    } else if a0 < 0.0 {
        (Real::NEG_INFINITY, Real::INFINITY)
    } else {
        (0.0, 0.0)
    }
}

fn invert3(m: [[Real; 3]; 3]) -> [[Real; 3]; 3] {
    let a = crate::math::Mat3::from_cols_array_2d(&m).transpose();
    let inv = a.inverse().transpose();
    inv.to_cols_array_2d()
}
