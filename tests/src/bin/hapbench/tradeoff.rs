//! `hapbench tradeoff`: speed against accuracy for every backend, over
//! mesh sizes and time steps. A 4 x 2 x 2 cm block fixed at x = 0 carries a
//! load on its free end; each configuration runs until the response has
//! settled (damped), and its deflection at the free end's centre is compared
//! with the converged reference: the static solution on a mesh twice finer
//! than the finest in the sweep. Speed is steps per second of wall time and
//! the real-time factor (simulated seconds per second).

use anyhow::{Context, Result};
use serde::Serialize;
use sim_server::backend::{Backend, Hybrid, HybridConfig, Implicit, ImplicitConfig, Precomputed};
use sim_server::prelude::*;
use sim_server::tensor_mass::element_bound;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use crate::plot::{Series, chart};
use crate::progress::bar;

/// Flags of `hapbench tradeoff`.
#[derive(clap::Args)]
pub struct Args {
    /// Simulated seconds per configuration (the response settles in ~0.3 s).
    #[arg(long, default_value_t = 1.0)]
    pub duration_s: f64,
    /// Write the results here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the Pareto plot here.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

const SIZE: [f64; 3] = [0.04, 0.02, 0.02];
const LOAD_N: f64 = 0.01;
const CELLS_M: [f64; 4] = [0.01, 0.005, 0.0025, 0.002];

/// One configuration's result.
#[derive(Clone, Debug, Serialize)]
pub struct Point {
    /// Backend name.
    pub backend: String,
    /// Cell edge (m).
    pub cell_m: f64,
    /// Tetrahedra.
    pub tets: usize,
    /// Step (s).
    pub dt_s: f64,
    /// Steps per second of wall time.
    pub steps_per_s: f64,
    /// Simulated seconds per wall second.
    pub realtime_factor: f64,
    /// |u - u_ref| / |u_ref| at the probe.
    pub error: f64,
    /// Whether no other point is both faster and more accurate.
    pub pareto: bool,
}

/// The summary per backend (its default configuration).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Summary {
    /// Steps per second.
    pub steps_per_s: f64,
    /// Relative error against the converged reference.
    pub error: f64,
}

fn model(cell_m: f64) -> Result<ElasticModel> {
    let mesh = BoxSpec::new(Vec3::from_array(SIZE), CellSize::EdgeM(cell_m)).generate()?;
    let tissue = Material::isotropic(5000.0, 0.45, 1000.0, 30.0)?;
    let materials = TetMaterials::uniform(tissue, mesh.tet_count());
    Ok(ElasticModel::new(mesh, materials)?)
}

fn find(m: &ElasticModel, at: [f64; 3]) -> Option<VertexId> {
    m.mesh()
        .positions_m()
        .iter()
        .position(|p| (*p - Vec3::from_array(at)).length() < 1e-9)
        .map(VertexId::from)
}

/// (fixed vertices, loaded vertices with their share of the load).
fn boundary(m: &ElasticModel) -> (Vec<VertexId>, Vec<(VertexId, Vec3)>) {
    let p = m.mesh().positions_m();
    let wall = (0..p.len())
        .filter(|&v| p[v].x < 1e-9)
        .map(VertexId::from)
        .collect();
    let end: Vec<VertexId> = (0..p.len())
        .filter(|&v| p[v].x > SIZE[0] - 1e-9)
        .map(VertexId::from)
        .collect();
    let share = Vec3::new(0.0, 0.0, -LOAD_N / end.len() as f64);
    (wall, end.into_iter().map(|v| (v, share)).collect())
}

const PROBE: [f64; 3] = [SIZE[0], SIZE[1] / 2.0, SIZE[2] / 2.0];

fn reference() -> Result<f64> {
    let m = model(CELLS_M[CELLS_M.len() - 1] / 2.0)?;
    let (wall, loads) = boundary(&m);
    let mut bc = Dirichlet::new(m.vertex_count());
    for v in wall {
        bc.fix(v);
    }
    let mut f = vec![Vec3::ZERO; m.vertex_count()];
    for (v, l) in loads {
        f[v.idx()] = l;
    }
    let sol = solve_static(&m, &bc, &f)?;
    let probe = find(&m, PROBE).context("the probe is not a vertex of the reference mesh")?;
    Ok(sol.displacement_m[probe.idx()].z)
}

fn measure<B: Backend>(mut sim: B, cell_m: f64, duration_s: f64, u_ref: f64) -> Result<Point> {
    let (wall, loads) = boundary(sim.model());
    for v in wall {
        sim.fix(v);
    }
    for (v, l) in loads {
        sim.set_external_force(v, l);
    }
    let probe = find(sim.model(), PROBE).context("the probe is not a vertex")?;
    let steps = (duration_s / sim.dt_s()).ceil() as usize;
    let start = Instant::now();
    for _ in 0..steps {
        sim.step();
    }
    let wall_s = start.elapsed().as_secs_f64().max(1e-9);
    let u = sim.displacement(probe).z;
    anyhow::ensure!(u.is_finite(), "{} diverged", sim.name());
    Ok(Point {
        backend: sim.name().to_string(),
        cell_m,
        tets: sim.model().mesh().tet_count(),
        dt_s: sim.dt_s(),
        steps_per_s: steps as f64 / wall_s,
        realtime_factor: steps as f64 * sim.dt_s() / wall_s,
        error: ((u - u_ref) / u_ref).abs(),
        pareto: false,
    })
}

/// Runs the sweep.
pub fn run(args: &Args) -> Result<()> {
    anyhow::ensure!(
        args.duration_s.is_finite() && args.duration_s >= 0.2,
        "--duration-s must be at least 0.2"
    );
    let progress = bar(1 + CELLS_M.len() * 7, "tradeoff");
    let u_ref = reference()?;
    progress.inc(1);
    let mut points = Vec::new();
    for cell in CELLS_M {
        let m = model(cell)?;
        let bound = element_bound(&m).dt_max_s;
        // tensor-mass: the explicit step just under its bound (a larger step
        // only sub-steps), in f64 and in f32 storage.
        let cfg = ExplicitConfig::new(0.9 * bound);
        points.push(measure(
            Explicit::<f64>::new(m.clone(), cfg)?,
            cell,
            args.duration_s,
            u_ref,
        )?);
        progress.inc(1);
        let mut p = measure(
            Explicit::<f32>::new(m.clone(), cfg)?,
            cell,
            args.duration_s,
            u_ref,
        )?;
        p.backend = "tensor-mass-f32".into();
        points.push(p);
        progress.inc(1);
        for dt in [0.001, 0.004, 0.016] {
            let sim = Implicit::new(m.clone(), ImplicitConfig::new(dt))?;
            points.push(measure(sim, cell, args.duration_s, u_ref)?);
            progress.inc(1);
        }
        // precomputed: static, so one step settles it; its steps/s exclude
        // the one-off precomputation.
        let (wall, _) = boundary(&m);
        let sim = Precomputed::new(m.clone(), &wall, 0.001, None, |_, _| {})?;
        points.push(measure(sim, cell, args.duration_s, u_ref)?);
        progress.inc(1);
        // hybrid: the loaded quarter (x > 3 cm) tensor-mass, the rest
        // precomputed; explicit steps just under the whole body's bound.
        let tets: Vec<TetId> = (0..m.mesh().tet_count())
            .map(TetId::from)
            .filter(|t| {
                let p = m.mesh().tet_points(*t);
                (p[0].x + p[1].x + p[2].x + p[3].x) / 4.0 > 0.75 * SIZE[0]
            })
            .collect();
        let sim = Hybrid::new(
            m.clone(),
            &wall,
            &tets,
            HybridConfig::new(0.9 * bound),
            |_, _| {},
        )?;
        points.push(measure(sim, cell, args.duration_s, u_ref)?);
        progress.inc(1);
    }
    progress.finish_and_clear();
    for i in 0..points.len() {
        let (e, r) = (points[i].error, points[i].realtime_factor);
        points[i].pareto = !points.iter().any(|q| {
            // Errors within 0.1% count as equal (same mesh, settled response).
            q.error <= e * 1.001
                && q.realtime_factor >= r
                && (q.realtime_factor > r || q.error < e * 0.999)
        });
    }
    // The summary: each backend's default (5 mm cells; implicit at 1 ms).
    let mut backends = BTreeMap::new();
    for p in &points {
        if p.cell_m == 0.005 && (p.backend != "implicit" || p.dt_s == 0.001) {
            backends.insert(
                p.backend.clone(),
                Summary {
                    steps_per_s: p.steps_per_s,
                    error: p.error,
                },
            );
        }
    }
    println!(
        "{:<16} {:>7} {:>7} {:>9} {:>11} {:>9} {:>10} pareto",
        "backend", "cell mm", "tets", "dt us", "steps/s", "x real", "error %"
    );
    for p in &points {
        println!(
            "{:<16} {:>7.1} {:>7} {:>9.1} {:>11.0} {:>9.2} {:>10.3} {}",
            p.backend,
            p.cell_m * 1e3,
            p.tets,
            p.dt_s * 1e6,
            p.steps_per_s,
            p.realtime_factor,
            p.error * 100.0,
            if p.pareto { "*" } else { "" }
        );
    }
    if let Some(path) = &args.json {
        let v = serde_json::json!({
            "reference_deflection_m": u_ref,
            "backends": backends,
            "sweep": points,
        });
        std::fs::write(path, serde_json::to_string_pretty(&v)? + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    if let Some(dir) = &args.plot {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let colors = [
            ("tensor-mass", "#1f77b4"),
            ("tensor-mass-f32", "#17becf"),
            ("implicit", "#d62728"),
            ("precomputed", "#2ca02c"),
        ];
        let mut series = Vec::new();
        for (name, color) in colors {
            let mut pts: Vec<(f64, f64)> = points
                .iter()
                .filter(|p| p.backend == name)
                .map(|p| (p.realtime_factor.log10(), (p.error.max(1e-6)).log10()))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            series.push(Series {
                name,
                color,
                points: pts,
            });
        }
        let x0 = points
            .iter()
            .map(|p| p.realtime_factor.log10())
            .fold(f64::INFINITY, f64::min);
        let x1 = points
            .iter()
            .map(|p| p.realtime_factor.log10())
            .fold(f64::NEG_INFINITY, f64::max);
        let svg = chart(
            "Speed against accuracy (block under an end load)",
            "log10 real-time factor",
            "log10 relative error",
            x0 - 0.1,
            x1 + 0.1,
            &series,
        );
        let path = dir.join("tradeoff.svg");
        std::fs::write(&path, svg).with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}
