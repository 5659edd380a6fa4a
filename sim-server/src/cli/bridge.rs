//! `sim-server bridge`: the session's streams on zenoh for other hosts.

use super::write_json;
use crate::bridge::{BridgeConfig, run};
use anyhow::{Result, bail};
use shared::SessionName;
use shared::remote::{Auth, DEFAULT_LISTEN, RemoteConfig, token};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

/// Flags of `sim-server bridge`.
#[derive(clap::Args)]
pub struct BridgeArgs {
    /// The session to carry.
    #[arg(long, default_value = "default")]
    pub session: String,
    /// Listen here (zenoh endpoint: tcp/ADDR:PORT, or tls/ADDR:PORT with a
    /// --zenoh-config giving the certificates); repeatable. Default
    /// tcp/127.0.0.1:7447 (loopback only) unless --connect or a
    /// --zenoh-config with endpoints is given.
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Vec<String>,
    /// Connect to a zenoh router or peer here instead of (or besides)
    /// listening; repeatable.
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// A zenoh configuration file (JSON5): TLS, mutual authentication,
    /// access control (docs/guide/remote.md). --listen and --connect override
    /// its endpoints.
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
    /// The token every client must know (mode 0600; written with a new
    /// random token if missing, then kept). Default: bridge.token in this
    /// user's private directory (/tmp/hapsim-<uid>/), where clients of the
    /// same user and host find it; give a station a copy (docs/guide/security.md).
    #[arg(long, value_name = "FILE")]
    pub token_file: Option<PathBuf>,
    /// The longest a force sample waits in the bridge (us): shared memory
    /// is polled this often (a remote pose wakes the loop at once).
    #[arg(long, default_value_t = 50)]
    pub poll_us: u64,
    /// Stop after this many seconds.
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// Write the summary as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Runs the bridge until SIGINT/SIGTERM or --duration-s.
pub fn bridge(args: BridgeArgs) -> Result<()> {
    let session = SessionName::new(&args.session)?;
    if !(1..=100_000).contains(&args.poll_us) {
        bail!("--poll-us must lie in 1..=100000, got {}", args.poll_us);
    }
    let duration = match args.duration_s {
        None => None,
        Some(d) => match Duration::try_from_secs_f64(d) {
            Ok(t) if d > 0.0 => Some(t),
            _ => bail!("--duration-s must be a positive number of seconds, got {d}"),
        },
    };
    let token_path = match args.token_file {
        Some(p) => p,
        None => token::default_token_path()?,
    };
    let mut remote = RemoteConfig {
        listen: args.listen,
        connect: args.connect,
        config_file: args.zenoh_config,
        auth: Auth::Serve(token::load_or_create(&token_path)?),
    };
    if remote.listen.is_empty() && remote.connect.is_empty() && remote.config_file.is_none() {
        remote.listen.push(DEFAULT_LISTEN.to_string());
    }
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, stop.clone())?;
    }
    let cfg = BridgeConfig {
        session,
        remote,
        poll: Duration::from_micros(args.poll_us),
        duration,
    };
    eprintln!(
        "sim-server bridge: session {} on zenoh ({})",
        cfg.session.as_str(),
        cfg.remote.describe()
    );
    let summary = run(&cfg, &stop)?;
    let (o, t) = (&summary.outbound, &summary.telemetry);
    println!(
        "bridge {}: {:.1} s | out: {} force samples ({} missed), {} contact problems, {} mesh frames, {} scene messages, {} telemetry batches | in: {} poses ({} refused), {} telemetry batches | simulation arrived {} times",
        summary.session,
        summary.duration_s,
        o.force,
        o.force_gaps,
        o.local_contact,
        o.mesh,
        o.scene_streams,
        t.out,
        summary.inbound.poses,
        summary.inbound.refused,
        t.r#in,
        summary.sim_arrivals
    );
    if let Some(path) = &args.json {
        write_json(path, &summary)?;
    }
    Ok(())
}
