//! What the simulation process needs around the [`tissue`] core, as a
//! library: scenes (TOML), mesh file formats and the recorded frame
//! series, a scene made ready to step ([`prepare`]), the force sample on
//! the wire ([`wire`]) and the benchmarks. The process itself (the
//! `sim-server run` loop that joins a session, the CLI) is the binary's. The core's modules are re-exported here under their
//! own names, so `sim_server::tensor_mass` is `tissue::tensor_mass`.
//!
//! ```
//! use sim_server::prelude::*;
//! use sim_server::scene::{SceneSource, build_scene};
//!
//! // The embedded liver scene, built and stepped without a session.
//! let src = SceneSource::embedded();
//! let scene = build_scene(&src, &src.parse()?)?;
//! let mut p = sim_server::prepare::prepare::<f32>(scene, None)?;
//! use sim_server::backend::Backend;
//! p.sim.step();
//! assert!(p.sim.displacements().iter().flatten().all(|x| x.is_finite()));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![warn(missing_docs)]

pub use tissue::{
    backend, background, contact, ids, material, material_map, math, membrane, prelude,
    static_newton, static_solve, tensor_mass, topology,
};

pub mod bench;
pub mod follow_refine;
pub mod frames;
pub mod input_file;
pub mod prepare;
pub mod provenance;
pub mod scene;
pub mod step_time;
pub mod wire;

/// Tetrahedral meshes ([`tissue::mesh`]), their file formats
/// ([`io`](crate::mesh::io)) and surfaces meshed into them
/// ([`tetrahedralize`](crate::mesh::tetrahedralize)).
pub mod mesh {
    pub use tissue::mesh::*;
    pub mod improve;
    pub mod io;
    pub mod tetrahedralize;
}
