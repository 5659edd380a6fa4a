//! `haptic-daemon run`'s arguments.

use crate::chain_args::ChainArgs;
use haptic_daemon::extrapolate::Method;
use std::path::PathBuf;

#[derive(clap::Args)]
pub(crate) struct RunArgs {
    /// simulated (a hand poking along z), simulated:FILE.csv (a hand following a
    /// trajectory), replay:FILE.csv (open-loop positions), plugin:LIB.so[:ARGS]
    /// (a C-ABI device, see include/hapsim_device.h), haply[:ws://HOST:PORT]
    /// (Haply Inverse3 through the Haply Inverse Service, default
    /// ws://localhost:10001).
    #[arg(long, default_value = "simulated")]
    pub device: String,
    /// Loop rate (Hz), 100 to 10000.
    #[arg(long, default_value_t = 1000.0)]
    pub rate: f64,
    /// The force extrapolator (default local-problem: the lowest error on
    /// every `hapbench extrapolation` run in docs/results/extrapolation.md, passive on all;
    /// without contact problems from the simulation it renders as
    /// local-normal, the next best).
    #[arg(long, value_enum, default_value_t = Method::LocalProblem)]
    pub extrapolation: Method,
    /// `local-problem`: solve the contact problems quasi-statically, without
    /// the tissue's inertia the simulation sends with them.
    #[arg(long)]
    pub quasi_static: bool,
    /// Force limit (N); at most the device's own.
    #[arg(long)]
    pub max_force: Option<f64>,
    /// Where the device's workspace lies in the scene: the scene point of
    /// the device's origin (m), `X,Y,Z` (docs/guide/devices.md has examples per
    /// device).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_v3, default_value = "0,0,0")]
    pub workspace_offset_m: [f64; 3],
    /// Scene metres per device metre (0.01 to 100): above 1 the tool moves
    /// further than the hand and the stiffness at the hand is the scene's
    /// times it.
    #[arg(long, default_value_t = 1.0)]
    pub workspace_scale: f64,
    /// The device's axes turned onto the scene's: degrees about the
    /// device's x, then y, then z axis, `RX,RY,RZ`.
    #[arg(long, value_name = "RX,RY,RZ", value_parser = parse_v3, default_value = "0,0,0")]
    pub workspace_rotate_deg: [f64; 3],
    /// The workspace placement from a file (TOML: `offset_m`, `scale`,
    /// `rotate_deg`, a `device` note), instead of the three
    /// `--workspace-*` flags (`haptic-daemon/workspaces/` has examples).
    #[arg(long, value_name = "FILE.toml", conflicts_with_all = ["workspace_offset_m", "workspace_scale", "workspace_rotate_deg"])]
    pub workspace: Option<PathBuf>,
    /// The daemon's checks (pose plausibility, live samples, stiffness
    /// cap, passivity).
    #[command(flatten)]
    pub chain: ChainArgs,
    /// Shared memory (default) or a session on another host.
    #[command(flatten)]
    pub remote: crate::remote_args::RemoteArgs,
    /// Session name shared with the simulation.
    #[arg(long, default_value = "default")]
    pub session: String,
    /// Stop after this many seconds (default: until SIGINT/SIGTERM).
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// Write the summary as JSON here at exit.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Record every tick to this CSV.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// SCHED_FIFO priority to ask for the RT thread (1-99; 0 = do not ask).
    #[arg(long, default_value_t = 80, value_parser = clap::value_parser!(i32).range(0..=99))]
    pub rt_priority: i32,
    /// Pin the loop to this CPU.
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Wake this many microseconds early and spin to the deadline (lower
    /// lateness, more CPU; at most half a period, refused above).
    #[arg(long, default_value_t = 0)]
    pub spin_us: u64,
    /// The I/O thread polls for each pose in a window of this many
    /// microseconds around its due time instead of being woken by the RT
    /// thread: one thread wake-up less on the pose's way to the
    /// simulation, the window's CPU every period (0: off; at most a
    /// period, refused above).
    #[arg(long, default_value_t = 0)]
    pub io_spin_us: u64,
    /// No live status line.
    #[arg(long)]
    pub quiet: bool,
}

/// `X,Y,Z` as three finite numbers.
fn parse_v3(text: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [x, y, z] = parts[..] else {
        return Err(format!("{text:?} is not three numbers X,Y,Z"));
    };
    let num = |v: &str| {
        v.parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("{v:?} in {text:?} is not a finite number"))
    };
    Ok([num(x)?, num(y)?, num(z)?])
}
