//! `sim-server bench`: steps per second of the explicit tensor-mass step on a
//! generated box, beside a memory-bandwidth probe measured in the same run,
//! so the figure can be read as a fraction of what the memory allows.

use crate::ids::VertexId;
use crate::material::{Material, MaterialModel};
use crate::material_map::TetMaterials;
use crate::math::{Real, Vec3};
use crate::mesh::{BoxSpec, CellSize, GenerateError, rcm_order};
use crate::tensor_mass::huge_pages::collect_huge;
use crate::tensor_mass::{
    BoundMethod, DtPolicy, ElasticModel, Explicit, ExplicitConfig, ExplicitError, ModelError,
    Storage,
};
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;
use thiserror::Error;

/// Benchmark settings.
#[derive(Clone, Debug)]
pub struct BenchConfig {
    /// Target number of tetrahedra (the box is a cube of side `side_m`).
    pub tets: usize,
    /// Timed steps.
    pub steps: usize,
    /// Worker threads.
    pub threads: usize,
    /// Renumber vertices by reverse Cuthill-McKee first.
    pub reorder: bool,
    /// Cube side (m).
    pub side_m: Real,
    /// Stability bound used to pick dt (the bench steps at 90% of it).
    pub bound: BoundMethod,
    /// Bytes of the bandwidth probe's buffer (well above the last-level cache).
    pub probe_bytes: usize,
    /// Strain model of the generated box's tissue.
    pub model: MaterialModel,
}

impl Default for BenchConfig {
    fn default() -> Self {
        Self {
            tets: 8000,
            steps: 2000,
            threads: 1,
            reorder: true,
            side_m: 0.1,
            bound: BoundMethod::Element,
            probe_bytes: 256 << 20,
            model: MaterialModel::Linear,
        }
    }
}

/// The JSON report (keys listed in the architecture page; extend, don't rename).
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// Tetrahedra in the generated mesh.
    pub tets: usize,
    /// Vertices.
    pub vertices: usize,
    /// Edges (off-diagonal tensor blocks).
    pub edges: usize,
    /// Worker threads.
    pub threads: usize,
    /// Kernel storage precision.
    pub precision: &'static str,
    /// Timed steps.
    pub steps: usize,
    /// Median over batches of steps per second.
    pub steps_per_s: Real,
    /// 1e9 / steps_per_s.
    pub ns_per_step: Real,
    /// Bytes the step streams (tensors, indices, state).
    pub bytes_per_step: usize,
    /// Read bandwidth measured by the probe in this run (bytes/s, best of 5).
    pub bandwidth_bytes_per_s: Real,
    /// bandwidth / bytes_per_step: the rate if the step were limited by DRAM bandwidth alone.
    pub bandwidth_bound_steps_per_s: Real,
    /// steps_per_s / bandwidth_bound_steps_per_s (above 1 when the data fits in cache).
    pub fraction_of_bandwidth_bound: Real,
    /// The step (s): the scene's, or 90% of the stable step.
    pub dt_s: Real,
    /// Sub-steps per step (1 unless dt is above the bound).
    pub substeps: usize,
    /// Stability bound used.
    pub bound: &'static str,
    /// Seconds spent building the mesh, model, bound and kernel.
    pub setup_s: Real,
    /// Per-batch steps per second, in run order.
    pub batch_steps_per_s: Vec<Real>,
    /// Strain models in the model ("linear", "stvk", "corotational", or
    /// several joined by "+").
    pub model: String,
    /// Tetrahedra with a nonlinear model (their large-strain pass runs
    /// beside the linear kernel).
    pub nonlinear_tets: usize,
}

/// Why the benchmark could not run.
#[derive(Debug, Error)]
pub enum BenchError {
    /// Mesh generation failed.
    #[error(transparent)]
    Generate(#[from] GenerateError),
    /// Model set-up failed.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// Integrator set-up failed.
    #[error(transparent)]
    Explicit(#[from] ExplicitError),
    /// A material error (cannot happen with the built-in tissue).
    #[error(transparent)]
    Material(#[from] crate::material::MaterialError),
    /// Bad settings.
    #[error("{0}")]
    Config(String),
}

/// Measures the read bandwidth (bytes/s) of `threads` threads summing a
/// buffer of `bytes`; best of five passes.
pub fn probe_bandwidth(threads: usize, bytes: usize) -> Result<Real, BenchError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .map_err(|e| BenchError::Config(format!("cannot start {threads} threads: {e}")))?;
    let words = (bytes / 8).max(1 << 16);
    // Backed like the step's own buffers (huge pages where offered), so the
    // probe and the step are measured under the same paging.
    let buf: Vec<u64> = collect_huge(words, 0..words as u64);
    let chunk = words.div_ceil(threads.max(1) * 8);
    let mut best: Real = 0.0;
    for _ in 0..5 {
        let t0 = Instant::now();
        let sum: u64 = pool.install(|| {
            buf.par_chunks(chunk)
                .map(|c| {
                    let mut acc = [0u64; 4];
                    for q in c.chunks_exact(4) {
                        for k in 0..4 {
                            acc[k] = acc[k].wrapping_add(q[k]);
                        }
                    }
                    acc.iter().fold(0u64, |a, b| a.wrapping_add(*b))
                })
                .reduce(|| 0, u64::wrapping_add)
        });
        let dt = t0.elapsed().as_secs_f64();
        std::hint::black_box(sum);
        best = best.max((words * 8) as Real / dt);
    }
    Ok(best)
}

/// What to step: a model with its constraints and loads.
pub struct BenchProblem {
    /// The model.
    pub model: ElasticModel,
    /// Fixed vertices.
    pub fixed: Vec<VertexId>,
    /// Imposed displacements (m).
    pub prescribed: Vec<(VertexId, Vec3)>,
    /// Per-vertex forces (N), or empty.
    pub loads_n: Vec<Vec3>,
    /// Step (s); `None` = 90% of the bound.
    pub dt_s: Option<Real>,
}

/// A liver-like cube of about `cfg.tets` tetrahedra, clamped at the bottom
/// and sheared by 1 mm at the top.
pub fn box_problem(cfg: &BenchConfig) -> Result<BenchProblem, BenchError> {
    if cfg.tets == 0 {
        return Err(BenchError::Config("tets must be positive".into()));
    }
    let mut mesh =
        BoxSpec::new(Vec3::splat(cfg.side_m), CellSize::TargetTets(cfg.tets)).generate()?;
    if cfg.reorder {
        mesh = mesh.permuted(&rcm_order(&mesh));
    }
    let tissue = Material::isotropic(4500.0, 0.45, 1060.0, 10.0)?.with_model(cfg.model);
    let materials = TetMaterials::uniform(tissue, mesh.tet_count());
    let model = ElasticModel::new(mesh, materials)?;
    let mut fixed = Vec::new();
    let mut prescribed = Vec::new();
    for (v, p) in model.mesh().positions_m().iter().enumerate() {
        if p.z <= 1e-12 {
            fixed.push(VertexId::from(v));
        } else if p.z >= cfg.side_m - 1e-12 {
            prescribed.push((VertexId::from(v), Vec3::new(1e-3, 0.0, 0.0)));
        }
    }
    Ok(BenchProblem {
        model,
        fixed,
        prescribed,
        loads_n: Vec::new(),
        dt_s: None,
    })
}

/// The strain models a model uses ("+"-joined, sorted) and how many
/// tetrahedra are nonlinear.
fn models_of(model: &ElasticModel) -> (String, usize) {
    let mut names = std::collections::BTreeSet::new();
    let mut nonlinear = 0;
    for t in 0..model.mesh().tet_count() {
        let m = model
            .materials()
            .material(crate::ids::TetId::from(t))
            .model();
        names.insert(m.name());
        nonlinear += m.is_nonlinear() as usize;
    }
    (names.into_iter().collect::<Vec<_>>().join("+"), nonlinear)
}

/// Times the explicit step of `problem`.
pub fn run_bench<S: Storage>(
    problem: BenchProblem,
    cfg: &BenchConfig,
) -> Result<BenchReport, BenchError> {
    if cfg.steps == 0 || cfg.threads == 0 {
        return Err(BenchError::Config(
            "steps and threads must be positive".into(),
        ));
    }
    let t0 = Instant::now();
    let (model_names, nonlinear_tets) = models_of(&problem.model);
    let BenchProblem {
        model,
        fixed,
        prescribed,
        loads_n,
        dt_s,
    } = problem;
    let stable = match cfg.bound {
        BoundMethod::Element => crate::tensor_mass::element_bound(&model),
        BoundMethod::PowerIteration => crate::tensor_mass::power_iteration(&model, 1e-6, 2000).step,
    };
    let dt_s = dt_s.unwrap_or(0.9 * stable.dt_max_s);
    let config = ExplicitConfig {
        dt_s,
        policy: DtPolicy::Substep,
        bound: cfg.bound,
        threads: cfg.threads,
    };
    let mut sim = Explicit::<S>::new(model, config)?;
    for v in fixed {
        sim.fix(v);
    }
    for (v, d) in prescribed {
        sim.prescribe(v, d);
    }
    for (v, f) in loads_n.iter().enumerate() {
        if *f != Vec3::ZERO {
            sim.set_external_force(VertexId::from(v), *f);
        }
    }
    let setup_s = t0.elapsed().as_secs_f64();
    for _ in 0..(cfg.steps / 10).clamp(1, 200) {
        sim.step();
    }
    let batches = 5.min(cfg.steps);
    let per_batch = cfg.steps / batches;
    let mut rates = Vec::with_capacity(batches);
    for _ in 0..batches {
        let t = Instant::now();
        for _ in 0..per_batch {
            sim.step();
        }
        rates.push(per_batch as Real / t.elapsed().as_secs_f64());
    }
    if !sim.displacements().iter().flatten().all(|x| x.is_finite()) {
        return Err(BenchError::Config(
            "the benchmark diverged (a bug: dt is under the bound)".into(),
        ));
    }
    let mut sorted = rates.clone();
    sorted.sort_by(Real::total_cmp);
    let steps_per_s = sorted[sorted.len() / 2];
    let bytes_per_step = sim.bytes_per_substep() * sim.substeps();
    let bandwidth = probe_bandwidth(cfg.threads, cfg.probe_bytes)?;
    let bound_rate = bandwidth / bytes_per_step as Real;
    Ok(BenchReport {
        tets: sim.model().mesh().tet_count(),
        vertices: sim.model().vertex_count(),
        edges: sim.model().topology().edges().len(),
        threads: cfg.threads,
        precision: S::NAME,
        steps: batches * per_batch,
        steps_per_s,
        ns_per_step: 1e9 / steps_per_s,
        bytes_per_step,
        bandwidth_bytes_per_s: bandwidth,
        bandwidth_bound_steps_per_s: bound_rate,
        fraction_of_bandwidth_bound: steps_per_s / bound_rate,
        dt_s,
        bound: stable.method.name(),
        substeps: sim.substeps(),
        setup_s,
        batch_steps_per_s: rates,
        model: model_names,
        nonlinear_tets,
    })
}
