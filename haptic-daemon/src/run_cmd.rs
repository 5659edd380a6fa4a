//! `haptic-daemon run`: checks the arguments, starts the I/O thread, the
//! contact problems' set-up thread and the real-time thread, prints a
//! status line a second, and at the end joins them and reports.

use crate::device_choice::{DeviceChoice, SIMULATED_DEVICE_MAX_FORCE_N, make_device};
use crate::device_choice::{Lateness, LoopConfig, RtEnd};
use crate::run_args::RunArgs;
use anyhow::{Context, Result, bail};
use haptic_daemon::daemon::Shared;
use haptic_daemon::device::WorkspaceSpec;
use haptic_daemon::extrapolate::Method;
use haptic_daemon::extrapolate::local_problem::LocalProblem;
use haptic_daemon::io::{IoConfig, IoSpin, Stats, run_io};
use haptic_daemon::local_setup::{LocalSetup, run_local_setup};
use haptic_daemon::rt::{RtReport, lock_memory, pin_to_cpu, set_fifo};
use haptic_daemon::safety::SafetyConfig;
use haptic_daemon::transport::Transport;
use serde::Serialize;
use shared::{SessionName, services};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// `--workspace-*` as the summary says them.
#[derive(Serialize)]
struct WorkspaceSummary {
    offset_m: [f64; 3],
    scale: f64,
    rotate_deg: [f64; 3],
    hand_max_stiffness_n_per_m: f64,
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
    /// The device's workspace in the scene and the stiffness cap as the
    /// hand feels it (`max_stiffness_n_per_m` times the scale).
    workspace: WorkspaceSummary,
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
    /// Device reads that failed or carried a non-finite field.
    device_bad_reads: u64,
    pose_rereferences: u64,
    passivity: bool,
    passivity_active_ticks: u64,
    passivity_dissipated_j: f64,
    telemetry_dropped: u64,
    overruns: u64,
    recorded_rows: u64,
    warnings: Vec<String>,
}

/// `haptic-daemon run`: the whole command.
pub(crate) fn run_main(args: RunArgs) -> Result<()> {
    check_args(&args)?;
    // `--record` naming the replayed trajectory overwrote it.
    let device_file = args
        .device
        .split_once(':')
        .filter(|(kind, _)| matches!(*kind, "replay" | "simulated"))
        .map(|(_, file)| std::path::Path::new(file));
    crate::out_files::distinct(
        &[
            ("--record", args.record.as_deref()),
            ("--json", args.json.as_deref()),
        ],
        &[("--device", device_file)],
    )?;
    let method = args.extrapolation;
    let session = SessionName::new(&args.session)?;
    let transport = args.remote.transport(&session)?;
    let (poke, poke_warning) = if args.device == "simulated" {
        aim_poke(&transport, &session, args.quiet)
    } else {
        (None, None)
    };
    let placement = match &args.workspace {
        Some(path) => WorkspaceSpec::read(path)?,
        None => WorkspaceSpec {
            offset_m: args.workspace_offset_m,
            scale: args.workspace_scale,
            rotate_deg: args.workspace_rotate_deg,
        },
    };
    let map = placement
        .map()
        .map_err(|e| anyhow::anyhow!("--workspace-*: {e}"))?;
    let device = make_device(&args.device, SIMULATED_DEVICE_MAX_FORCE_N, poke, map)?;
    let device_max = device.specs().max_force_n;
    let limit = force_limit(args.max_force, device_max)?;
    let safety = SafetyConfig::new(limit)?;
    // --max-stiffness-n-per-m is what the hand feels (a device's data
    // sheet); the loop caps the scene's stiffness, that over the scale.
    let mut chain = args
        .chain
        .config(map.stiffness_at_hand(device.specs().max_stiffness_n_per_m))?;
    chain.max_stiffness_n_per_m = chain.max_stiffness_n_per_m.map(|k| k / map.scale);
    let stiffness_cap = chain
        .max_stiffness_n_per_m
        .unwrap_or(device.specs().max_stiffness_n_per_m);
    if !map.is_identity() && !args.quiet {
        let [x, y, z] = map.offset_m.map(|v| v * 1e3);
        let [rx, ry, rz] = placement.rotate_deg;
        say!(
            "workspace: the device's origin at ({x:.1}, {y:.1}, {z:.1}) mm in the scene, scale {}, turned ({rx}, {ry}, {rz}) deg; stiffness cap {stiffness_cap:.0} N/m in the scene, {:.0} N/m at the hand",
            map.scale,
            map.stiffness_at_hand(stiffness_cap)
        );
    }
    let shared = Arc::new(Shared::new(1 << 16));
    let stop_signal = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, stop_signal.clone())?;
    }
    let stats = Arc::new(Mutex::new(Stats::default()));
    let period_ns = (1e9 / args.rate).round() as u64;
    // `local-problem`: a thread of its own sets up each contact problem,
    // the RT thread solves the newest (a triple buffer between them,
    // allocated here).
    let (local_in, local_out) = if method == Method::LocalProblem {
        let (i, o) = triple_buffer::triple_buffer(&LocalProblem::new());
        (Some(i), Some(o))
    } else {
        (None, None)
    };
    let io = spawn_io(&args, &shared, &stats, &transport, &session, period_ns)?;
    let local_setup = match local_in {
        Some(input) => Some(spawn_local_setup(
            &shared,
            &transport,
            &session,
            LocalSetup {
                tick_ns: period_ns,
                inertia: !args.quasi_static,
            },
            input,
        )?),
        None => None,
    };
    let (report_tx, report_rx) = std::sync::mpsc::channel::<RtReport>();
    let rt = spawn_rt(
        device,
        LoopConfig {
            method,
            safety,
            chain,
            local: local_out,
            shared: shared.clone(),
            period_ns,
            spin_ns: args.spin_us.saturating_mul(1000),
        },
        (args.rt_priority, args.cpu),
        (transport.clone(), session.clone()),
        report_tx,
    )?;
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
            let line = status_line(&stats, &shared);
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
    warnings.extend(poke_warning);
    if shared.flags.version_mismatch.load(Ordering::Relaxed) {
        warnings.push(format!(
            "ignored force samples of another protocol version (this daemon speaks {})",
            shared::protocol::PROTOCOL_VERSION
        ));
    }
    let remote_clock = match &transport {
        Transport::Remote(link) => Some((
            link.clock().offset_ns() as f64 * 1e-3,
            link.clock().rtt_ns() as f64 * 1e-3,
        )),
        Transport::Shm => None,
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
        workspace: WorkspaceSummary {
            offset_m: placement.offset_m,
            scale: map.scale,
            rotate_deg: placement.rotate_deg,
            hand_max_stiffness_n_per_m: map.stiffness_at_hand(stiffness_cap),
        },
        samples_received: shared.samples.load(Ordering::Relaxed),
        samples_not_live: shared.samples_not_live.load(Ordering::Relaxed),
        local_problems: shared.local_problems.load(Ordering::Relaxed),
        local_problems_inertial: shared.local_problems_inertial.load(Ordering::Relaxed),
        local_problems_refused: shared.local_problems_refused.load(Ordering::Relaxed),
        local_problem_render_us: render_us,
        poses_rejected: shared.poses_rejected.load(Ordering::Relaxed),
        device_bad_reads: shared.device_bad_reads.load(Ordering::Relaxed),
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
    drop(s);
    print_summary(&summary, method);
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&summary)? + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

/// How long `--device simulated` waits for a running simulation's scene
/// to aim its built-in poke.
const SCENE_WAIT: Duration = Duration::from_secs(1);

/// The built-in poke aimed at the simulation's organ (its rest bounding
/// box, from the `scene` stream), or `None` (the poke down the z axis)
/// when no simulation is there or none answers within [`SCENE_WAIT`], with
/// the warning that says so (printed, and kept for the summary).
fn aim_poke(
    transport: &Transport,
    session: &SessionName,
    quiet: bool,
) -> (Option<haptic_daemon::device::Path>, Option<String>) {
    // No simulation there, no wait: a daemon started first pokes the axis.
    let scene = transport.scene_now(session, SCENE_WAIT).ok().flatten();
    // Tool 0 is the device's; its round end starts clear of the organ.
    let path = scene.and_then(|s| {
        let radius = if s.tool_count > 0 {
            s.tools[0].radius_m
        } else {
            0.0
        };
        haptic_daemon::device::Path::poke_over(s.bounds_min_m, s.bounds_max_m, radius)
    });
    match (&path, quiet) {
        (
            Some(haptic_daemon::device::Path::Poke {
                start_m, depth_m, ..
            }),
            false,
        ) => say!(
            "simulated device: poking the scene's organ at x = {:.1} mm, y = {:.1} mm, from z = {:.1} mm (the tip 3 mm clear of it) down {:.1} mm and back every 4 s",
            start_m[0] * 1e3,
            start_m[1] * 1e3,
            start_m[2] * 1e3,
            depth_m * 1e3
        ),
        (None, _) => {
            let w = format!(
                "no simulation's scene at start (none running, or none answering within {} s): the simulated device pokes down the z axis from z = 50 mm to 20 mm (give it a path with simulated:FILE.csv)",
                SCENE_WAIT.as_secs()
            );
            say!("warning: {w}");
            return (None, Some(w));
        }
        _ => {}
    }
    (path, None)
}

/// The rate and duration, checked before anything starts.
fn check_args(args: &RunArgs) -> Result<()> {
    if !(100.0..=10_000.0).contains(&args.rate) {
        bail!("--rate must lie in 100..=10000 Hz, got {}", args.rate);
    }
    if let Some(d) = args.duration_s
        && !(d.is_finite() && d > 0.0)
    {
        bail!("--duration-s must be a positive number of seconds, got {d}");
    }
    // Asked for more than they can do, they were clamped without a word.
    let period_us = 1e6 / args.rate;
    if args.spin_us as f64 > 0.5 * period_us {
        bail!(
            "--spin-us must be at most half the period ({:.0} us at {} Hz), got {}",
            0.5 * period_us,
            args.rate,
            args.spin_us
        );
    }
    if args.io_spin_us as f64 > period_us {
        bail!(
            "--io-spin-us must be at most the period ({:.0} us at {} Hz), got {}",
            period_us,
            args.rate,
            args.io_spin_us
        );
    }
    Ok(())
}

/// `--max-force`, at most the device's own limit (the default).
fn force_limit(asked: Option<f64>, device_max: f64) -> Result<f64> {
    match asked {
        Some(f) if !(f.is_finite() && f > 0.0) => {
            bail!("--max-force must be a positive number of newtons")
        }
        Some(f) if f > device_max => {
            bail!("--max-force {f} N exceeds the device's limit of {device_max} N")
        }
        Some(f) => Ok(f),
        None => Ok(device_max),
    }
}

/// The I/O thread: poses out, force samples and telemetry in.
fn spawn_io(
    args: &RunArgs,
    shared: &Arc<Shared>,
    stats: &Arc<Mutex<Stats>>,
    transport: &Transport,
    session: &SessionName,
    period_ns: u64,
) -> Result<JoinHandle<Result<(), haptic_daemon::io::IoError>>> {
    let cfg = IoConfig {
        transport: transport.clone(),
        session: session.clone(),
        record: args.record.clone(),
        spin: (args.io_spin_us > 0).then(|| IoSpin {
            period_ns,
            window_ns: args.io_spin_us.saturating_mul(1000).min(period_ns),
        }),
    };
    // The I/O thread stays at normal priority: SCHED_FIFO 5 below the
    // RT thread was tried and measured slower at the median beside a
    // normal-priority simulation on two cores (docs/results/latency.md).
    let (shared, stats) = (shared.clone(), stats.clone());
    Ok(std::thread::Builder::new()
        .name("haptic-io".into())
        .spawn(move || run_io(shared, cfg, stats))?)
}

/// The thread that sets up each contact problem for `local-problem`.
fn spawn_local_setup(
    shared: &Arc<Shared>,
    transport: &Transport,
    session: &SessionName,
    setup: LocalSetup,
    input: triple_buffer::Input<LocalProblem>,
) -> Result<JoinHandle<Result<(), haptic_daemon::transport::TransportError>>> {
    let (shared, session, transport) = (shared.clone(), session.clone(), transport.clone());
    Ok(std::thread::Builder::new()
        .name("haptic-local".into())
        .spawn(move || run_local_setup(shared, transport, session, setup, input))?)
}

/// The real-time thread: memory locked, SCHED_FIFO `priority` and `cpu` as
/// asked (what it got sent back on `report_tx`), the force source of
/// `session` opened, then the loop on the device.
fn spawn_rt(
    device: DeviceChoice,
    cfg: LoopConfig,
    (priority, cpu): (i32, Option<usize>),
    (transport, session): (Transport, SessionName),
    report_tx: std::sync::mpsc::Sender<RtReport>,
) -> Result<JoinHandle<Result<RtEnd>>> {
    Ok(std::thread::Builder::new()
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
            // `_node` keeps the force source's node alive for the loop.
            let (sub, _node) = transport.force_source(
                "haptic-daemon-rt",
                &session,
                services::FORCE_BUFFER_LATEST,
            )?;
            let shared = cfg.shared.clone();
            let result = device.run_loop(cfg, sub);
            shared.flags.rt_done.store(true, Ordering::Release);
            result
        })?)
}

/// The once-a-second status line. Formatted under the stats lock and
/// printed after it: the I/O thread takes this lock every batch and must
/// not wait on a slow terminal.
fn status_line(stats: &Mutex<Stats>, shared: &Shared) -> String {
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
}

/// The summary lines on stdout, warnings on stderr.
fn print_summary(summary: &Summary, method: Method) {
    out!(
        "{} ticks at {:.1} Hz (target {}) | lateness us p50 {:.0} p99 {:.0} p99.9 {:.0} max {:.0} | max force {:.3} N (limit {} N) | {} samples ({} not live) | {} poses rejected ({} new references, {} bad device reads) | passivity damped {} ticks",
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
        summary.device_bad_reads,
        summary.passivity_active_ticks
    );
    if method == Method::LocalProblem {
        let render =
            |q: fn(&Lateness) -> f64| summary.local_problem_render_us.as_ref().map_or(0.0, q);
        out!(
            "local-problem: {} contact problems set up ({} with the tissue's inertia), {} refused; a tick's render p50 {:.0} us, p99 {:.0} us, max {:.0} us",
            summary.local_problems,
            summary.local_problems_inertial,
            summary.local_problems_refused,
            render(|l| l.p50),
            render(|l| l.p99),
            render(|l| l.max)
        );
    }
    for w in &summary.warnings {
        say!("warning: {w}");
    }
}
