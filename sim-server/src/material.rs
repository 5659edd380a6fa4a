//! Linear elastic materials: isotropic, and transversally isotropic in the
//! paper's 4-parameter form (transverse Lame constants plus delta-lambda and
//! delta-mu along a fibre), with each anisotropic energy term switchable.
//!
//! Every constructor checks positive definiteness and refuses impossible input
//! with the admissible range in the message.

use crate::math::Real;
use thiserror::Error;

/// Why a material was refused.
#[derive(Debug, Error, PartialEq)]
pub enum MaterialError {
    /// Young's modulus must be positive.
    #[error("young_pa must be a positive finite number, got {0}")]
    Young(Real),
    /// Poisson's ratio must lie in (-1, 0.5).
    #[error("poisson must lie in (-1, 0.5) for a stable isotropic solid, got {0}")]
    Poisson(Real),
    /// Lame constants that make the isotropic energy indefinite.
    #[error(
        "Lame constants lambda={lambda_pa} Pa, mu={mu_pa} Pa are not positive definite: need mu > 0 and lambda > -2 mu / 3 = {lambda_min_pa} Pa"
    )]
    Lame {
        /// lambda (Pa).
        lambda_pa: Real,
        /// mu (Pa).
        mu_pa: Real,
        /// The smallest admissible lambda for this mu.
        lambda_min_pa: Real,
    },
    /// Density must be positive.
    #[error("density_kg_m3 must be a positive finite number, got {0}")]
    Density(Real),
    /// Damping must be non-negative.
    #[error("damping_per_s must be a finite number >= 0, got {0}")]
    Damping(Real),
    /// A non-finite anisotropy parameter.
    #[error("{field} must be finite, got {value}")]
    NonFinite {
        /// The field name.
        field: &'static str,
        /// The value.
        value: Real,
    },
    /// delta_mu too negative: the shear modulus along the fibre would be <= 0.
    #[error(
        "delta_mu_pa = {delta_mu_pa} Pa makes the fibre shear modulus mu + delta_mu <= 0; it must exceed {min_pa} Pa"
    )]
    DeltaMu {
        /// The value given.
        delta_mu_pa: Real,
        /// The bound (-mu).
        min_pa: Real,
    },
    /// delta_lambda outside the positive-definite interval for this delta_mu.
    #[error(
        "delta_lambda_pa = {delta_lambda_pa} Pa is not positive definite with delta_mu_pa = {delta_mu_pa} Pa and terms {terms}: it must lie in ({min_pa}, {max_pa}) Pa"
    )]
    DeltaLambda {
        /// The value given.
        delta_lambda_pa: Real,
        /// The delta_mu it was checked with.
        delta_mu_pa: Real,
        /// Lower end of the admissible open interval (may be -inf).
        min_pa: Real,
        /// Upper end (may be +inf).
        max_pa: Real,
        /// The enabled terms.
        terms: Terms,
    },
    /// Engineering constants the 4-parameter model cannot represent.
    #[error(
        "young_fiber_pa = {young_fiber_pa} Pa with shear_fiber_pa = {shear_fiber_pa} Pa cannot be represented by the paper's 4-parameter model with these transverse constants: young_fiber_pa must lie in ({min_pa}, {max_pa}] Pa"
    )]
    Engineering {
        /// E_L given.
        young_fiber_pa: Real,
        /// G_LT given.
        shear_fiber_pa: Real,
        /// Lower end of the representable range for this G_LT.
        min_pa: Real,
        /// Upper end.
        max_pa: Real,
    },
}

/// Isotropic Lame constants (Pa), validated positive definite.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Isotropic {
    lambda_pa: Real,
    mu_pa: Real,
}

impl Isotropic {
    /// From Young's modulus (Pa) and Poisson's ratio.
    pub fn from_young_poisson(young_pa: Real, poisson: Real) -> Result<Self, MaterialError> {
        if !(young_pa.is_finite() && young_pa > 0.0) {
            return Err(MaterialError::Young(young_pa));
        }
        if !(poisson.is_finite() && poisson > -1.0 && poisson < 0.5) {
            return Err(MaterialError::Poisson(poisson));
        }
        let lambda = young_pa * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
        let mu = young_pa / (2.0 * (1.0 + poisson));
        Self::from_lame(lambda, mu)
    }

    /// From the Lame constants (Pa).
    pub fn from_lame(lambda_pa: Real, mu_pa: Real) -> Result<Self, MaterialError> {
        let ok = lambda_pa.is_finite() && mu_pa.is_finite() && mu_pa > 0.0;
        if !ok || 3.0 * lambda_pa + 2.0 * mu_pa <= 0.0 {
            return Err(MaterialError::Lame {
                lambda_pa,
                mu_pa,
                lambda_min_pa: -2.0 * mu_pa / 3.0,
            });
        }
        Ok(Self { lambda_pa, mu_pa })
    }

    /// lambda (Pa).
    pub fn lambda_pa(&self) -> Real {
        self.lambda_pa
    }

    /// mu, the shear modulus (Pa).
    pub fn mu_pa(&self) -> Real {
        self.mu_pa
    }

    /// Young's modulus (Pa).
    pub fn young_pa(&self) -> Real {
        let (l, m) = (self.lambda_pa, self.mu_pa);
        m * (3.0 * l + 2.0 * m) / (l + m)
    }

    /// Poisson's ratio.
    pub fn poisson(&self) -> Real {
        self.lambda_pa / (2.0 * (self.lambda_pa + self.mu_pa))
    }
}

/// Which anisotropic energy terms are enabled (paper eqs 9-11).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Terms {
    /// Stretch along the fibre, eq 9: (d_lambda/2 + d_mu) I4^2.
    pub stretch: bool,
    /// Cross-stretch, eq 10: d_lambda (I1 I4 - I4^2).
    pub cross: bool,
    /// Shear, eq 11: 2 d_mu (I5 - I4^2).
    pub shear: bool,
}

impl Terms {
    /// All three terms: the full transversally isotropic material.
    pub const ALL: Terms = Terms {
        stretch: true,
        cross: true,
        shear: true,
    };
    /// Only the stretch term (a "fibre" that only resists extension).
    pub const STRETCH: Terms = Terms {
        stretch: true,
        cross: false,
        shear: false,
    };

    /// The 0/1 multipliers (stretch, cross, shear).
    pub fn factors(&self) -> (Real, Real, Real) {
        let f = |b: bool| if b { 1.0 } else { 0.0 };
        (f(self.stretch), f(self.cross), f(self.shear))
    }
}

impl std::fmt::Display for Terms {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let names: Vec<&str> = [
            (self.stretch, "stretch"),
            (self.cross, "cross"),
            (self.shear, "shear"),
        ]
        .iter()
        .filter(|(on, _)| *on)
        .map(|(_, n)| *n)
        .collect();
        write!(f, "[{}]", names.join(", "))
    }
}

/// The elastic part of a material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Elasticity {
    /// Isotropic.
    Isotropic(Isotropic),
    /// Transversally isotropic; the fibre direction is per tetrahedron.
    Transverse(TransverselyIsotropic),
}

/// Transversally isotropic constants in the paper's form: the transverse
/// (isotropic-plane) Lame constants and the differences along the fibre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransverselyIsotropic {
    transverse: Isotropic,
    delta_lambda_pa: Real,
    delta_mu_pa: Real,
    terms: Terms,
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

/// A complete material: elasticity, density and mass-proportional damping.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    elasticity: Elasticity,
    density_kg_m3: Real,
    damping_per_s: Real,
}

impl Material {
    /// Validates density (> 0) and damping (>= 0, per second: the damping force
    /// on a vertex is `-damping_per_s * m_i * velocity`).
    pub fn new(
        elasticity: Elasticity,
        density_kg_m3: Real,
        damping_per_s: Real,
    ) -> Result<Self, MaterialError> {
        if !(density_kg_m3.is_finite() && density_kg_m3 > 0.0) {
            return Err(MaterialError::Density(density_kg_m3));
        }
        if !(damping_per_s.is_finite() && damping_per_s >= 0.0) {
            return Err(MaterialError::Damping(damping_per_s));
        }
        Ok(Self {
            elasticity,
            density_kg_m3,
            damping_per_s,
        })
    }

    /// Shorthand for an isotropic material from Young/Poisson.
    pub fn isotropic(
        young_pa: Real,
        poisson: Real,
        density_kg_m3: Real,
        damping_per_s: Real,
    ) -> Result<Self, MaterialError> {
        let iso = Isotropic::from_young_poisson(young_pa, poisson)?;
        Self::new(Elasticity::Isotropic(iso), density_kg_m3, damping_per_s)
    }

    /// The elastic constants.
    pub fn elasticity(&self) -> &Elasticity {
        &self.elasticity
    }

    /// Density (kg/m^3).
    pub fn density_kg_m3(&self) -> Real {
        self.density_kg_m3
    }

    /// Mass-proportional damping (1/s).
    pub fn damping_per_s(&self) -> Real {
        self.damping_per_s
    }

    /// The transverse (or isotropic) Lame constants.
    pub fn lame(&self) -> Isotropic {
        match self.elasticity {
            Elasticity::Isotropic(i) => i,
            Elasticity::Transverse(t) => t.transverse,
        }
    }

    /// Whether the material is anisotropic.
    pub fn is_anisotropic(&self) -> bool {
        matches!(self.elasticity, Elasticity::Transverse(_))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn liver() -> Isotropic {
        Isotropic::from_young_poisson(4500.0, 0.45).unwrap()
    }

    #[test]
    fn young_poisson_round_trip() {
        let m = liver();
        assert!((m.young_pa() - 4500.0).abs() < 1e-9);
        assert!((m.poisson() - 0.45).abs() < 1e-12);
        assert!(Isotropic::from_young_poisson(1.0, 0.5).is_err());
        assert!(Isotropic::from_young_poisson(-1.0, 0.3).is_err());
        // lambda must exceed -2 mu / 3 = -0.8 Pa for mu = 1.2 Pa.
        assert!(Isotropic::from_lame(-0.79, 1.2).is_ok());
        let e = Isotropic::from_lame(-0.81, 1.2).unwrap_err().to_string();
        assert!(e.contains("-0.8"), "{e}");
    }

    #[test]
    fn refusals_name_the_admissible_range() {
        let t = liver();
        let err = TransverselyIsotropic::new(t, 0.0, -2.0 * t.mu_pa(), Terms::ALL).unwrap_err();
        assert!(err.to_string().contains("must exceed"), "{err}");
        let err = TransverselyIsotropic::new(t, 1e9, 0.0, Terms::ALL).unwrap_err();
        let MaterialError::DeltaLambda { min_pa, max_pa, .. } = err else {
            panic!("{err}")
        };
        // Just inside the interval is accepted, just outside refused.
        let inside = min_pa + 1e-6 * (max_pa - min_pa);
        assert!(TransverselyIsotropic::new(t, inside, 0.0, Terms::ALL).is_ok());
        assert!(TransverselyIsotropic::new(t, max_pa * 1.0001, 0.0, Terms::ALL).is_err());
        assert!(
            TransverselyIsotropic::new(t, min_pa - 1e-3 * min_pa.abs(), 0.0, Terms::ALL).is_err()
        );
    }

    /// The interval from the closed form agrees with a direct eigen check of
    /// the Voigt matrix, for every subset of terms.
    #[test]
    fn pd_interval_matches_voigt_eigenvalues() {
        let t = liver();
        for bits in 1..8u8 {
            let terms = Terms {
                stretch: bits & 1 != 0,
                cross: bits & 2 != 0,
                shear: bits & 4 != 0,
            };
            for dm in [-0.5 * t.mu_pa(), 0.0, 3.0 * t.mu_pa()] {
                for k in -40..=40 {
                    let dl = k as Real * 2000.0;
                    let accepted = TransverselyIsotropic::new(t, dl, dm, terms).is_ok();
                    let c = TransverselyIsotropic {
                        transverse: t,
                        delta_lambda_pa: dl,
                        delta_mu_pa: dm,
                        terms,
                    }
                    .voigt_fiber_z();
                    let m = nalgebra::Matrix6::from_fn(|i, j| c[i][j]);
                    let min_eig = m.symmetric_eigen().eigenvalues.min();
                    let pd = min_eig > 1e-9 * t.mu_pa();
                    if (min_eig.abs() > 1e-6 * t.mu_pa()) || accepted == pd {
                        assert_eq!(
                            accepted, pd,
                            "terms {terms} dl {dl} dm {dm}: min eig {min_eig}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn engineering_constants_round_trip() {
        for t in [liver(), Isotropic::from_young_poisson(4500.0, 0.3).unwrap()] {
            let mu = t.mu_pa();
            for (dl, dm) in [
                (0.0, mu),
                (-0.2 * mu, 3.0 * mu),
                (0.5 * mu, -0.3 * mu),
                (2.0 * mu, 0.0),
            ] {
                let Ok(m) = TransverselyIsotropic::new(t, dl, dm, Terms::ALL) else {
                    continue;
                };
                let eng = m.engineering();
                let back = TransverselyIsotropic::from_engineering(
                    t,
                    eng.young_fiber_pa,
                    eng.shear_fiber_pa,
                )
                .unwrap_or_else(|e| panic!("{eng:?}: {e}"));
                let again = back.engineering();
                assert!(
                    (again.young_fiber_pa - eng.young_fiber_pa).abs() < 1e-8 * eng.young_fiber_pa
                );
                assert!(
                    (again.shear_fiber_pa - eng.shear_fiber_pa).abs() < 1e-9 * eng.shear_fiber_pa
                );
                // The paper's closed forms agree with the compliance.
                let (l, dl, dm) = (t.lambda_pa(), m.delta_lambda_pa(), m.delta_mu_pa());
                let nu_lt = (l + dl) / (2.0 * (l + mu));
                assert!((eng.poisson_fiber_transverse - nu_lt).abs() < 1e-12);
                let e_l = t.young_pa() + 2.0 * dm - dl * (dl + l - mu) / (l + mu);
                assert!((eng.young_fiber_pa - e_l).abs() < 1e-9 * e_l);
            }
        }
        // A fibre three times stiffer with twice the shear is out of reach of
        // the 4-parameter model when the transverse plane is nearly
        // incompressible (C33 - C13 = 2 C44 ties them): refused with the range.
        let err = TransverselyIsotropic::from_engineering(liver(), 13500.0, 3104.0).unwrap_err();
        let MaterialError::Engineering { max_pa, .. } = err else {
            panic!("{err}")
        };
        assert!(
            max_pa < 13500.0 && err.to_string().contains("must lie in"),
            "{err}"
        );
        assert!(TransverselyIsotropic::from_engineering(liver(), 0.99 * max_pa, 3104.0).is_ok());
    }

    #[test]
    fn density_and_damping_checked() {
        assert!(Material::isotropic(4500.0, 0.45, 0.0, 1.0).is_err());
        assert!(Material::isotropic(4500.0, 0.45, 1060.0, -1.0).is_err());
        assert!(Material::isotropic(4500.0, 0.45, 1060.0, 0.0).is_ok());
    }
}
