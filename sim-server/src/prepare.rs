//! A scene made ready to step: the library's entry point from a built
//! scene to a backend with its constraints, loads and tools (used by
//! `sim-server run`, hapbench and the tests).

use crate::backend::Backend;
use crate::contact::Tools;
use crate::math::{Real, Vec3};
use crate::scene::BuiltScene;
use crate::tensor_mass::{Explicit, ExplicitConfig, Storage};
use shared::protocol::MAX_TOOLS;
use thiserror::Error;

/// Why a scene could not be set up on a backend.
#[derive(Debug, Error)]
pub enum PrepareError<E: std::error::Error + 'static> {
    /// The backend refused the model or the step.
    #[error(transparent)]
    Backend(E),
    /// The contact cannot run as the scene asks.
    #[error(transparent)]
    Contact(#[from] crate::contact::ContactError),
}

/// A scene ready to step: the integrator with the scene's fixed vertices,
/// prescribed displacements and loads applied, and its tools.
pub struct Prepared<B: Backend> {
    /// The backend.
    pub sim: B,
    /// The scene's tools (at most `MAX_TOOLS`), scene-held vertices reserved.
    pub tools: Tools,
    /// The step (s).
    pub dt_s: Real,
    /// Each vertex's index before the scene renumbered them, if it did.
    pub original_vertex_ids: Option<Vec<u32>>,
}

/// Sets `scene` up for stepping with the explicit tensor-mass integrator at
/// `dt_s` (default: the scene's, else 90% of the stable step; a larger one
/// is sub-stepped or refused as the scene says).
pub fn prepare<S: Storage>(
    scene: BuiltScene,
    dt_s: Option<Real>,
) -> Result<Prepared<Explicit<S>>, PrepareError<crate::tensor_mass::ExplicitError>> {
    prepare_with(scene, dt_s, |model, settings, dt_s| {
        let mut sim = Explicit::<S>::new(
            model,
            ExplicitConfig {
                dt_s,
                policy: settings.policy,
                bound: settings.bound,
                threads: settings.threads,
            },
        )?;
        if settings.multirate {
            sim.set_multirate(true)?;
        }
        Ok(sim)
    })
}

/// Sets `scene` up on the backend `make` builds from the model, the
/// scene's settings and the step (`dt_s`, else the scene's, else 90% of the
/// explicit stable step).
pub fn prepare_with<B: Backend, E: std::error::Error + 'static>(
    scene: BuiltScene,
    dt_s: Option<Real>,
    make: impl FnOnce(
        crate::tensor_mass::ElasticModel,
        &crate::scene::SimSettings,
        Real,
    ) -> Result<B, E>,
) -> Result<Prepared<B>, PrepareError<E>> {
    let BuiltScene {
        model,
        fixed,
        prescribed,
        loads_n,
        tools,
        settings,
        contact,
        original_vertex_ids,
        ..
    } = scene;
    // The bound only when no step is given: backends that need it compute
    // their own, and it costs an eigenproblem per tetrahedron.
    let dt_s = dt_s
        .or(settings.dt_s)
        .unwrap_or_else(|| 0.9 * crate::tensor_mass::element_bound(&model).dt_max_s);
    let mut sim = make(model, &settings, dt_s).map_err(PrepareError::Backend)?;
    for v in &fixed {
        sim.fix(*v);
    }
    for (v, d) in &prescribed {
        sim.prescribe(*v, *d);
    }
    for (v, f) in loads_n.iter().enumerate() {
        if *f != Vec3::ZERO {
            sim.set_external_force(crate::ids::VertexId::from(v), *f);
        }
    }
    let decls = &tools[..tools.len().min(MAX_TOOLS)];
    // A tool never takes over (or releases) a vertex the scene holds.
    let held: Vec<_> = fixed
        .iter()
        .copied()
        .chain(prescribed.iter().map(|(v, _)| *v))
        .collect();
    let contacts = Tools::with_config(decls, &mut sim, &contact, &held)?;
    Ok(Prepared {
        sim,
        tools: contacts,
        dt_s,
        original_vertex_ids,
    })
}
