//! `haptic-daemon`: the hard-real-time haptic loop (`run`) and the session
//! recorder (`record`).

use anyhow::Result;
use clap::{Parser, Subcommand};
use record_cmd::{RecordArgs, record_main};
use run_args::RunArgs;

mod chain_args;
mod out_files;
mod record_cmd;
mod remote_args;

/// Prints to stderr, ignoring failures: a closed pipe must never panic the
/// process while the real-time thread is commanding a device.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

/// Prints to stdout, ignoring failures (see `say!`).
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

mod device_choice;
mod run_args;
mod run_cmd;

#[derive(Parser)]
#[command(
    name = "haptic-daemon",
    version,
    about = "Hard-real-time haptic loop: device, extrapolation, safety"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the haptic loop.
    #[command(allow_negative_numbers = true)]
    Run(Box<RunArgs>),
    /// Record a session's force samples and telemetry losslessly, counting
    /// sequence gaps (SIGINT/SIGTERM stop it after a flush).
    #[command(allow_negative_numbers = true)]
    Record(RecordArgs),
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Run(args) => run_cmd::run_main(*args),
        Command::Record(args) => record_main(args),
    }
}
