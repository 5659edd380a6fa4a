//! Which material and fibre direction each tetrahedron uses.
//!
//! A small table of materials plus a per-tetrahedron index keeps this compact
//! on million-element meshes; fibre directions are stored only once some
//! tetrahedron is given one, so an isotropic scene pays nothing for them.

use crate::ids::TetId;
use crate::material::Material;
use crate::math::{Real, Vec3};
use thiserror::Error;

/// Index of a material in a [`TetMaterials`] table.
#[repr(transparent)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MaterialId(pub u16);

/// Why a material assignment was refused.
#[derive(Debug, Error, PartialEq)]
pub enum AssignError {
    /// The tetrahedron does not exist.
    #[error("tetrahedron {tet} does not exist (the mesh has {count})")]
    NoSuchTet {
        /// The index given.
        tet: usize,
        /// Number of tetrahedra.
        count: usize,
    },
    /// The fibre direction is zero or not finite.
    #[error("fibre direction {dir:?} of tetrahedron {tet} is not a finite non-zero vector")]
    BadFiber {
        /// The tetrahedron.
        tet: usize,
        /// The direction given.
        dir: [Real; 3],
    },
    /// Too many distinct materials.
    #[error("at most 65535 materials are supported")]
    TooMany,
    /// An anisotropic tetrahedron lacks a fibre direction.
    #[error("tetrahedron {tet} uses a transversally isotropic material but has no fibre direction")]
    MissingFiber {
        /// The tetrahedron.
        tet: usize,
    },
}

/// Per-tetrahedron materials and fibre directions.
#[derive(Clone, Debug)]
pub struct TetMaterials {
    table: Vec<Material>,
    index: Vec<MaterialId>,
    fibers: Vec<Vec3>,
}

impl TetMaterials {
    /// Every one of `tet_count` tetrahedra uses `material`.
    pub fn uniform(material: Material, tet_count: usize) -> Self {
        Self {
            table: vec![material],
            index: vec![MaterialId(0); tet_count],
            fibers: Vec::new(),
        }
    }

    /// Adds a material to the table.
    pub fn add(&mut self, material: Material) -> Result<MaterialId, AssignError> {
        if self.table.len() >= u16::MAX as usize {
            return Err(AssignError::TooMany);
        }
        self.table.push(material);
        Ok(MaterialId((self.table.len() - 1) as u16))
    }

    fn check(&self, t: TetId) -> Result<(), AssignError> {
        if t.idx() < self.index.len() {
            Ok(())
        } else {
            Err(AssignError::NoSuchTet {
                tet: t.idx(),
                count: self.index.len(),
            })
        }
    }

    /// Tetrahedron `t` uses material `m`.
    pub fn assign(&mut self, t: TetId, m: MaterialId) -> Result<(), AssignError> {
        self.check(t)?;
        assert!(
            (m.0 as usize) < self.table.len(),
            "material id from another table"
        );
        self.index[t.idx()] = m;
        Ok(())
    }

    /// Sets the fibre direction of `t` (normalised here).
    pub fn set_fiber(&mut self, t: TetId, dir: Vec3) -> Result<(), AssignError> {
        self.check(t)?;
        let len = dir.length();
        if !(len.is_finite() && len > 0.0) {
            return Err(AssignError::BadFiber {
                tet: t.idx(),
                dir: dir.to_array(),
            });
        }
        if self.fibers.is_empty() {
            self.fibers = vec![Vec3::ZERO; self.index.len()];
        }
        self.fibers[t.idx()] = dir / len;
        Ok(())
    }

    /// Every material with strain model `model` (constants and fibres kept).
    pub fn with_model(mut self, model: crate::material::MaterialModel) -> Self {
        for m in &mut self.table {
            *m = m.with_model(model);
        }
        self
    }

    /// The materials of `tets` (in that order) as a map of their own.
    pub fn subset(&self, tets: &[TetId]) -> Self {
        Self {
            table: self.table.clone(),
            index: tets.iter().map(|t| self.index[t.idx()]).collect(),
            fibers: if self.fibers.is_empty() {
                Vec::new()
            } else {
                tets.iter().map(|t| self.fibers[t.idx()]).collect()
            },
        }
    }

    /// The material of `t`.
    pub fn material(&self, t: TetId) -> &Material {
        &self.table[self.index[t.idx()].0 as usize]
    }

    /// The fibre of `t` (zero when none was set).
    pub fn fiber(&self, t: TetId) -> Vec3 {
        self.fibers.get(t.idx()).copied().unwrap_or(Vec3::ZERO)
    }

    /// Number of tetrahedra covered.
    pub fn len(&self) -> usize {
        self.index.len()
    }

    /// Whether no tetrahedra are covered.
    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// Checks that every anisotropic tetrahedron has a fibre.
    pub fn validate(&self) -> Result<(), AssignError> {
        for t in 0..self.index.len() {
            let t = TetId::from(t);
            if self.material(t).is_anisotropic() && self.fiber(t) == Vec3::ZERO {
                return Err(AssignError::MissingFiber { tet: t.idx() });
            }
        }
        Ok(())
    }

    /// Whether any tetrahedron is anisotropic.
    pub fn any_anisotropic(&self) -> bool {
        self.table.iter().any(Material::is_anisotropic)
            && self
                .index
                .iter()
                .any(|m| self.table[m.0 as usize].is_anisotropic())
    }
}
