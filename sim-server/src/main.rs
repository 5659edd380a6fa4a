//! The `sim-server` command line.

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand, ValueEnum};
use sim_server::bench::{BenchConfig, BenchReport, run_bench};
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
    /// Time the explicit tensor-mass step on a generated mesh.
    Bench {
        /// Mesh generator.
        #[arg(long, value_enum, default_value = "box")]
        generate: Generator,
        /// Target number of tetrahedra.
        #[arg(long, default_value_t = 8000)]
        tets: usize,
        /// Timed steps (split into 5 batches; the median batch is reported).
        #[arg(long, default_value_t = 2000)]
        steps: usize,
        /// Worker threads.
        #[arg(long, default_value_t = 1)]
        threads: usize,
        /// Tensor storage precision.
        #[arg(long, value_enum, default_value = "f32")]
        precision: Precision,
        /// Stability bound that sets dt (90% of it).
        #[arg(long, value_enum, default_value = "element")]
        bound: Bound,
        /// Keep the generator's vertex order (no reverse Cuthill-McKee).
        #[arg(long)]
        no_reorder: bool,
        /// Write the report as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Bench {
            generate: Generator::Box,
            tets,
            steps,
            threads,
            precision,
            bound,
            no_reorder,
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
                ..BenchConfig::default()
            };
            let report = match precision {
                Precision::F32 => run_bench::<f32>(&cfg),
                Precision::F64 => run_bench::<f64>(&cfg),
            }
            .context("benchmark failed")?;
            print_report(&report);
            if let Some(path) = json {
                let text = serde_json::to_string_pretty(&report)?;
                std::fs::write(&path, text + "\n")
                    .with_context(|| format!("cannot write {}", path.display()))?;
            }
        }
    }
    Ok(())
}

fn print_report(r: &BenchReport) {
    println!(
        "box {} tets, {} vertices, {} edges | {} thread(s), {} storage | dt {:.3e} s ({} bound)",
        r.tets, r.vertices, r.edges, r.threads, r.precision, r.dt_s, r.bound
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
