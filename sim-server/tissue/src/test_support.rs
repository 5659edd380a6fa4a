//! Fixtures the physics-law tests share: meshes, materials and models
//! built the same way in the core's tests and the simulation server's
//! (feature `test-support`; not part of a running process). The fixtures
//! panic on a fixture that cannot be built: they are for tests.
#![allow(clippy::missing_panics_doc)]

use crate::material::MaterialError;
use crate::prelude::*;

/// A deterministic xorshift generator in [-0.5, 0.5).
pub struct Rng(u64);

impl Rng {
    /// A generator seeded by `seed` (any value; zero is made odd).
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    /// The next number, in [-0.5, 0.5).
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
    /// A vector of three next numbers.
    pub fn vec3(&mut self) -> Vec3 {
        Vec3::new(self.next(), self.next(), self.next())
    }
}

/// A box mesh of `cells` cubes of edge `h`, interior vertices moved randomly
/// by up to `jitter * h` (the patch test wants a mesh that is not structured).
pub fn box_mesh(cells: [usize; 3], h: f64, jitter: f64, seed: u64) -> TetMesh {
    let size = Vec3::new(cells[0] as f64, cells[1] as f64, cells[2] as f64) * h;
    let mesh = BoxSpec::new(size, CellSize::EdgeM(h)).generate().unwrap();
    if jitter == 0.0 {
        return mesh;
    }
    let mut rng = Rng::new(seed);
    let eps = 1e-9 * h;
    let positions: Vec<Vec3> = mesh
        .positions_m()
        .iter()
        .map(|p| {
            let interior = (0..3).all(|a| p[a] > eps && p[a] < size[a] - eps);
            if interior {
                *p + rng.vec3() * (2.0 * jitter * h)
            } else {
                *p
            }
        })
        .collect();
    let tets = mesh.tets().iter().map(|t| t.map(|v| v.0)).collect();
    let out = TetMesh::new(positions, tets).unwrap();
    assert_eq!(out.reoriented(), 0, "jitter too large: elements inverted");
    out
}

/// The liver's isotropic constants (E 4500 Pa, nu 0.45).
pub fn liver_iso() -> Isotropic {
    Isotropic::from_young_poisson(4500.0, 0.45).unwrap()
}

/// The liver's isotropic material (density 1060 kg/m^3, no damping).
pub fn iso_material() -> Material {
    Material::isotropic(4500.0, 0.45, 1060.0, 0.0).unwrap()
}

/// A transversely isotropic material on [`liver_iso`] with the fibre
/// constants `dl`, `dm` (Pa) and the anisotropic `terms`.
///
/// # Errors
/// The material's own when the constants are not admissible.
pub fn aniso_material(dl: f64, dm: f64, terms: Terms) -> Result<Material, MaterialError> {
    let t = TransverselyIsotropic::new(liver_iso(), dl, dm, terms)?;
    Material::new(Elasticity::Transverse(t), 1060.0, 0.0)
}

/// Every subset of anisotropic terms with realistic constants.
pub fn term_sets() -> Vec<Terms> {
    (1..8u8)
        .map(|b| Terms {
            stretch: b & 1 != 0,
            cross: b & 2 != 0,
            shear: b & 4 != 0,
        })
        .collect()
}

/// A model with a mix: isotropic tetrahedra and anisotropic ones with random
/// fibres (each its own direction).
pub fn mixed_model(mesh: TetMesh, terms: Terms, seed: u64) -> ElasticModel {
    let mut rng = Rng::new(seed);
    let n = mesh.tet_count();
    let mut mats = TetMaterials::uniform(iso_material(), n);
    let mu = liver_iso().mu_pa();
    let aniso = mats
        .add(aniso_material(0.8 * mu, 2.0 * mu, terms).unwrap())
        .unwrap();
    for t in (0..n).filter(|t| t % 3 != 0) {
        mats.assign(TetId::from(t), aniso).unwrap();
        mats.set_fiber(TetId::from(t), rng.vec3() + Vec3::new(0.0, 0.0, 0.1))
            .unwrap();
    }
    ElasticModel::new(mesh, mats).unwrap()
}

/// Max absolute entry over a slice of tensors.
pub fn max_entry(ms: &[Mat3]) -> f64 {
    ms.iter().map(crate::math::max_abs).fold(0.0, f64::max)
}

/// A dense symmetric matrix's eigenvalues, ascending.
pub fn sym_eigenvalues(n: usize, rowmajor: &[f64]) -> Vec<f64> {
    let m = nalgebra::DMatrix::from_row_slice(n, n, rowmajor);
    let mut ev: Vec<f64> = m.symmetric_eigen().eigenvalues.iter().copied().collect();
    ev.sort_by(f64::total_cmp);
    ev
}

/// The 4 x 2 x 2 cm block of the backend tests (nu 0.45, 30 /s damping).
pub const BLOCK_M: [f64; 3] = [0.04, 0.02, 0.02];

/// [`BLOCK_M`] meshed with cells of `cell_m`.
pub fn block(cell_m: f64) -> ElasticModel {
    let mesh = BoxSpec::new(Vec3::from_array(BLOCK_M), CellSize::EdgeM(cell_m))
        .generate()
        .unwrap();
    let tissue = Material::isotropic(5000.0, 0.45, 1000.0, 30.0).unwrap();
    let materials = TetMaterials::uniform(tissue, mesh.tet_count());
    ElasticModel::new(mesh, materials).unwrap()
}
