//! The `sim-server` command line.

mod bridge;
mod cli;
mod server;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand, ValueEnum};
use sim_server::bench::{BenchConfig, BenchProblem, BenchReport, box_problem, run_bench};
use sim_server::material::MaterialModel;
use sim_server::tensor_mass::BoundMethod;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "sim-server",
    version,
    about = "Soft-tissue simulation server (tensor-mass FEM)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum)]
enum Generator {
    /// A cube split into tetrahedra.
    Box,
}

/// Strain models on the command line.
#[derive(Clone, Copy, ValueEnum)]
enum ModelArg {
    /// The paper's linearised strain.
    Linear,
    /// St Venant-Kirchhoff.
    Stvk,
    /// Corotational.
    Corotational,
}

impl ModelArg {
    fn model(self) -> MaterialModel {
        match self {
            ModelArg::Linear => MaterialModel::Linear,
            ModelArg::Stvk => MaterialModel::Stvk,
            ModelArg::Corotational => MaterialModel::Corotational,
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum Precision {
    /// Single-precision tensor storage (state stays f64).
    F32,
    /// Double-precision tensor storage.
    F64,
}

#[derive(Clone, Copy, ValueEnum)]
enum Bound {
    /// Irons' element bound (proven, survives cutting).
    Element,
    /// Power iteration on the assembled model.
    PowerIteration,
}

#[derive(Subcommand)]
enum Command {
    /// Run the simulation for the haptic daemon and the viewer: reads tool
    /// poses, applies the contact models, steps in real time (or as fast as it
    /// can with --headless), publishes force samples every step and the mesh
    /// state at the viewer rate.
    #[command(allow_negative_numbers = true)]
    Run(cli::run::RunArgs),
    /// The whole stack on the embedded liver: sim-server and haptic-daemon with
    /// the simulated device running a scripted hepatectomy (the grasper grips
    /// and pulls the left lobe, the cavitron removes right-lobe parenchyma).
    #[command(allow_negative_numbers = true)]
    Demo(cli::demo::DemoArgs),
    /// Validate a scene (.toml) or a mesh (.msh, .vtk, .vtu, .mesh): counts,
    /// quality, materials per region, the stable time step, enabled models.
    /// Without FILE, checks the embedded default scene.
    #[command(allow_negative_numbers = true)]
    Check {
        /// Scene or mesh file.
        file: Option<PathBuf>,
        /// Also write the summary as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Tetrahedralize organ surfaces (STL, OBJ, PLY, OFF, VTK, VTP, e.g.
    /// from a 3D Slicer segmentation) with fTetWild, then check the result
    /// as `check` does (quality, the stable step).
    #[command(allow_negative_numbers = true)]
    Mesh(cli::mesh::MeshArgs),
    /// Static equilibrium of a scene: writes a VTU with point data
    /// `displacement` (m) and `force` (N: support reactions at fixed and
    /// prescribed vertices, the applied load elsewhere), as VTU or legacy
    /// VTK, or the deformed mesh (medit) or surface (OBJ, STL), by the
    /// extension of --out.
    #[command(allow_negative_numbers = true)]
    Solve {
        /// Scene file (default: the embedded scene).
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Output, by extension: .vtu or .vtk (mesh with `displacement` and
        /// `force`), .mesh (medit: the deformed mesh), .obj or .stl (the
        /// deformed surface).
        #[arg(long)]
        out: PathBuf,
        /// Also write a JSON summary here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Carry a session's streams between shared memory and zenoh, for
    /// viewers, recorders and haptic daemons on other hosts
    /// (`viewer --connect`, `haptic-daemon run --connect`).
    #[command(allow_negative_numbers = true)]
    Bridge(cli::bridge::BridgeArgs),
    /// Time the explicit tensor-mass step on a generated box or a scene.
    #[command(allow_negative_numbers = true)]
    Bench {
        /// Mesh generator (ignored with --scene).
        #[arg(long, value_enum, default_value = "box")]
        generate: Generator,
        /// Time this scene instead of a generated box ("default" = the embedded scene).
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Target number of tetrahedra.
        #[arg(long, default_value_t = 8000, value_parser = cli::count)]
        tets: usize,
        /// Timed steps (split into 5 batches; the median batch is reported).
        #[arg(long, default_value_t = 2000, value_parser = cli::count)]
        steps: usize,
        /// Worker threads.
        #[arg(long, default_value_t = 1, value_parser = cli::count)]
        threads: usize,
        /// Tensor storage precision.
        #[arg(long, value_enum, default_value = "f32")]
        precision: Precision,
        /// Stability bound that sets dt (90% of it).
        #[arg(long, value_enum, default_value = "element")]
        bound: Bound,
        /// Step (s); default the scene's dt_s, else 90% of the stable step.
        #[arg(long)]
        dt_s: Option<f64>,
        /// Keep the generator's vertex order (no reverse Cuthill-McKee).
        #[arg(long)]
        no_reorder: bool,
        /// Strain model of every tetrahedron (default: linear for the
        /// generated box, the scene's own with --scene).
        #[arg(long, value_enum)]
        model: Option<ModelArg>,
        /// Write the report as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
}

fn main() -> Result<()> {
    // Behave like a Unix tool when the reader of stdout goes away
    // (`sim-server check | head`): end quietly instead of panicking on EPIPE.
    // SAFETY: setting a signal disposition at start, before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    match cli.command {
        Command::Run(args) => cli::run::run(args)?,
        Command::Demo(args) => cli::demo::run(args)?,
        Command::Bridge(args) => cli::bridge::bridge(args)?,
        Command::Check { file, json } => cli::check::run(file.as_deref(), json.as_deref())?,
        Command::Mesh(args) => cli::mesh::run(&args)?,
        Command::Solve { scene, out, json } => {
            cli::solve::run(scene.as_deref(), &out, json.as_deref())?
        }
        Command::Bench {
            generate: Generator::Box,
            scene,
            dt_s,
            tets,
            steps,
            threads,
            precision,
            bound,
            no_reorder,
            model,
            json,
        } => {
            if threads == 0 {
                bail!("--threads must be at least 1");
            }
            let cfg = BenchConfig {
                tets,
                steps,
                threads,
                reorder: !no_reorder,
                bound: match bound {
                    Bound::Element => BoundMethod::Element,
                    Bound::PowerIteration => BoundMethod::PowerIteration,
                },
                model: model.map_or(MaterialModel::Linear, ModelArg::model),
                ..BenchConfig::default()
            };
            let mut problem = match &scene {
                Some(path) => {
                    let path = (path.as_os_str() != "default").then_some(path.as_path());
                    let (_, b) = cli::load_scene(path)?;
                    BenchProblem {
                        model: b.model,
                        fixed: b.fixed,
                        prescribed: b.prescribed,
                        loads_n: b.loads_n,
                        dt_s: b.settings.dt_s,
                    }
                }
                None => box_problem(&cfg).context("cannot build the benchmark box")?,
            };
            if let (Some(m), Some(_)) = (model, &scene) {
                problem.model = problem.model.with_model(m.model());
            }
            if let Some(dt) = dt_s {
                sim_server::scene::check_step("--dt-s", dt).map_err(anyhow::Error::msg)?;
                problem.dt_s = Some(dt);
            }
            let report = match precision {
                Precision::F32 => run_bench::<f32>(problem, &cfg),
                Precision::F64 => run_bench::<f64>(problem, &cfg),
            }
            .context("benchmark failed")?;
            print_report(&report);
            if let Some(path) = json {
                sim_server::provenance::write_stamped(&path, &report)?;
            }
        }
    }
    Ok(())
}

fn print_report(r: &BenchReport) {
    println!(
        "mesh {} tets, {} vertices, {} edges | {} thread(s), {} storage | dt {:.3e} s in {} sub-step(s) ({} bound)",
        r.tets, r.vertices, r.edges, r.threads, r.precision, r.dt_s, r.substeps, r.bound
    );
    println!(
        "model {} ({} nonlinear tetrahedra)",
        r.model, r.nonlinear_tets
    );
    println!(
        "{:.0} steps/s ({:.1} us/step, median of {} batches) | {:.2} MB/step | probe {:.1} GB/s -> bandwidth bound {:.0} steps/s ({:.2}x of it)",
        r.steps_per_s,
        r.ns_per_step / 1e3,
        r.batch_steps_per_s.len(),
        r.bytes_per_step as f64 / 1e6,
        r.bandwidth_bytes_per_s / 1e9,
        r.bandwidth_bound_steps_per_s,
        r.fraction_of_bandwidth_bound
    );
}
