//! Linear elastic materials: isotropic, and transversally isotropic in the
//! paper's 4-parameter form (transverse Lame constants plus delta-lambda and
//! delta-mu along a fibre), with each anisotropic energy term switchable.
//!
//! Every constructor checks positive definiteness and refuses impossible input
//! with the admissible range in the message.

mod transverse;

pub use transverse::{EngineeringConstants, TransverselyIsotropic};

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

/// How strain is measured: the paper's linear model, or one valid for
/// large displacements with the same constants and energy terms.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum MaterialModel {
    /// Linearised strain (the paper): fastest, valid for displacements
    /// under about a tenth of the mesh size; a rotation is not force-free.
    #[default]
    Linear,
    /// St Venant-Kirchhoff: the same energy in the Green-Lagrange strain
    /// (Picinbono, Delingette, Ayache 2003).
    Stvk,
    /// Corotational: the linear energy in each element's rotated frame
    /// (polar rotation), as in SOFA's corotational FEM.
    Corotational,
}

impl MaterialModel {
    /// The scene-file name.
    pub fn name(&self) -> &'static str {
        match self {
            MaterialModel::Linear => "linear",
            MaterialModel::Stvk => "stvk",
            MaterialModel::Corotational => "corotational",
        }
    }

    /// Whether the forces are nonlinear in the displacements.
    pub fn is_nonlinear(&self) -> bool {
        *self != MaterialModel::Linear
    }
}

/// A complete material: elasticity, density, mass-proportional damping and
/// the strain model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    elasticity: Elasticity,
    density_kg_m3: Real,
    damping_per_s: Real,
    model: MaterialModel,
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
            model: MaterialModel::Linear,
        })
    }

    /// The same material with strain model `model`.
    pub fn with_model(self, model: MaterialModel) -> Self {
        Self { model, ..self }
    }

    /// The strain model.
    pub fn model(&self) -> MaterialModel {
        self.model
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
            Elasticity::Transverse(t) => t.transverse(),
        }
    }

    /// Whether the material is anisotropic.
    pub fn is_anisotropic(&self) -> bool {
        matches!(self.elasticity, Elasticity::Transverse(_))
    }
}

#[cfg(test)]
mod tests;
