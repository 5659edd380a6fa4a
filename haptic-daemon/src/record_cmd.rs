//! `haptic-daemon record`: a session's force samples and telemetry, losslessly.

use anyhow::{Context, Result, bail};
use shared::SessionName;
use std::path::PathBuf;
use std::sync::Arc;

#[derive(clap::Args)]
pub struct RecordArgs {
    /// Session to record.
    #[arg(long, default_value = "default")]
    session: String,
    /// Force samples CSV (one row per tool per simulation step).
    #[arg(long)]
    forces: Option<PathBuf>,
    /// Telemetry CSV (one row per haptic tick, the `run --record` columns).
    #[arg(long)]
    telemetry: Option<PathBuf>,
    /// Stop after this many seconds.
    #[arg(long)]
    duration_s: Option<f64>,
    /// Write the counts (received, gaps, lost, restarts per stream) as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    #[command(flatten)]
    remote: crate::remote_args::RemoteArgs,
}

pub fn record_main(args: RecordArgs) -> Result<()> {
    if args.forces.is_none() && args.telemetry.is_none() && args.json.is_none() {
        bail!("nothing to record: give --forces FILE, --telemetry FILE or --json FILE");
    }
    if let Some(d) = args.duration_s
        && !(d.is_finite() && d > 0.0)
    {
        bail!("--duration-s must be a positive number of seconds");
    }
    // Two streams into one file interleaved their rows and lost a header.
    crate::out_files::distinct(
        &[
            ("--forces", args.forces.as_deref()),
            ("--telemetry", args.telemetry.as_deref()),
            ("--json", args.json.as_deref()),
        ],
        &[],
    )?;
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, stop.clone())?;
    }
    let session = SessionName::new(&args.session)?;
    let transport = args.remote.transport(&session)?;
    let cfg = haptic_daemon::record::RecordConfig {
        session,
        forces: args.forces,
        telemetry: args.telemetry,
        duration_s: args.duration_s,
    };
    let s = haptic_daemon::record::record(&cfg, &transport, &stop)?;
    eprintln!(
        "recorded {} force samples ({} gaps, {} lost, {} restarts), {} ticks ({} gaps, {} lost, {} restarts)",
        s.forces.received,
        s.forces.gaps,
        s.forces.lost,
        s.forces.restarts,
        s.telemetry.received,
        s.telemetry.gaps,
        s.telemetry.lost,
        s.telemetry.restarts
    );
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&s)? + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}
