//! `hapbench latency`: how late things arrive, beside their raw baselines
//! measured in the same run.
//!
//! - Baselines: bare iceoryx2 one-way latency (a child process publishes a
//!   time-stamped sample every millisecond, this process receives it) and
//!   bare `clock_nanosleep` lateness (a 1 kHz absolute-deadline loop).
//! - The system: `sim-server run` and `haptic-daemon run` (simulated hand)
//!   in one session, observed by this process on the same streams:
//!   sim -> daemon (force sample stamp to its receipt), daemon -> sim (pose
//!   stamp, taken at the device read, to its receipt), device -> force (a
//!   device read until the first force sample computed from that pose is
//!   published, plus the sim -> daemon transport: when the daemon can render
//!   it), and the daemon's tick lateness from its telemetry.
//!
//! Receipt is by a subscriber polled every 20 us, so the figures are the
//! transport and the processes' own delays, not this observer's.
//!
//! The simulation's own step time (`sim_step_us`, from its run summary) is
//! reported beside them: device -> force cannot be shorter than a step, and
//! when a step takes longer than the simulation's period a pose also waits
//! for the step in progress.

use anyhow::{Context, Result};
use haptic_daemon::rt::Pacer;
use serde::Serialize;
use shared::protocol::ForceMsg;
use shared::{SessionName, monotonic_ns, services};
use std::collections::VecDeque;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use crate::plot::{Axes, Scale, Series, chart};
use crate::progress::bar;

/// Flags of `hapbench latency`.
#[derive(clap::Args)]
pub struct Args {
    /// Seconds per measurement.
    #[arg(long, default_value_t = 5.0)]
    pub duration_s: f64,
    /// Write the results here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write SVG plots here.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// The simulation's scene (default: sim-server's embedded liver).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// The simulation's step (s), instead of the scene's (`sim-server run
    /// --dt-s`).
    #[arg(long)]
    pub dt_s: Option<f64>,
    /// The daemon's I/O thread polls for poses in a window of this many
    /// microseconds (`haptic-daemon run --io-spin-us`; 0: woken by the RT
    /// thread).
    #[arg(long, default_value_t = 0)]
    pub io_spin_us: u64,
    /// The daemon's extrapolator (`haptic-daemon run --extrapolation`;
    /// `local-problem` also has the simulation publish contact problems).
    #[arg(long, value_enum, default_value_t = haptic_daemon::extrapolate::Method::LocalProblem)]
    pub extrapolation: haptic_daemon::extrapolate::Method,
    /// `local-problem` without the tissue's inertia (`haptic-daemon run
    /// --quasi-static`).
    #[arg(long)]
    pub quasi_static: bool,
    /// Both processes under SCHED_FIFO: the daemon's RT thread at this
    /// priority, the simulation's stepping loop 10
    /// below (`--rt-priority` of each), the observer 3 below (only when the
    /// simulation is real-time too); 0: the daemon without it and the
    /// simulation at normal priority (the default).
    /// Needs CAP_SYS_NICE or an rtprio limit.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(i32).range(0..=99))]
    pub rt_priority: i32,
    /// The simulation's loop priority instead of `--rt-priority` - 10 (0:
    /// normal priority, e.g. to time the daemon's default beside a
    /// normal-priority simulation).
    #[arg(long, value_parser = clap::value_parser!(i32).range(0..=98))]
    pub sim_rt_priority: Option<i32>,
    /// The daemon on the far side of `sim-server bridge` (zenoh over
    /// loopback TCP, `--connect`), force samples observed where it receives
    /// them, beside a bare zenoh baseline.
    #[arg(long)]
    pub bridge: bool,
}

/// Percentiles of one latency (us).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Stats {
    /// Samples.
    pub count: usize,
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// 99.9th percentile.
    pub p999: f64,
    /// Largest.
    pub max: f64,
}

/// Percentiles of `v` (sorted in place); zeros when empty.
pub fn stats(v: &mut [f64]) -> Stats {
    if v.is_empty() {
        return Stats::default();
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    Stats {
        count: v.len(),
        p50: at(0.5),
        p99: at(0.99),
        p999: at(0.999),
        max: v[v.len() - 1],
    }
}

#[derive(Serialize)]
struct Report {
    duration_s: f64,
    /// The daemon ran through `sim-server bridge` (zenoh, loopback TCP).
    bridge: bool,
    baseline_iceoryx2_us: Stats,
    /// Bare zenoh between two processes (with `--bridge`).
    baseline_zenoh_us: Option<Stats>,
    /// The daemon's clock offset estimate at its end and its probe round
    /// trip (us; with `--bridge`; the true offset is zero on one host). The
    /// pose figures (daemon -> sim, device -> force) are corrected by it.
    daemon_clock_offset_us: Option<f64>,
    daemon_clock_rtt_us: Option<f64>,
    baseline_sleep_lateness_us: Stats,
    sim_to_daemon_us: Stats,
    daemon_to_sim_us: Stats,
    device_to_force_us: Stats,
    tick_lateness_us: Stats,
    /// The simulation's physics step (its run summary's `step_us`).
    sim_step_us: serde_json::Value,
    /// The simulation's turnaround, wake-up to sample sent (its run
    /// summary's `turnaround_us`).
    sim_turnaround_us: serde_json::Value,
    /// From a pose's device read to the simulation waking for the step
    /// that takes it (its run summary's `pose_wait_us`).
    sim_pose_wait_us: serde_json::Value,
    /// Steps the simulation started early on a fresh pose.
    sim_steps_on_pose: u64,
    /// Steps the simulation took.
    sim_steps: u64,
    /// The SCHED_FIFO priorities asked (`--rt-priority`) and granted: the
    /// simulation's loop (its run summary's `rt_priority`, 0 when refused
    /// or not asked).
    rt_priority_asked: i32,
    sim_rt_priority: serde_json::Value,
}

pub(crate) fn spawn(args: &[&str], bin: PathBuf) -> Result<Child> {
    Command::new(&bin)
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .with_context(|| format!("cannot start {}", bin.display()))
}

fn sibling(name: &str) -> Result<PathBuf> {
    let bin = std::env::current_exe()?.with_file_name(name);
    anyhow::ensure!(
        bin.exists(),
        "{} not found: build it with `cargo build --release --workspace`",
        bin.display()
    );
    Ok(bin)
}

fn us(ns: i128) -> f64 {
    ns as f64 * 1e-3
}

/// Runs the measurements.
pub fn run(args: &Args) -> Result<()> {
    anyhow::ensure!(
        args.duration_s.is_finite() && args.duration_s >= 0.5,
        "--duration-s must be at least 0.5"
    );
    if let Some(dt) = args.dt_s {
        // Checked here too: sim-server would refuse it, and the run would
        // end with only "no traffic".
        sim_server::scene::check_step("--dt-s", dt).map_err(anyhow::Error::msg)?;
    }
    let d = args.duration_s;
    let what = run_description(args);
    println!("run: {what}");
    let pid = std::process::id();
    // The daemon's timer slack (1 ns) for the observer's polling and the
    // sleep baseline alike, so that only what is measured differs.
    let _ = haptic_daemon::rt::minimal_timer_slack();
    let node = services::node("hapbench-latency")?;
    let progress = bar(3, "latency");

    // Baseline 1: bare iceoryx2 between two processes.
    let probe_session = format!("hapbench-probe{pid}");
    let sub = services::subscriber(&services::force_service(
        &node,
        &SessionName::new(&probe_session)?,
    )?)?;
    let mut probe = spawn(
        &[
            "probe",
            "--session",
            &probe_session,
            "--duration-s",
            &d.to_string(),
        ],
        std::env::current_exe()?,
    )?;
    let mut bare = Vec::new();
    let end = monotonic_ns() + ((d + 1.0) * 1e9) as u64;
    while monotonic_ns() < end {
        while let Ok(Some(s)) = sub.receive() {
            bare.push(us(monotonic_ns() as i128 - s.t_ns as i128));
        }
        std::thread::sleep(Duration::from_micros(20));
    }
    let _ = probe.wait();
    drop(sub);
    progress.inc(1);

    // Baseline 2: bare clock_nanosleep at 1 kHz (timer slack as the daemon's).
    let mut pacer = Pacer::new(1_000_000, monotonic_ns());
    let mut sleep = Vec::new();
    for _ in 0..(d * 1000.0) as usize {
        let (_, late) = pacer.wait();
        sleep.push(late as f64 * 1e-3);
    }

    let mut bare_zenoh = if args.bridge {
        Some(crate::latency_remote::bare(d)?)
    } else {
        None
    };

    progress.inc(1);
    // The system.
    let session_name = format!("hapbench-lat{pid}");
    let session = SessionName::new(&session_name)?;
    let forces = services::subscriber(&services::force_service(&node, &session)?)?;
    let poses = services::subscriber(&services::pose_service(&node, &session)?)?;
    let telemetry = services::subscriber(&services::telemetry_service(&node, &session)?)?;
    let run_s = (d + 2.0).to_string();
    let sim_json = std::env::temp_dir().join(format!("hapbench-latency-sim{pid}.json"));
    let mut sim_args = vec![
        "run".to_string(),
        "--quiet".to_string(),
        "--session".to_string(),
        session_name.clone(),
        "--duration-s".to_string(),
        run_s,
        "--json".to_string(),
        sim_json.display().to_string(),
    ];
    if let Some(scene) = &args.scene {
        sim_args.push("--scene".to_string());
        sim_args.push(scene.display().to_string());
    }
    if let Some(dt) = args.dt_s {
        sim_args.push("--dt-s".to_string());
        sim_args.push(dt.to_string());
    }
    let sim_priority = args
        .sim_rt_priority
        .unwrap_or((args.rt_priority - 10).clamp(0, 98));
    if sim_priority > 0 {
        sim_args.push("--rt-priority".to_string());
        sim_args.push(sim_priority.to_string());
    }
    let sim_args: Vec<&str> = sim_args.iter().map(String::as_str).collect();
    let mut sim = spawn(&sim_args, sibling("sim-server")?)?;
    std::thread::sleep(Duration::from_millis(500));
    // With --bridge: the daemon joins through zenoh, and its force samples
    // are observed on zenoh, where it receives them.
    let bridged = match args.bridge {
        true => Some(crate::latency_remote::Bridged::start(
            &session,
            d + 2.0,
            &sibling("sim-server")?,
        )?),
        false => None,
    };
    let endpoint = bridged
        .as_ref()
        .map(|b| b.endpoint.clone())
        .unwrap_or_default();
    let (daemon_for_s, io_spin_us) = ((d + 0.5).to_string(), args.io_spin_us.to_string());
    let daemon_priority = args.rt_priority.to_string();
    let daemon_json = std::env::temp_dir().join(format!("hapbench-latency-daemon{pid}.json"));
    let daemon_json_arg = daemon_json.display().to_string();
    let mut daemon = spawn(
        &[
            "run",
            "--quiet",
            "--rt-priority",
            &daemon_priority,
            "--session",
            &session_name,
            "--duration-s",
            &daemon_for_s,
            "--io-spin-us",
            &io_spin_us,
            "--extrapolation",
            args.extrapolation.name(),
        ]
        .into_iter()
        .chain(args.quasi_static.then_some("--quasi-static"))
        .chain(args.bridge.then_some("--connect"))
        .chain(args.bridge.then_some(endpoint.as_str()))
        .chain(["--json", daemon_json_arg.as_str()])
        .collect::<Vec<_>>(),
        sibling("haptic-daemon")?,
    )?;
    // Real-time only beside a real-time simulation: beside a normal one
    // it would take the simulation's share instead.
    if args.rt_priority > 3 && sim_priority > 0 {
        // The observer above the simulation's loop and the daemon's I/O
        // thread, below its RT thread (whose ticks it must not delay): at
        // normal priority it waited for their turns, and its receive times
        // (daemon -> sim, device -> force) grew by ~200 us that the
        // processes did not take.
        if let Err(e) = shared::rt::set_fifo(args.rt_priority - 3) {
            eprintln!("hapbench: {}", shared::rt::fifo_refused_hint(&e));
        }
    }
    // What queued while the processes started is not latency: drop it.
    while let Ok(Some(_)) = forces.receive() {}
    while let Ok(Some(_)) = poses.receive() {}
    while let Ok(Some(_)) = telemetry.receive() {}
    let (mut s2d, mut d2s, mut dev2f, mut ticks) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    // Recent poses by seq: (seq, device-read stamp).
    let mut recent: VecDeque<(u64, u64)> = VecDeque::with_capacity(4096);
    let mut last_used = None;
    let end = monotonic_ns() + ((d + 1.0) * 1e9) as u64;
    while monotonic_ns() < end {
        while let Ok(Some(p)) = poses.receive() {
            d2s.push(us(monotonic_ns() as i128 - p.t_ns as i128));
            if recent.len() == recent.capacity() {
                recent.pop_front();
            }
            recent.push_back((p.seq, p.t_ns));
        }
        // Shared memory: received by this poll; zenoh: as delivered.
        let arrived: Vec<(u64, ForceMsg)> = match &bridged {
            Some(b) => b.observer.drain(),
            None => std::iter::from_fn(|| forces.receive().ok().flatten().map(|f| *f))
                .map(|f| (monotonic_ns(), f))
                .collect(),
        };
        for (received_ns, f) in arrived {
            let now = received_ns as i128;
            let transport = now - f.t_ns as i128;
            s2d.push(us(transport));
            // Only the first step that used a pose: later steps reuse it
            // when no newer one came (e.g. after the daemon stopped).
            let used = f.tools[0].pose_seq;
            if last_used != Some(used)
                && let Some(&(_, read_ns)) = recent.iter().find(|(s, _)| *s == used)
            {
                dev2f.push(us(f.t_ns as i128 - read_ns as i128 + transport));
            }
            last_used = Some(used);
        }
        while let Ok(Some(b)) = telemetry.receive() {
            for t in &b.ticks[..(b.count as usize).min(b.ticks.len())] {
                ticks.push(t.lateness_ns as f64 * 1e-3);
            }
        }
        std::thread::sleep(Duration::from_micros(20));
    }
    let _ = daemon.wait();
    let daemon_summary: serde_json::Value = std::fs::read_to_string(&daemon_json)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default();
    let _ = std::fs::remove_file(&daemon_json);
    // The daemon stamps poses in the simulation host's clock by its offset
    // estimate; on one host the true offset is zero, so its estimate is the
    // error those figures carry: take it out.
    let clock = daemon_summary["clock_offset_us"]
        .as_f64()
        .zip(daemon_summary["clock_rtt_us"].as_f64());
    if let Some((offset_us, _)) = clock {
        for v in d2s.iter_mut().chain(dev2f.iter_mut()) {
            *v += offset_us;
        }
    }
    if let Some(b) = bridged {
        b.stop();
    }
    // SIGTERM: the simulation stops and writes its summary.
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(sim.id() as libc::pid_t, libc::SIGTERM) };
    let _ = sim.wait();
    let sim_summary: serde_json::Value = std::fs::read_to_string(&sim_json)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default();
    let _ = std::fs::remove_file(&sim_json);
    progress.finish_and_clear();
    anyhow::ensure!(
        !s2d.is_empty() && !d2s.is_empty(),
        "no traffic between sim-server and haptic-daemon"
    );

    let mut curves: Vec<(&str, Vec<f64>)> = vec![
        ("iceoryx2 bare", bare.clone()),
        ("sleep lateness bare", sleep.clone()),
        ("sim -> daemon", s2d.clone()),
        ("daemon -> sim", d2s.clone()),
        ("device -> force", dev2f.clone()),
        ("tick lateness", ticks.clone()),
    ];
    if let Some(z) = &bare_zenoh {
        curves.push(("zenoh bare", z.clone()));
    }
    let report = Report {
        duration_s: d,
        bridge: args.bridge,
        baseline_iceoryx2_us: stats(&mut bare),
        baseline_zenoh_us: bare_zenoh.as_mut().map(|v| stats(v)),
        daemon_clock_offset_us: clock.map(|c| c.0),
        daemon_clock_rtt_us: clock.map(|c| c.1),
        baseline_sleep_lateness_us: stats(&mut sleep),
        sim_to_daemon_us: stats(&mut s2d),
        daemon_to_sim_us: stats(&mut d2s),
        device_to_force_us: stats(&mut dev2f),
        tick_lateness_us: stats(&mut ticks),
        sim_step_us: sim_summary["step_us"].clone(),
        sim_turnaround_us: sim_summary["turnaround_us"].clone(),
        sim_pose_wait_us: sim_summary["pose_wait_us"].clone(),
        rt_priority_asked: args.rt_priority,
        sim_rt_priority: sim_summary["rt_priority"].clone(),
        sim_steps_on_pose: sim_summary["steps_on_pose"].as_u64().unwrap_or(0),
        sim_steps: sim_summary["steps"].as_u64().unwrap_or(0),
    };
    println!(
        "{:<22} {:>8} {:>10} {:>10} {:>10} {:>10}",
        "latency (us)", "count", "p50", "p99", "p99.9", "max"
    );
    let zenoh_bare = report.baseline_zenoh_us.map(|z| ("zenoh (bare)", z));
    for (name, s) in zenoh_bare.iter().map(|(n, z)| (*n, z)).chain([
        ("iceoryx2 (bare)", &report.baseline_iceoryx2_us),
        ("sleep lateness (bare)", &report.baseline_sleep_lateness_us),
        ("sim -> daemon", &report.sim_to_daemon_us),
        ("daemon -> sim", &report.daemon_to_sim_us),
        ("device -> force", &report.device_to_force_us),
        ("tick lateness", &report.tick_lateness_us),
    ]) {
        println!(
            "{name:<22} {:>8} {:>10.1} {:>10.1} {:>10.1} {:>10.1}",
            s.count, s.p50, s.p99, s.p999, s.max
        );
    }
    for (name, v) in [
        ("sim step", &report.sim_step_us),
        ("sim turnaround", &report.sim_turnaround_us),
        ("device -> sim wake", &report.sim_pose_wait_us),
    ] {
        let at = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
        println!(
            "{name:<22} {:>8} {:>10.1} {:>10.1} {:>10.1} {:>10.1}",
            report.sim_steps,
            at("p50"),
            at("p99"),
            at("p999"),
            at("max")
        );
    }
    if args.rt_priority > 0 || sim_priority > 0 {
        println!(
            "SCHED_FIFO: daemon RT thread asked {}, simulation loop {sim_priority} (granted: {})",
            args.rt_priority, report.sim_rt_priority
        );
    }
    if let (Some(o), Some(r)) = (report.daemon_clock_offset_us, report.daemon_clock_rtt_us) {
        println!(
            "the daemon's clock offset estimate {o:+.1} us (round trip {r:.1} us; true offset 0; taken out of the pose figures)"
        );
    }
    if let Some(path) = &args.json {
        sim_server::provenance::write_stamped(path, &report)?;
    }
    if let Some(dir) = &args.plot {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let mut series: Vec<Series> = curves
            .into_iter()
            .map(|(name, v)| Series::line(name, tail_points(v)))
            .collect();
        // The simulation's own rows: only their summary's percentiles, as
        // markers where they fall (the largest at 1 - 1/steps).
        let steps = report.sim_steps.max(2) as f64;
        for (name, v) in [
            ("sim step", &report.sim_step_us),
            ("sim turnaround", &report.sim_turnaround_us),
            ("device -> sim wake", &report.sim_pose_wait_us),
        ] {
            let pts: Vec<(f64, f64)> = [(0.5, "p50"), (0.99, "p99"), (0.999, "p999")]
                .into_iter()
                .chain([(1.0 - 1.0 / steps, "max")])
                .filter_map(|(p, k)| Some((p, v[k].as_f64()?)))
                .collect();
            series.push(Series::markers(name, pts));
        }
        let x1 = series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0))
            .fold(0.99, f64::max);
        let svg = chart(
            &format!("Latency percentiles: {what}"),
            "percentile (1 - p on a log scale)",
            "latency (us)",
            0.0,
            x1,
            &series,
            Axes {
                x: Scale::Tail,
                y: Scale::Log10,
            },
        );
        let path = dir.join("latency.svg");
        std::fs::write(&path, svg).with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

/// What a run measures, said at its start and in its plot's title: the
/// scene, the duration, the step and the daemon's settings, with the
/// defaults named.
fn run_description(args: &Args) -> String {
    let scene = args.scene.as_ref().map_or_else(
        || "the embedded liver (default)".to_string(),
        |p| p.display().to_string(),
    );
    let dt = args.dt_s.map_or_else(
        || "the scene's step".to_string(),
        |dt| format!("step {dt} s"),
    );
    format!(
        "{scene}, {} s, {dt}, {}{} extrapolation, RT priority {}{}",
        args.duration_s,
        args.extrapolation.name(),
        if args.quasi_static {
            " (quasi-static)"
        } else {
            ""
        },
        args.rt_priority,
        if args.bridge { ", zenoh bridge" } else { "" }
    )
}

/// A sorted distribution's percentile curve for a tail axis: points at
/// log-spaced 1 - p, from p0 to the last sample's p = 1 - 1/n.
fn tail_points(mut v: Vec<f64>) -> Vec<(f64, f64)> {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return Vec::new();
    }
    // 50 points per decade of 1 - p, each the sample at that rank.
    let decades = (n as f64).log10();
    let steps = (decades * 50.0).ceil() as usize;
    let mut out: Vec<(f64, f64)> = Vec::with_capacity(steps + 1);
    let mut last = usize::MAX;
    for k in 0..=steps {
        let p = 1.0 - 10f64.powf(-decades * k as f64 / steps.max(1) as f64);
        let i = ((p * n as f64) as usize).min(n - 1);
        if i != last {
            out.push((i as f64 / n as f64, v[i]));
            last = i;
        }
    }
    out
}
