//! `hapbench`: makes the product's claims measurable, one command each.
//! Each subcommand writes `--json FILE` (keys on the architecture page) and
//! SVG plots to `--plot DIR`.

mod extrapolation;
mod plot;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(version, about = "hapsim benchmarks: extrapolation error, ...")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Force extrapolators against the haptic-rate ground truth (paper 5.2):
    /// RMS and max error, p99 per-tick jump, net energy into the hand.
    Extrapolation(extrapolation::Args),
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Extrapolation(args) => extrapolation::run(&args),
    }
}
