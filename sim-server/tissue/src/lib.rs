//! The soft-tissue core of the surgery simulator (no file formats, no
//! scenes, no processes: those are `sim-server`'s): tensor-mass linear FEM on
//! tetrahedra (Picinbono, Lombardo, Delingette, Ayache 2002) with
//! transversally isotropic anisotropy, explicit integration with a checked
//! stable step, cutting by tetrahedron removal, and a static solver.
//!
//! ```
//! use tissue::prelude::*;
//!
//! // A 4 x 2 x 2 cm block of liver-like tissue, 5 mm cells.
//! let mesh = BoxSpec::new(Vec3::new(0.04, 0.02, 0.02), CellSize::EdgeM(0.005)).generate()?;
//! let tissue = Material::isotropic(4500.0, 0.45, 1060.0, 20.0)?;
//! let materials = TetMaterials::uniform(tissue, mesh.tet_count());
//! let model = ElasticModel::new(mesh, materials)?;
//!
//! // 1 ms steps, sub-stepped if that is above the stable step.
//! let mut sim = Explicit::<f32>::new(model, ExplicitConfig::new(1e-3))?;
//! for v in 0..sim.model().vertex_count() {
//!     let v = VertexId::from(v);
//!     let p = sim.model().mesh().positions_m()[v.idx()];
//!     if p.x == 0.0 {
//!         sim.fix(v); // clamp the left face
//!     } else if p.x > 0.0399 {
//!         sim.set_external_force(v, Vec3::new(0.0, 0.0, -1e-3)); // pull the right face down
//!     }
//! }
//! for _ in 0..100 {
//!     sim.step();
//! }
//! sim.remove_tet(TetId(0))?; // cut
//! sim.step();
//! assert!(sim.displacements().iter().flatten().all(|x| x.is_finite()));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![warn(missing_docs)]

pub mod backend;
pub mod background;
pub mod contact;
mod dense_lu;
pub mod ids;
pub mod material;
pub mod material_map;
pub mod math;
pub mod membrane;
pub mod mesh;
pub mod static_newton;
pub mod static_solve;
pub mod tensor_mass;
#[cfg(feature = "test-support")]
pub mod test_support;
pub mod topology;

/// The types most programs need.
pub mod prelude {
    pub use crate::ids::{EdgeId, TetId, VertexId};
    pub use crate::material::{Elasticity, Isotropic, Material, Terms, TransverselyIsotropic};
    pub use crate::material_map::{MaterialId, TetMaterials};
    pub use crate::math::{Mat3, Real, Vec3};
    pub use crate::mesh::{BoxSpec, CellSize, TetMesh};
    pub use crate::static_solve::{Dirichlet, StaticSolution, solve_static};
    pub use crate::tensor_mass::{
        BoundMethod, DtPolicy, ElasticModel, Explicit, ExplicitConfig, StableStep,
    };
}
