//! `hapbench`: makes the product's claims measurable, one command each.
//! Each subcommand writes `--json FILE` (keys on the architecture page) and
//! SVG plots to `--plot DIR`.

mod extrapolation;
mod latency;
mod latency_probe;
mod latency_remote;
mod local_render;
mod phases;
mod plot;
mod progress;
mod report;
mod stability;
mod tradeoff;
mod tradeoff_large;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    version,
    about = "hapsim benchmarks: latency, force extrapolation error, speed against accuracy, stability at the extremes"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Force extrapolators against the haptic-rate ground truth (paper 5.2):
    /// RMS and max error, p99 per-tick jump, net energy into the hand.
    #[command(allow_negative_numbers = true)]
    Extrapolation(extrapolation::Args),
    /// The extremes (Poisson ratio, anisotropy, membrane stiffness, time
    /// step, slivers, deep and fast tools), each stable, refused or
    /// diverged-and-detected.
    #[command(allow_negative_numbers = true)]
    Stability(stability::Args),
    /// Sim -> daemon, daemon -> sim and device -> force latency and the
    /// daemon's tick lateness, beside bare iceoryx2 and bare sleep baselines.
    #[command(allow_negative_numbers = true)]
    Latency(latency::Args),
    /// Speed against accuracy for every backend over mesh sizes and time
    /// steps, with the Pareto front.
    #[command(allow_negative_numbers = true)]
    Tradeoff(tradeoff::Args),
    /// Renders benchmark JSON files (`--json`) as Markdown results pages
    /// with their date, commit and machine (docs/results/measured/).
    Report(report::Args),
    /// The latency baseline's publisher process (started by `latency`).
    #[command(hide = true)]
    #[command(allow_negative_numbers = true)]
    Probe(latency_probe::ProbeArgs),
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Extrapolation(args) => extrapolation::run(&args),
        Command::Stability(args) => stability::run(&args),
        Command::Latency(args) => latency::run(&args),
        Command::Tradeoff(args) => tradeoff::run(&args),
        Command::Report(args) => report::run(&args),
        Command::Probe(args) => latency_probe::probe(&args),
    }
}
