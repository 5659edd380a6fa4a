//! `haptic-daemon run`: the hard-real-time haptic loop.

use anyhow::{Context, Result, bail};
use chain_args::ChainArgs;
use clap::{Parser, Subcommand};
use haptic_daemon::daemon::{ChainConfig, RtLoop, Shared};
use haptic_daemon::device::{
    Device, HandModel, Haply, Path, Plugin, Replay, Simulated, Trajectory,
};
use haptic_daemon::extrapolate::Method;
use haptic_daemon::extrapolate::local_problem::LocalProblem;
use haptic_daemon::io::{IoConfig, IoSpin, Stats, run_io};
use haptic_daemon::local_setup::{LocalSetup, run_local_setup};
use haptic_daemon::rt::{LatenessHistogram, Pacer, RtReport, lock_memory, pin_to_cpu, set_fifo};
use haptic_daemon::safety::{SafetyConfig, SafetyState};
use record_cmd::{RecordArgs, record_main};
use serde::Serialize;
use shared::{SessionName, monotonic_ns, services};
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

mod chain_args;
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
    Run(RunArgs),
    /// Record a session's force samples and telemetry losslessly, counting
    /// sequence gaps (SIGINT/SIGTERM stop it after a flush).
    #[command(allow_negative_numbers = true)]
    Record(RecordArgs),
}

#[derive(clap::Args)]
struct RunArgs {
    /// simulated (a hand poking along z), simulated:FILE.csv (a hand following a
    /// trajectory), replay:FILE.csv (open-loop positions), plugin:LIB.so[:ARGS]
    /// (a C-ABI device, see include/hapsim_device.h), haply[:ws://HOST:PORT]
    /// (Haply Inverse3 through the Haply Inverse Service, default
    /// ws://localhost:10001).
    #[arg(long, default_value = "simulated")]
    device: String,
    /// Loop rate (Hz), 100 to 10000.
    #[arg(long, default_value_t = 1000.0)]
    rate: f64,
    /// The force extrapolator (default local-problem: the lowest error on
    /// every `hapbench extrapolation` run in the README, passive on all;
    /// without contact problems from the simulation it renders as
    /// local-normal, the next best).
    #[arg(long, value_enum, default_value_t = Method::LocalProblem)]
    extrapolation: Method,
    /// `local-problem`: solve the contact problems quasi-statically, without
    /// the tissue's inertia the simulation sends with them.
    #[arg(long)]
    quasi_static: bool,
    /// Force limit (N); at most the device's own.
    #[arg(long)]
    max_force: Option<f64>,
    /// The daemon's checks (pose plausibility, live samples, stiffness
    /// cap, passivity).
    #[command(flatten)]
    chain: ChainArgs,
    /// Shared memory (default) or a session on another host.
    #[command(flatten)]
    remote: remote_args::RemoteArgs,
    /// Session name shared with the simulation.
    #[arg(long, default_value = "default")]
    session: String,
    /// Stop after this many seconds (default: until SIGINT/SIGTERM).
    #[arg(long)]
    duration_s: Option<f64>,
    /// Write the summary as JSON here at exit.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Record every tick to this CSV.
    #[arg(long)]
    record: Option<PathBuf>,
    /// SCHED_FIFO priority to ask for the RT thread (0 = do not ask).
    #[arg(long, default_value_t = 80)]
    rt_priority: i32,
    /// Pin the loop to this CPU.
    #[arg(long)]
    cpu: Option<usize>,
    /// Wake this many microseconds early and spin to the deadline (lower
    /// lateness, more CPU; at most half a period).
    #[arg(long, default_value_t = 0)]
    spin_us: u64,
    /// The I/O thread polls for each pose in a window of this many
    /// microseconds around its due time instead of being woken by the RT
    /// thread: one thread wake-up less on the pose's way to the
    /// simulation, the window's CPU every period (0: off; at most a
    /// period).
    #[arg(long, default_value_t = 0)]
    io_spin_us: u64,
    /// No live status line.
    #[arg(long)]
    quiet: bool,
}

#[derive(Serialize)]
struct Lateness {
    p50: f64,
    p99: f64,
    p999: f64,
    max: f64,
}

impl Lateness {
    fn of(h: &LatenessHistogram) -> Self {
        Self {
            p50: h.quantile_us(0.5),
            p99: h.quantile_us(0.99),
            p999: h.quantile_us(0.999),
            max: h.max_us(),
        }
    }
}

/// What the RT thread reports at its end.
struct RtEnd {
    ticks: u64,
    overruns: u64,
    /// `local-problem`: each tick's render time.
    render_us: Option<Lateness>,
}

#[derive(Serialize)]
struct Summary {
    /// With --connect: the clock offset estimate to the simulation's host
    /// (remote - local, us) and the probe round trip bounding its error.
    clock_offset_us: Option<f64>,
    clock_rtt_us: Option<f64>,
    ticks: u64,
    rate_hz: f64,
    target_rate_hz: f64,
    lateness_us: Lateness,
    max_force_n: f64,
    device_max_force_n: f64,
    force_limit_n: f64,
    extrapolation: &'static str,
    device: String,
    max_stiffness_n_per_m: f64,
    samples_received: u64,
    samples_not_live: u64,
    /// `local-problem`: contact problems set up, of those with the tissue's
    /// inertia, and refused.
    local_problems: u64,
    local_problems_inertial: u64,
    local_problems_refused: u64,
    /// `local-problem`: each tick's render on the RT thread (us).
    local_problem_render_us: Option<Lateness>,
    poses_rejected: u64,
    pose_rereferences: u64,
    passivity: bool,
    passivity_active_ticks: u64,
    passivity_dissipated_j: f64,
    telemetry_dropped: u64,
    overruns: u64,
    recorded_rows: u64,
    warnings: Vec<String>,
}

fn make_device(spec: &str, max_force_n: f64) -> Result<DeviceChoice> {
    let (kind, arg) = spec
        .split_once(':')
        .map_or((spec, None), |(k, a)| (k, Some(a)));
    match (kind, arg) {
        ("simulated", None) => {
            let path = Path::Poke {
                start_m: [0.0, 0.0, 0.05],
                direction: [0.0, 0.0, -1.0],
                depth_m: 0.03,
                period_s: 4.0,
            };
            Ok(DeviceChoice::Simulated(Simulated::new(
                path,
                HandModel::default(),
                max_force_n,
            )))
        }
        ("simulated", Some(file)) => {
            let t = Trajectory::read(std::path::Path::new(file))?;
            Ok(DeviceChoice::Simulated(Simulated::new(
                Path::Trajectory(t),
                HandModel::default(),
                max_force_n,
            )))
        }
        ("replay", Some(file)) => {
            let t = Trajectory::read(std::path::Path::new(file))?;
            Ok(DeviceChoice::Replay(Replay::new(t, max_force_n)))
        }
        ("plugin", Some(rest)) => {
            // plugin:PATH[:ARGS]
            let (lib, plugin_args) = rest.split_once(':').unwrap_or((rest, ""));
            Ok(DeviceChoice::Plugin(Plugin::load(
                std::path::Path::new(lib),
                plugin_args,
            )?))
        }
        ("haply", url) => Ok(DeviceChoice::Haply(Haply::connect(
            url.unwrap_or("ws://localhost:10001"),
        )?)),
        _ => bail!(
            "unknown device {spec:?}: use simulated, simulated:FILE.csv, replay:FILE.csv or plugin:LIB.so[:ARGS]"
        ),
    }
}

/// The devices this binary knows, as a closed set (the loop is generic).
enum DeviceChoice {
    Simulated(Simulated),
    Replay(Replay),
    Plugin(Plugin),
    Haply(Haply),
}

impl DeviceChoice {
    fn specs(&self) -> haptic_daemon::device::DeviceSpecs {
        match self {
            DeviceChoice::Simulated(d) => d.specs(),
            DeviceChoice::Replay(d) => d.specs(),
            DeviceChoice::Plugin(d) => d.specs(),
            DeviceChoice::Haply(d) => d.specs(),
        }
    }
}

/// The device's own limit for the simulated and replayed devices (N).
const SIMULATED_DEVICE_MAX_FORCE_N: f64 = 8.0;

fn main() -> Result<()> {
    let args = match Cli::parse().command {
        Command::Run(args) => args,
        Command::Record(args) => return record_main(args),
    };
    if !(100.0..=10_000.0).contains(&args.rate) {
        bail!("--rate must lie in 100..=10000 Hz, got {}", args.rate);
    }
    if let Some(d) = args.duration_s
        && !(d.is_finite() && d > 0.0)
    {
        bail!("--duration-s must be a positive number of seconds, got {d}");
    }
    let method = args.extrapolation;
    let session = SessionName::new(&args.session)?;
    let transport = args.remote.transport(&session)?;
    let device = make_device(&args.device, SIMULATED_DEVICE_MAX_FORCE_N)?;
    let device_max = device.specs().max_force_n;
    let limit = match args.max_force {
        Some(f) if !(f.is_finite() && f > 0.0) => {
            bail!("--max-force must be a positive number of newtons")
        }
        Some(f) if f > device_max => {
            bail!("--max-force {f} N exceeds the device's limit of {device_max} N")
        }
        Some(f) => f,
        None => device_max,
    };
    let safety = SafetyConfig::new(limit)?;
    let chain = args.chain.config(device.specs().max_stiffness_n_per_m)?;
    let stiffness_cap = chain
        .max_stiffness_n_per_m
        .unwrap_or(device.specs().max_stiffness_n_per_m);
    let shared = Arc::new(Shared::new(1 << 16));
    let stop_signal = Arc::new(std::sync::atomic::AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, stop_signal.clone())?;
    }
    let stats = Arc::new(Mutex::new(Stats::default()));
    let period_ns = (1e9 / args.rate).round() as u64;
    let io_spin = (args.io_spin_us > 0).then(|| IoSpin {
        period_ns,
        window_ns: args.io_spin_us.saturating_mul(1000).min(period_ns),
    });
    // `local-problem`: a thread of its own sets up each contact problem,
    // the RT thread solves the newest (a triple buffer between them,
    // allocated here).
    let (local_in, local_out) = if method == Method::LocalProblem {
        let (i, o) = triple_buffer::triple_buffer(&LocalProblem::new());
        (Some(i), Some(o))
    } else {
        (None, None)
    };
    let io = {
        let cfg = IoConfig {
            transport: transport.clone(),
            session: session.clone(),
            record: args.record.clone(),
            spin: io_spin,
        };
        // The I/O thread stays at normal priority: SCHED_FIFO 5 below the
        // RT thread was tried and measured slower at the median beside a
        // normal-priority simulation on two cores (README, Latency).
        let (shared, stats) = (shared.clone(), stats.clone());
        std::thread::Builder::new()
            .name("haptic-io".into())
            .spawn(move || run_io(shared, cfg, stats))?
    };
    let local_setup = match local_in {
        Some(input) => {
            let (shared, session, transport) = (shared.clone(), session.clone(), transport.clone());
            let setup = LocalSetup {
                tick_ns: period_ns,
                inertia: !args.quasi_static,
            };
            Some(
                std::thread::Builder::new()
                    .name("haptic-local".into())
                    .spawn(move || run_local_setup(shared, transport, session, setup, input))?,
            )
        }
        None => None,
    };
    let spin_ns = args.spin_us.saturating_mul(1000);
    let (report_tx, report_rx) = std::sync::mpsc::channel::<RtReport>();
    let rt = {
        let shared = shared.clone();
        let session = session.clone();
        let transport = transport.clone();
        let (priority, cpu) = (args.rt_priority, args.cpu);
        std::thread::Builder::new()
            .name("haptic-rt".into())
            .spawn(move || -> Result<RtEnd> {
                let _ = haptic_daemon::rt::minimal_timer_slack();
                let mut report = RtReport {
                    mlockall: Some(lock_memory()),
                    ..RtReport::default()
                };
                if priority > 0 {
                    report.sched_fifo = Some(set_fifo(priority));
                }
                if let Some(c) = cpu {
                    report.affinity = Some(pin_to_cpu(c));
                }
                let _ = report_tx.send(report);
                let (sub, _node) = transport.force_source(
                    "haptic-daemon-rt",
                    &session,
                    services::FORCE_BUFFER_LATEST,
                )?;
                let result = match device {
                    DeviceChoice::Simulated(d) => run_loop(
                        d,
                        method,
                        safety,
                        chain,
                        sub,
                        local_out,
                        shared.clone(),
                        period_ns,
                        spin_ns,
                    ),
                    DeviceChoice::Replay(d) => run_loop(
                        d,
                        method,
                        safety,
                        chain,
                        sub,
                        local_out,
                        shared.clone(),
                        period_ns,
                        spin_ns,
                    ),
                    DeviceChoice::Plugin(d) => run_loop(
                        d,
                        method,
                        safety,
                        chain,
                        sub,
                        local_out,
                        shared.clone(),
                        period_ns,
                        spin_ns,
                    ),
                    DeviceChoice::Haply(d) => run_loop(
                        d,
                        method,
                        safety,
                        chain,
                        sub,
                        local_out,
                        shared.clone(),
                        period_ns,
                        spin_ns,
                    ),
                };
                shared.flags.rt_done.store(true, Ordering::Release);
                result
            })?
    };
    let warnings: Vec<String> = report_rx.recv().map(|r| r.warnings()).unwrap_or_default();
    for w in &warnings {
        say!("warning: {w}");
    }
    let start = Instant::now();
    let mut last_status = Instant::now();
    loop {
        std::thread::sleep(Duration::from_millis(50));
        let expired = args
            .duration_s
            .is_some_and(|d| start.elapsed().as_secs_f64() >= d);
        if expired || stop_signal.load(Ordering::Relaxed) || rt.is_finished() {
            shared.flags.stop.store(true, Ordering::Release);
            break;
        }
        if !args.quiet && last_status.elapsed() >= Duration::from_secs(1) {
            last_status = Instant::now();
            // Formatted under the lock, printed after it: the I/O thread
            // takes this lock every batch and must not wait on a slow
            // terminal.
            let line = {
                let s = stats.lock().expect("stats");
                let rate = s.rate_hz();
                let age = if s.last_age_ns == u64::MAX {
                    "none".to_string()
                } else {
                    format!("{:.1} ms", s.last_age_ns as f64 / 1e6)
                };
                let f = s.last_force_n;
                format!(
                    "{rate:7.0} Hz | lateness p50 {:.0} us p99 {:.0} us max {:.0} us | sample age {age} | force {:+.3} {:+.3} {:+.3} N | rejected {} poses, {} samples | passivity {} ticks | {}",
                    s.lateness.quantile_us(0.5),
                    s.lateness.quantile_us(0.99),
                    s.lateness.max_us(),
                    f[0],
                    f[1],
                    f[2],
                    shared.poses_rejected.load(Ordering::Relaxed),
                    shared.samples_not_live.load(Ordering::Relaxed),
                    shared.passivity_ticks.load(Ordering::Relaxed),
                    if shared.flags.peer_alive.load(Ordering::Relaxed) {
                        "sim connected"
                    } else {
                        "no sim"
                    }
                )
            };
            say!("{line}");
        }
    }
    let rt_result = rt
        .join()
        .map_err(|_| anyhow::anyhow!("the real-time thread panicked (the device was disabled)"))?;
    let io_result = io
        .join()
        .map_err(|_| anyhow::anyhow!("the I/O thread panicked"))?;
    let RtEnd {
        ticks,
        overruns,
        render_us,
    } = rt_result?;
    io_result?;
    if let Some(t) = local_setup {
        t.join()
            .map_err(|_| anyhow::anyhow!("the contact-problem thread panicked"))??;
    }
    let s = stats.lock().expect("stats");
    let mut warnings = warnings;
    if shared.flags.version_mismatch.load(Ordering::Relaxed) {
        warnings.push(format!(
            "ignored force samples of another protocol version (this daemon speaks {})",
            shared::protocol::PROTOCOL_VERSION
        ));
    }
    let remote_clock = match &transport {
        haptic_daemon::transport::Transport::Remote(link) => Some((
            link.clock().offset_ns() as f64 * 1e-3,
            link.clock().rtt_ns() as f64 * 1e-3,
        )),
        haptic_daemon::transport::Transport::Shm => None,
    };
    let summary = Summary {
        ticks,
        rate_hz: s.rate_hz(),
        target_rate_hz: args.rate,
        lateness_us: Lateness::of(&s.lateness),
        max_force_n: s.max_force_n,
        device_max_force_n: device_max,
        force_limit_n: limit,
        extrapolation: method.name(),
        device: args.device.clone(),
        max_stiffness_n_per_m: stiffness_cap,
        samples_received: shared.samples.load(Ordering::Relaxed),
        samples_not_live: shared.samples_not_live.load(Ordering::Relaxed),
        local_problems: shared.local_problems.load(Ordering::Relaxed),
        local_problems_inertial: shared.local_problems_inertial.load(Ordering::Relaxed),
        local_problems_refused: shared.local_problems_refused.load(Ordering::Relaxed),
        local_problem_render_us: render_us,
        poses_rejected: shared.poses_rejected.load(Ordering::Relaxed),
        pose_rereferences: shared.pose_rereferences.load(Ordering::Relaxed),
        passivity: chain.passivity.enabled,
        passivity_active_ticks: shared.passivity_ticks.load(Ordering::Relaxed),
        passivity_dissipated_j: shared.passivity_dissipated_j(),
        telemetry_dropped: shared.telemetry_dropped.load(Ordering::Relaxed),
        overruns,
        recorded_rows: s.recorded,
        warnings,
        clock_offset_us: remote_clock.map(|c| c.0),
        clock_rtt_us: remote_clock.map(|c| c.1),
    };
    out!(
        "{} ticks at {:.1} Hz (target {}) | lateness us p50 {:.0} p99 {:.0} p99.9 {:.0} max {:.0} | max force {:.3} N (limit {} N) | {} samples ({} not live) | {} poses rejected ({} new references) | passivity damped {} ticks",
        summary.ticks,
        summary.rate_hz,
        summary.target_rate_hz,
        summary.lateness_us.p50,
        summary.lateness_us.p99,
        summary.lateness_us.p999,
        summary.lateness_us.max,
        summary.max_force_n,
        summary.force_limit_n,
        summary.samples_received,
        summary.samples_not_live,
        summary.poses_rejected,
        summary.pose_rereferences,
        summary.passivity_active_ticks
    );
    if method == Method::LocalProblem {
        out!(
            "local-problem: {} contact problems set up ({} with the tissue's inertia), {} refused; a tick's render p50 {:.0} us, p99 {:.0} us, max {:.0} us",
            summary.local_problems,
            summary.local_problems_inertial,
            summary.local_problems_refused,
            summary
                .local_problem_render_us
                .as_ref()
                .map_or(0.0, |l| l.p50),
            summary
                .local_problem_render_us
                .as_ref()
                .map_or(0.0, |l| l.p99),
            summary
                .local_problem_render_us
                .as_ref()
                .map_or(0.0, |l| l.max)
        );
    }
    for w in &summary.warnings {
        say!("warning: {w}");
    }
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&summary)? + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

/// The loop on the RT thread: ticks until stop, then ramps the force to zero
/// and disables the device. A panic inside is caught so the device is still
/// zeroed and disabled. Returns the ticks, overruns and render times.
#[allow(clippy::too_many_arguments)] // the loop's whole configuration, passed once
fn run_loop<D: Device>(
    device: D,
    method: Method,
    safety: SafetyConfig,
    chain: ChainConfig,
    sub: shared::source::Source<shared::protocol::ForceMsg>,
    local: Option<triple_buffer::Output<LocalProblem>>,
    shared: Arc<Shared>,
    period_ns: u64,
    spin_ns: u64,
) -> Result<RtEnd> {
    let mut rt = RtLoop::with_chain(device, method, safety, chain, Some(sub), shared.clone());
    if let Some(local) = local {
        rt = rt.with_local_problems(local);
    }
    let start = monotonic_ns();
    rt.enable(start)?;
    let mut pacer = Pacer::new(period_ns, start).with_spin(spin_ns);
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let mut stopping = false;
        loop {
            let (deadline, lateness) = pacer.wait();
            if !stopping && shared.flags.stop.load(Ordering::Acquire) {
                rt.shutdown(deadline);
                stopping = true;
            }
            rt.tick(deadline.saturating_add(lateness.max(0) as u64), lateness);
            if stopping && matches!(rt.safety_state(), SafetyState::Stopped(_)) {
                break;
            }
        }
    }));
    rt.disable();
    if outcome.is_err() {
        bail!("the real-time loop panicked; the device was zeroed and disabled");
    }
    Ok(RtEnd {
        ticks: rt.ticks(),
        overruns: pacer.overruns(),
        render_us: rt.render_times().map(Lateness::of),
    })
}
