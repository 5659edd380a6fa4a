//! Subcommand implementations of the `sim-server` binary (the clap
//! definitions are in main.rs).

pub mod bridge;
pub mod check;
pub mod demo;
pub mod mesh;
pub mod run;
pub mod solve;

use crate::server::follow_live::{LiveFollow, LiveRemesh};
use crate::server::{RunConfig, RunSummary, run, run_following};
use anyhow::{Context, Result};
use sim_server::backend::{Hybrid, HybridConfig, Implicit, ImplicitConfig, Precomputed};
use sim_server::follow_refine::Follower;
use sim_server::prepare::{prepare, prepare_with};
use sim_server::scene::real_time::RealTime;
use sim_server::scene::spec::BackendName;
use sim_server::scene::{BuiltScene, HYBRID_NEEDS_SPLIT, SceneSource, build_scene};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// The backends a `--backend` flag names (the scene's [`BackendName`]s;
/// kept here so that the scene code needs no clap).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendArg {
    /// Explicit tensor-mass (paper 3.3-3.5).
    TensorMass,
    /// Implicit backward Euler.
    Implicit,
    /// Precomputed static responses (Cotin), no cutting.
    Precomputed,
    /// Precomputed joined to a cuttable tensor-mass part.
    Hybrid,
}

impl From<BackendArg> for BackendName {
    fn from(b: BackendArg) -> Self {
        match b {
            BackendArg::TensorMass => BackendName::TensorMass,
            BackendArg::Implicit => BackendName::Implicit,
            BackendArg::Precomputed => BackendName::Precomputed,
            BackendArg::Hybrid => BackendName::Hybrid,
        }
    }
}

/// The contact laws a `--contact-law` flag names (`[contact] law`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ContactLawArg {
    /// Compliant springs on points of the surface triangles (tensor-mass,
    /// precomputed).
    Penalty,
    /// The paper's law: touched vertices prescribed on the tool's plane.
    Projection,
}

/// `--contact-law`: the scene's `[contact] law` replaced (the backend
/// refuses a law it cannot run when the tools are built).
fn override_contact_law(scene: &mut BuiltScene, law: Option<ContactLawArg>) {
    if let Some(law) = law {
        scene.contact.law = Some(match law {
            ContactLawArg::Penalty => sim_server::contact::ContactLaw::Penalty,
            ContactLawArg::Projection => sim_server::contact::ContactLaw::Projection,
        });
    }
}

/// `--implicit-iterations`: the per-step budget, 0 for none.
pub fn implicit_step_iterations(n: usize) -> Option<usize> {
    (n > 0).then_some(n)
}

/// Runs `scene` on `backend` (the scene's when `None`), calling `ready`
/// once the backend is prepared and before the first step: the demo starts
/// its haptic daemon there, so that the daemon's scripted hand does not run
/// ahead of a simulation that spends seconds preparing (the precomputed
/// responses on a machine without them in the cache: the grasp of the
/// liver demo was over before the first step, and the hand felt nothing).
pub fn run_scene(
    src: &SceneSource,
    mut scene: BuiltScene,
    backend: Option<BackendName>,
    cfg: &RunConfig,
    stop: Arc<AtomicBool>,
    ready: impl FnOnce() -> Result<()>,
) -> Result<RunSummary> {
    // What `check` prints, said before the run too.
    for w in &scene.report.warnings {
        eprintln!("warning: {w}");
    }
    let backend = backend.unwrap_or(scene.settings.backend);
    anyhow::ensure!(
        scene.follow.is_none() || backend == BackendName::TensorMass,
        "[contact] refine_radius_m needs the tensor-mass backend, which can change its mesh while it runs; --backend {} fixes its matrices when it starts",
        backend.as_str()
    );
    Ok(match backend {
        BackendName::Implicit => {
            // Stable at any step: the real-time step, not the explicit bound.
            let dt = real_time_step(&scene);
            let prepared = prepare_with(scene, Some(dt), |model, _, dt_s| {
                let mut config = ImplicitConfig::new(dt_s);
                config.step_iterations = cfg.implicit_step_iterations;
                Implicit::new(model, config)
            })?;
            ready()?;
            run(prepared, cfg, stop)?
        }
        BackendName::Precomputed => {
            if scene
                .prescribed
                .iter()
                .any(|(_, d)| *d != sim_server::math::Vec3::ZERO)
            {
                anyhow::bail!(
                    "the precomputed backend holds the scene's fixed vertices only; this scene prescribes displacements: use tensor-mass or implicit"
                );
            }
            let fixed: Vec<_> = scene
                .fixed
                .iter()
                .chain(scene.prescribed.iter().map(|(v, _)| v))
                .copied()
                .collect();
            let dt = real_time_step(&scene);
            let cache = cache_dir();
            let loads = scene.loads_n.clone();
            // A force on a held vertex goes to the support in every backend.
            let mut held = fixed.clone();
            held.sort_unstable();
            let prepared = prepare_with(scene, Some(dt), |model, _, dt_s| {
                Precomputed::new(model, &fixed, dt_s, cache.as_deref(), progress_line())
            })?;
            if let Some(v) = interior_load(&loads, |v| {
                prepared.sim.can_load(v) || held.binary_search(&v).is_ok()
            }) {
                anyhow::bail!(
                    "the precomputed backend applies forces to surface vertices only (its responses are to surface forces); the scene loads interior vertex {}: use tensor-mass or implicit",
                    v.0
                );
            }
            if prepared.sim.from_cache {
                eprintln!("precomputed responses read from the cache");
            }
            ready()?;
            run(prepared, cfg, stop)?
        }
        BackendName::Hybrid => {
            let Some(tets) = scene.hybrid_tets.clone() else {
                anyhow::bail!("{HYBRID_NEEDS_SPLIT}");
            };
            let prescribed = scene.prescribed.clone();
            let loads = scene.loads_n.clone();
            let mut held: Vec<_> = scene
                .fixed
                .iter()
                .chain(scene.prescribed.iter().map(|(v, _)| v))
                .copied()
                .collect();
            held.sort_unstable();
            let fixed = scene.fixed.clone();
            let cache_dir = cache_dir();
            let prepared = prepare_with(scene, None, |model, settings, dt_s| {
                let config = HybridConfig {
                    dt_s,
                    policy: settings.policy,
                    cache_dir,
                };
                Hybrid::new(model, &fixed, &tets, config, progress_line())
            })?;
            if let Some((v, _)) = prescribed
                .iter()
                .find(|(v, d)| *d != sim_server::math::Vec3::ZERO && !prepared.sim.can_load(*v))
            {
                anyhow::bail!(
                    "the hybrid backend cannot impose the scene's displacement on vertex {}: it is inside the precomputed part (outside [hybrid] select), whose responses cover surface forces only",
                    v.0
                );
            }
            if let Some(v) = interior_load(&loads, |v| {
                prepared.sim.can_load(v) || held.binary_search(&v).is_ok()
            }) {
                anyhow::bail!(
                    "the hybrid backend's precomputed part takes forces on its surface only; the scene loads vertex {} inside it (outside [hybrid] select): move the load or the region, or use tensor-mass",
                    v.0
                );
            }
            eprintln!(
                "hybrid: {} tensor-mass tetrahedra, {} shared vertices, {} precomputed surface vertices, stable step {:.3e} s ({} sub-steps per step){}",
                prepared.sim.tensor_mass_tets(),
                prepared.sim.shared_len(),
                prepared.sim.precomputed_sources(),
                prepared.sim.stable_step().dt_max_s,
                prepared.sim.substeps(),
                if prepared.sim.from_cache() {
                    " (responses read from the cache)"
                } else {
                    ""
                }
            );
            ready()?;
            run(prepared, cfg, stop)?
        }
        _ if scene.settings.single_precision => {
            let real_time = RealTime::of(&scene);
            let follow = live_follow::<f32>(src, &mut scene)?;
            let prepared = prepare::<f32>(scene, None)?;
            warn_real_time(&real_time, prepared.sim.stable_step().dt_max_s);
            ready()?;
            run_following(prepared, follow, cfg, stop)?
        }
        _ => {
            let real_time = RealTime::of(&scene);
            let follow = live_follow::<f64>(src, &mut scene)?;
            let prepared = prepare::<f64>(scene, None)?;
            warn_real_time(&real_time, prepared.sim.stable_step().dt_max_s);
            ready()?;
            run_following(prepared, follow, cfg, stop)?
        }
    })
}

/// The refinement that follows the tools, when `scene` asks for one,
/// with its worker thread started.
fn live_follow<S: sim_server::tensor_mass::Storage>(
    src: &SceneSource,
    scene: &mut BuiltScene,
) -> Result<Option<Box<dyn LiveRemesh<sim_server::tensor_mass::Explicit<S>>>>> {
    let Some(follower) = Follower::new(src, scene)? else {
        return Ok(None);
    };
    let live =
        LiveFollow::<S>::start(follower).context("cannot start the refinement's worker thread")?;
    Ok(Some(Box::new(live)))
}

/// The warning (on stderr) that the explicit step `dt_max_s` cannot keep
/// real time, if it cannot (as `check` says it).
fn warn_real_time(real_time: &RealTime, dt_max_s: f64) {
    if let Some(w) = real_time.warning(dt_max_s) {
        eprintln!("warning: {w}");
    }
}

/// The first vertex with a non-zero force that `accepts` refuses.
fn interior_load(
    loads_n: &[sim_server::math::Vec3],
    accepts: impl Fn(sim_server::ids::VertexId) -> bool,
) -> Option<sim_server::ids::VertexId> {
    loads_n
        .iter()
        .enumerate()
        .map(|(v, f)| (sim_server::ids::VertexId::from(v), f))
        .find(|(v, f)| **f != sim_server::math::Vec3::ZERO && !accepts(*v))
        .map(|(v, _)| v)
}

/// A progress line on stderr for a precomputation, every 10%.
fn progress_line() -> impl FnMut(usize, usize) {
    let mut shown = 0;
    move |done, total| {
        let pct = 100 * done / total.max(1);
        if pct >= shown + 10 || done == total {
            shown = pct;
            eprint!("\rprecomputing unit responses: {pct:3}% ({done}/{total})");
            if done == total {
                eprintln!();
            }
        }
    }
}

/// A count flag (`--tets`, `--steps`, `--threads`): a whole number of at
/// least 1, with a message that says so (clap's own says "invalid digit"
/// for a negative number).
pub fn count(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!("expected a whole number of at least 1, got {s:?}")),
    }
}

/// [`count`] for a u64 flag (`run --steps`).
pub fn count_u64(s: &str) -> Result<u64, String> {
    count(s).map(|n| n as u64)
}

/// `--dt-s`: the step instead of the scene's, if given (a finite number
/// of seconds within the scene's bounds on `dt_s`).
fn override_step(scene: &mut BuiltScene, dt_s: Option<f64>) -> Result<()> {
    if let Some(dt) = dt_s {
        sim_server::scene::check_step("--dt-s", dt).map_err(anyhow::Error::msg)?;
        scene.settings.dt_s = Some(dt);
    }
    Ok(())
}

/// The step of backends not bound by the explicit stability limit: the
/// scene's `dt_s` (or one period of its `rate_hz`), else 1 ms.
fn real_time_step(scene: &BuiltScene) -> f64 {
    scene.settings.dt_s.unwrap_or(1e-3)
}

/// Where precomputed responses are kept (the meshes a scene's `surface`
/// makes too).
fn cache_dir() -> Option<std::path::PathBuf> {
    sim_server::mesh::tetrahedralize::cache_dir()
}

/// Reads and builds a scene file, or the embedded scene when `path` is `None`.
pub fn load_scene(path: Option<&Path>) -> Result<(SceneSource, BuiltScene)> {
    let src = match path {
        Some(p) => SceneSource::read(p)?,
        None => SceneSource::embedded(),
    };
    let spec = src.parse()?;
    let built =
        build_scene(&src, &spec).with_context(|| format!("cannot build scene {}", src.name))?;
    Ok((src, built))
}

/// Writes pretty JSON to `path`.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text + "\n").with_context(|| format!("cannot write {}", path.display()))
}
