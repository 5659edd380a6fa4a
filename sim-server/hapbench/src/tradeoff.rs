//! `hapbench tradeoff`: speed against accuracy for every backend, over
//! mesh sizes and time steps. A 4 x 2 x 2 cm block fixed at x = 0 carries a
//! load on its free end; each configuration runs until the response has
//! settled (damped), and its deflection at the free end's centre is compared
//! with the converged reference: the static solution on a mesh twice finer
//! than the finest in the sweep. Speed is steps per second of wall time and
//! the real-time factor (simulated seconds per second).
//!
//! With `--scene FILE` the same backends run on that scene instead (its
//! mesh, materials, fixed vertices and forces, or, without forces, 0.01 N
//! down on its highest free surface vertex), over time steps only, and the
//! reference is the scene's own static solution: the error left is the
//! backends' (time stepping, solver, coupling), not the mesh's. The hybrid
//! runs when the scene has a `[hybrid]` section.

use anyhow::{Context, Result};
use serde::Serialize;
use sim_server::backend::{Backend, Hybrid, HybridConfig, Implicit, ImplicitConfig, Precomputed};
use sim_server::prelude::*;
use sim_server::tensor_mass::element_bound;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use crate::plot::{Axes, Scale, Series, chart};
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
    /// Sweep the backends on this scene instead of the generated block
    /// ("default" = the embedded scene).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Compare the material models (linear, corotational, StVK) under a
    /// large deformation instead of the backends (see `tradeoff_large`).
    #[arg(long, conflicts_with = "scene")]
    pub large: bool,
}

/// One body to sweep: its model, supports and forces, the probe vertex and
/// the reference displacement there.
struct Case {
    model: ElasticModel,
    fixed: Vec<VertexId>,
    loads: Vec<(VertexId, Vec3)>,
    probe: VertexId,
    u_ref: Vec3,
    /// Cell size (m): the generator's, or the scene mesh's median edge.
    cell_m: f64,
    /// The hybrid's tensor-mass part, if it is to run.
    hybrid_tets: Option<Vec<TetId>>,
}

pub const SIZE: [f64; 3] = [0.04, 0.02, 0.02];
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
    block(cell_m, sim_server::material::MaterialModel::Linear)
}

/// The block on `cell_m` cells with strain model `strain`.
pub fn block(cell_m: f64, strain: sim_server::material::MaterialModel) -> Result<ElasticModel> {
    let mesh = BoxSpec::new(Vec3::from_array(SIZE), CellSize::EdgeM(cell_m)).generate()?;
    let tissue = Material::isotropic(5000.0, 0.45, 1000.0, 30.0)?.with_model(strain);
    let materials = TetMaterials::uniform(tissue, mesh.tet_count());
    Ok(ElasticModel::new(mesh, materials)?)
}

pub fn find(m: &ElasticModel, at: [f64; 3]) -> Option<VertexId> {
    m.mesh()
        .positions_m()
        .iter()
        .position(|p| (*p - Vec3::from_array(at)).length() < 1e-9)
        .map(VertexId::from)
}

/// (fixed vertices, loaded vertices with their share of `load_n` down).
pub fn boundary(m: &ElasticModel, load_n: f64) -> (Vec<VertexId>, Vec<(VertexId, Vec3)>) {
    let p = m.mesh().positions_m();
    let wall = (0..p.len())
        .filter(|&v| p[v].x < 1e-9)
        .map(VertexId::from)
        .collect();
    let end: Vec<VertexId> = (0..p.len())
        .filter(|&v| p[v].x > SIZE[0] - 1e-9)
        .map(VertexId::from)
        .collect();
    let share = Vec3::new(0.0, 0.0, -load_n / end.len() as f64);
    (wall, end.into_iter().map(|v| (v, share)).collect())
}

pub const PROBE: [f64; 3] = [SIZE[0], SIZE[1] / 2.0, SIZE[2] / 2.0];

fn reference() -> Result<Vec3> {
    let m = model(CELLS_M[CELLS_M.len() - 1] / 2.0)?;
    let (wall, loads) = boundary(&m, LOAD_N);
    let u = static_displacements(&m, &wall, &loads)?;
    let probe = find(&m, PROBE).context("the probe is not a vertex of the reference mesh")?;
    Ok(u[probe.idx()])
}

/// The static solution of `m` with `fixed` held and `loads` applied (m).
fn static_displacements(
    m: &ElasticModel,
    fixed: &[VertexId],
    loads: &[(VertexId, Vec3)],
) -> Result<Vec<Vec3>> {
    let mut bc = Dirichlet::new(m.vertex_count());
    for v in fixed {
        bc.fix(*v);
    }
    let mut f = vec![Vec3::ZERO; m.vertex_count()];
    for (v, l) in loads {
        f[v.idx()] = *l;
    }
    Ok(solve_static(m, &bc, &f)?.displacement_m)
}

/// The block on `cell_m` cells against the fine reference `u_ref`; the
/// hybrid makes the loaded quarter (x > 3 cm) its tensor-mass part.
fn block_case(cell_m: f64, u_ref: Vec3) -> Result<Case> {
    let m = model(cell_m)?;
    let (fixed, loads) = boundary(&m, LOAD_N);
    let probe = find(&m, PROBE).context("the probe is not a vertex")?;
    let hybrid_tets = (0..m.mesh().tet_count())
        .map(TetId::from)
        .filter(|t| {
            let p = m.mesh().tet_points(*t);
            (p[0].x + p[1].x + p[2].x + p[3].x) / 4.0 > 0.75 * SIZE[0]
        })
        .collect();
    Ok(Case {
        model: m,
        fixed,
        loads,
        probe,
        u_ref,
        cell_m,
        hybrid_tets: Some(hybrid_tets),
    })
}

/// A scene file as a case: its reference is its own static solution.
fn scene_case(path: &std::path::Path) -> Result<Case> {
    use sim_server::scene::{SceneSource, build_scene};
    // "default" is the embedded scene, as for `sim-server run --scene`.
    let src = if path.as_os_str() == "default" {
        SceneSource::embedded()
    } else {
        SceneSource::read(path)?
    };
    let scene = build_scene(&src, &src.parse()?)
        .with_context(|| format!("cannot build scene {}", src.name))?;
    anyhow::ensure!(
        scene.prescribed.iter().all(|(_, d)| *d == Vec3::ZERO),
        "{}: tradeoff compares backends under forces; this scene imposes displacements",
        src.name
    );
    let m = scene.model;
    let mut fixed = scene.fixed.clone();
    fixed.extend(scene.prescribed.iter().map(|(v, _)| *v));
    fixed.sort_unstable();
    fixed.dedup();
    anyhow::ensure!(
        !fixed.is_empty(),
        "{}: the scene fixes no vertex, so it has no static solution to compare with",
        src.name
    );
    let mut loads: Vec<(VertexId, Vec3)> = scene
        .loads_n
        .iter()
        .enumerate()
        .filter(|(_, f)| **f != Vec3::ZERO)
        .map(|(v, f)| (VertexId::from(v), *f))
        .collect();
    if loads.is_empty() {
        let rest = m.mesh().positions_m();
        let top = m
            .topology()
            .surface_triangles(m.mesh())
            .flatten()
            .filter(|v| fixed.binary_search(v).is_err())
            .max_by(|a, b| rest[a.idx()].z.total_cmp(&rest[b.idx()].z))
            .context("the scene has no free surface vertex")?;
        loads.push((top, Vec3::new(0.0, 0.0, -0.01)));
    }
    let reference = static_displacements(&m, &fixed, &loads)?;
    let probe = (0..reference.len())
        .max_by(|a, b| reference[*a].length().total_cmp(&reference[*b].length()))
        .map(VertexId::from)
        .context("empty mesh")?;
    let rest = m.mesh().positions_m();
    let mut edges: Vec<f64> = m
        .topology()
        .edges()
        .iter()
        .map(|[a, b]| rest[a.idx()].distance(rest[b.idx()]))
        .collect();
    edges.sort_by(f64::total_cmp);
    Ok(Case {
        cell_m: edges.get(edges.len() / 2).copied().unwrap_or(0.0),
        u_ref: reference[probe.idx()],
        probe,
        fixed,
        loads,
        hybrid_tets: scene.hybrid_tets,
        model: m,
    })
}

/// Every backend on `case`: tensor-mass just under its bound in f64 and f32
/// storage, implicit at 1, 4 and 16 ms, precomputed (static: its steps/s
/// exclude the one-off precomputation), hybrid when the case has a split.
fn sweep(case: &Case, duration_s: f64, tick: &mut dyn FnMut()) -> Result<Vec<Point>> {
    let m = &case.model;
    let bound = element_bound(m).dt_max_s;
    let mut points = Vec::new();
    let cfg = ExplicitConfig::new(0.9 * bound);
    points.push(measure(
        Explicit::<f64>::new(m.clone(), cfg)?,
        case,
        duration_s,
    )?);
    tick();
    let mut p = measure(Explicit::<f32>::new(m.clone(), cfg)?, case, duration_s)?;
    p.backend = "tensor-mass-f32".into();
    points.push(p);
    tick();
    for dt in [0.001, 0.004, 0.016] {
        let sim = Implicit::new(m.clone(), ImplicitConfig::new(dt))?;
        points.push(measure(sim, case, duration_s)?);
        tick();
    }
    let sim = Precomputed::new(m.clone(), &case.fixed, 0.001, None, |_, _| {})?;
    points.push(measure(sim, case, duration_s)?);
    tick();
    if let Some(tets) = &case.hybrid_tets {
        let sim = Hybrid::new(
            m.clone(),
            &case.fixed,
            tets,
            HybridConfig::new(0.9 * bound),
            |_, _| {},
        )?;
        points.push(measure(sim, case, duration_s)?);
        tick();
    }
    Ok(points)
}

fn measure<B: Backend>(mut sim: B, case: &Case, duration_s: f64) -> Result<Point> {
    for v in &case.fixed {
        sim.fix(*v);
    }
    for (v, l) in &case.loads {
        sim.set_external_force(*v, *l);
    }
    let steps = (duration_s / sim.dt_s()).ceil() as usize;
    let start = Instant::now();
    for _ in 0..steps {
        sim.step();
    }
    let wall_s = start.elapsed().as_secs_f64().max(1e-9);
    let u = sim.displacement(case.probe);
    anyhow::ensure!(u.is_finite(), "{} diverged", sim.capabilities().name);
    Ok(Point {
        backend: sim.capabilities().name.to_string(),
        cell_m: case.cell_m,
        tets: sim.model().mesh().tet_count(),
        dt_s: sim.dt_s(),
        steps_per_s: steps as f64 / wall_s,
        realtime_factor: steps as f64 * sim.dt_s() / wall_s,
        error: (u - case.u_ref).length() / case.u_ref.length(),
        pareto: false,
    })
}

/// Runs the sweep.
pub fn run(args: &Args) -> Result<()> {
    anyhow::ensure!(
        args.duration_s.is_finite() && args.duration_s >= 0.2,
        "--duration-s must be at least 0.2"
    );
    if args.large {
        let progress = bar(1 + super::tradeoff_large::count(), "tradeoff --large");
        let u_ref = super::tradeoff_large::reference()?;
        progress.inc(1);
        let points = super::tradeoff_large::sweep(u_ref, args.duration_s, &mut || progress.inc(1))?;
        progress.finish_and_clear();
        super::tradeoff_large::print(&points, u_ref);
        if let Some(path) = &args.json {
            let v = serde_json::json!({
                "reference_displacement_m": u_ref.to_array(),
                "models": points,
            });
            sim_server::provenance::write_stamped(path, &v)?;
        }
        return Ok(());
    }
    println!(
        "run: {}, {} s per run",
        match &args.scene {
            Some(s) => format!("scene {}", s.display()),
            None => "the generated block under an end load (default)".to_string(),
        },
        args.duration_s
    );
    let (mut points, u_ref) = match &args.scene {
        Some(path) => {
            let case = scene_case(path)?;
            let progress = bar(7, "tradeoff");
            let points = sweep(&case, args.duration_s, &mut || progress.inc(1))?;
            progress.finish_and_clear();
            (points, case.u_ref)
        }
        None => {
            let progress = bar(1 + CELLS_M.len() * 7, "tradeoff");
            let u_ref = reference()?;
            progress.inc(1);
            let mut points = Vec::new();
            for cell in CELLS_M {
                let case = block_case(cell, u_ref)?;
                points.extend(sweep(&case, args.duration_s, &mut || progress.inc(1))?);
            }
            progress.finish_and_clear();
            (points, u_ref)
        }
    };
    for i in 0..points.len() {
        let (e, r) = (points[i].error, points[i].realtime_factor);
        points[i].pareto = !points.iter().any(|q| {
            // Errors within 0.1% count as equal (same mesh, settled response).
            q.error <= e * 1.001
                && q.realtime_factor >= r
                && (q.realtime_factor > r || q.error < e * 0.999)
        });
    }
    // The summary: each backend's default (5 mm cells for the block;
    // implicit at 1 ms).
    let mut backends = BTreeMap::new();
    for p in &points {
        if (args.scene.is_some() || p.cell_m == 0.005)
            && (p.backend != "implicit" || p.dt_s == 0.001)
        {
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
            "reference_deflection_m": u_ref.z,
            "reference_displacement_m": u_ref.to_array(),
            "backends": backends,
            "sweep": points,
        });
        sim_server::provenance::write_stamped(path, &v)?;
    }
    if let Some(dir) = &args.plot {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let backends = [
            "tensor-mass",
            "tensor-mass-f32",
            "implicit",
            "precomputed",
            "hybrid",
        ];
        let at = |p: &Point| (p.realtime_factor, p.error.max(1e-6));
        let mut series = Vec::new();
        for name in backends {
            let pts: Vec<(f64, f64)> = points
                .iter()
                .filter(|p| p.backend == name)
                .map(at)
                .collect();
            series.push(Series::markers(name, pts));
        }
        // The Pareto front: the points no other beats on both speed and
        // error, joined from slow to fast.
        let mut front: Vec<(f64, f64)> = points.iter().filter(|p| p.pareto).map(at).collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        series.push(Series::line("Pareto front", front));
        let (x0, x1) = points
            .iter()
            .map(|p| at(p).0)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                (lo.min(x), hi.max(x))
            });
        let title = match &args.scene {
            Some(s) => format!(
                "Speed against accuracy: {}, against its static solution",
                s.display()
            ),
            None => "Speed against accuracy: block under an end load (default)".to_string(),
        };
        let svg = chart(
            &title,
            "simulated seconds per wall second (real-time factor)",
            "relative error",
            x0 / 1.26,
            x1 * 1.26,
            &series,
            Axes {
                x: Scale::Log10,
                y: Scale::Log10,
            },
        );
        let path = dir.join("tradeoff.svg");
        std::fs::write(&path, svg).with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}
