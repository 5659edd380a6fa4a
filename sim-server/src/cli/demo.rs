//! `sim-server demo`: the whole stack on the embedded liver with a simulated
//! device running a scripted hepatectomy: the daemon's simulated hand holds
//! the grasper, which grips the left lobe and pulls it while the cavitron
//! (scripted in the simulation) removes right-lobe parenchyma.

use super::{load_scene, write_json};
use crate::server::{RunConfig, ToolScript};
use anyhow::{Context, Result, bail};
use serde::Serialize;
use sim_server::math::Vec3;
use sim_server::scene::spec::BackendName;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// The grasper's scripted hand (a trajectory for the daemon's simulated device).
const GRASPER_CSV: &str = include_str!("../../scenes/hepatectomy-grasper.csv");

/// Flags of `sim-server demo`.
#[derive(clap::Args)]
pub struct DemoArgs {
    /// No live status lines (the summary and JSON still come).
    #[arg(long)]
    pub headless: bool,
    /// Seconds to run.
    #[arg(long, default_value_t = 10.0)]
    pub duration_s: f64,
    /// Write the summary as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Do not start the viewer (it starts when a display is available and
    /// not --headless).
    #[arg(long)]
    pub no_viewer: bool,
    /// Backend (tensor-mass, implicit, precomputed, hybrid); default the
    /// scene's.
    #[arg(long, value_enum)]
    pub backend: Option<super::BackendArg>,
    /// Save the run as a ParaView series: a VTU per mesh frame (30 Hz) and
    /// `frames.pvd`, in this directory (created).
    #[arg(long, value_name = "DIR")]
    pub save_frames: Option<PathBuf>,
    /// The step (s) instead of the scene's (as `sim-server run --dt-s`).
    #[arg(long)]
    pub dt_s: Option<f64>,
    /// The haptic daemon's force extrapolator (`haptic-daemon run
    /// --extrapolation`: constant, linear-time, linear-position,
    /// linear-position-signed, local-model, local-normal, local-problem).
    #[arg(long, default_value = "local-problem")]
    pub extrapolation: String,
    /// The implicit backend's CG iterations per step at most (as `sim-server
    /// run --implicit-iterations`; 0: to the tolerance).
    #[arg(long, default_value_t = crate::server::IMPLICIT_STEP_ITERATIONS)]
    pub implicit_iterations: usize,
    /// The simulation's stepping loop under SCHED_FIFO at this priority (as
    /// `sim-server run --rt-priority`; 0: normal priority).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(i32).range(0..=98))]
    pub rt_priority: i32,
    /// The contact law instead of the scene's (as `sim-server run
    /// --contact-law`).
    #[arg(long, value_enum)]
    pub contact_law: Option<super::ContactLawArg>,
}

/// Starts the viewer on `session` when it makes sense: not headless, a
/// display to open a window on, and the binary built next to this one.
fn start_viewer(args: &DemoArgs, session: &str) -> Option<std::process::Child> {
    if args.headless || args.no_viewer {
        return None;
    }
    let has_display = ["DISPLAY", "WAYLAND_DISPLAY"]
        .iter()
        .any(|k| std::env::var_os(k).is_some_and(|v| !v.is_empty()));
    let bin = std::env::current_exe().ok()?.with_file_name("viewer");
    if !has_display {
        eprintln!(
            "demo: no display, so no viewer window; a picture of the session: {} --session {session} --snapshot liver.png",
            bin.display()
        );
        return None;
    }
    if !bin.exists() {
        eprintln!(
            "demo: {} not built: cargo build --release -p viewer --features window",
            bin.display()
        );
        return None;
    }
    let mut cmd = Command::new(&bin);
    cmd.args(["--session", session]).stdout(Stdio::null());
    die_with_parent(&mut cmd);
    match cmd.spawn() {
        Ok(child) => Some(child),
        Err(e) => {
            eprintln!("demo: cannot start {}: {e}", bin.display());
            None
        }
    }
}

#[derive(Serialize)]
struct DemoJson {
    sim_steps_per_s: f64,
    haptic_ticks_per_s: f64,
    tets_removed: u64,
    contact_steps: u64,
    max_force_n: f64,
    device_max_force_n: f64,
    poses_received: u64,
    samples_received_by_daemon: u64,
    duration_s: f64,
    contact_fraction: f64,
    /// Simulated time dropped after stalls (s): why `sim_steps_per_s` can
    /// fall short of the rate on a loaded machine.
    sim_dropped_time_s: f64,
    /// The simulation's step time (us).
    sim_step_us: sim_server::step_time::StepPercentiles,
    /// The stepping thread's CPU time per step's whole work (us; the run
    /// summary's `step_cpu_us`): the step's own cost, without preemption.
    sim_step_cpu_us: sim_server::step_time::StepPercentiles,
    /// The wall time of each step's whole work, the wait left out (us;
    /// the run summary's `step_work_us`).
    sim_step_work_us: sim_server::step_time::StepPercentiles,
    /// Steps finished from the prediction made while the simulation
    /// waited for the pose (the rest ran whole).
    sim_predicted_steps: u64,
    /// The simulation's steps.
    sim_steps: u64,
    /// The implicit backend's CG iterations a step, or the precomputed
    /// backend's Newton iterations of the penalty contact, mean and most,
    /// and the steps its budget stopped short (the run summary's
    /// `solve_*`).
    sim_solve_iterations_mean: f64,
    /// See `sim_solve_iterations_mean`.
    sim_solve_iterations_max: usize,
    /// See `sim_solve_iterations_mean`.
    sim_solve_capped_steps: u64,
    /// The tools' contact law, `penalty` or `projection` (the run
    /// summary's `contact_law`).
    sim_contact_law: &'static str,
}

/// A pipe (both ends close on exec).
fn pipe() -> std::io::Result<(std::fs::File, std::fs::File)> {
    use std::os::fd::FromRawFd;
    let mut fds = [0 as libc::c_int; 2];
    // SAFETY: pipe2(2) writes two descriptors into `fds`; each is then
    // owned by exactly one File.
    unsafe {
        if libc::pipe2(fds.as_mut_ptr(), libc::O_CLOEXEC) != 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok((
            std::fs::File::from_raw_fd(fds[0]),
            std::fs::File::from_raw_fd(fds[1]),
        ))
    }
}

// The trajectory is written into its pipe before the daemon starts: it
// must fit the pipe's buffer (64 KiB on Linux; POSIX promises 4 KiB).
const _: () = assert!(GRASPER_CSV.len() < 4096);

/// The daemon's file descriptors for its trajectory (read) and its JSON
/// summary (write): no file in /tmp, so a demo killed outright (SIGKILL)
/// leaves nothing behind. The daemon opens them as `/dev/fd/3` and `/dev/fd/4`.
const TRAJ_FD: libc::c_int = 3;
const JSON_FD: libc::c_int = 4;

/// Gives the child `traj` as fd 3 and `json` as fd 4 (without close-on-exec).
fn pass_fds(cmd: &mut Command, traj: libc::c_int, json: libc::c_int) {
    use std::os::unix::process::CommandExt;
    // SAFETY: the closure runs in the child between fork and exec and calls
    // only async-signal-safe functions (fcntl, dup2). Both descriptors are
    // first copied above 10, so that placing one cannot clobber the other.
    unsafe {
        cmd.pre_exec(move || {
            let high = |fd| {
                let h = libc::fcntl(fd, libc::F_DUPFD, 10);
                if h < 0 {
                    Err(std::io::Error::last_os_error())
                } else {
                    Ok(h)
                }
            };
            let (t, j) = (high(traj)?, high(json)?);
            for (from, to) in [(t, TRAJ_FD), (j, JSON_FD)] {
                if libc::dup2(from, to) < 0 {
                    return Err(std::io::Error::last_os_error());
                }
                // The daemon holds only fds 3 and 4: a second write end of
                // the summary pipe would keep the demo's read from ending.
                libc::close(from);
            }
            Ok(())
        });
    }
}

/// Makes the child get SIGTERM when the demo dies, even by SIGKILL (Linux
/// `PR_SET_PDEATHSIG`): a haptic daemon left running would go on
/// commanding its device with nobody to stop it.
fn die_with_parent(cmd: &mut Command) {
    use std::os::unix::process::CommandExt;
    let parent = std::process::id() as libc::pid_t;
    // SAFETY: the closure runs in the child between fork and exec and calls
    // only async-signal-safe functions (prctl, getppid, _exit).
    unsafe {
        cmd.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            // The parent may have died before the prctl took effect.
            if libc::getppid() != parent {
                libc::_exit(0);
            }
            Ok(())
        });
    }
}

/// The cavitron: from outside the anterior face of the right lobe, slowly in.
fn cavitron_script() -> ToolScript {
    ToolScript {
        tool: 1,
        points: vec![
            (0.0, Vec3::new(-0.04, 0.12, 0.0), 1.0),
            (2.0, Vec3::new(-0.04, 0.08, 0.0), 1.0),
            (8.0, Vec3::new(-0.04, 0.03, 0.0), 1.0),
            (10.0, Vec3::new(-0.04, 0.12, 0.0), 1.0),
        ],
    }
}

/// Runs the demo.
pub fn run(args: DemoArgs) -> Result<()> {
    if !(args.duration_s.is_finite() && args.duration_s > 0.0) {
        bail!("--duration-s must be positive");
    }
    let backend = args.backend.map(BackendName::from);
    let (src, mut scene) = load_scene(None)?;
    super::override_step(&mut scene, args.dt_s)?;
    super::override_contact_law(&mut scene, args.contact_law);
    if scene.tools.len() < 2 {
        bail!("the demo scene needs two tools");
    }
    let exe = std::env::current_exe()?;
    let daemon_bin = exe.with_file_name("haptic-daemon");
    if !daemon_bin.exists() {
        bail!(
            "{} not found: build it with `cargo build --release -p haptic-daemon`",
            daemon_bin.display()
        );
    }
    let pid = std::process::id();
    let session = format!("demo{pid}");
    // The trajectory goes in through a pipe (it fits the pipe's buffer),
    // the daemon's summary comes back through another.
    let (traj_read, mut traj_write) = pipe().context("cannot make a pipe for the daemon")?;
    let (mut json_read, json_write) = pipe().context("cannot make a pipe for the daemon")?;
    {
        use std::io::Write;
        traj_write.write_all(GRASPER_CSV.as_bytes())?;
    }
    drop(traj_write);
    let mut daemon_cmd = Command::new(&daemon_bin);
    daemon_cmd
        .args([
            "run",
            "--session",
            &session,
            "--extrapolation",
            &args.extrapolation,
        ])
        .arg("--device")
        .arg(format!("simulated:/dev/fd/{TRAJ_FD}"))
        .arg("--duration-s")
        .arg(format!("{}", args.duration_s))
        .arg("--json")
        .arg(format!("/dev/fd/{JSON_FD}"))
        .stdout(Stdio::null());
    if args.headless {
        daemon_cmd.arg("--quiet");
    }
    die_with_parent(&mut daemon_cmd);
    {
        use std::os::fd::AsRawFd;
        pass_fds(
            &mut daemon_cmd,
            traj_read.as_raw_fd(),
            json_write.as_raw_fd(),
        );
    }
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, stop.clone())?;
    }
    let mut viewer = start_viewer(&args, &session);
    let cfg = RunConfig {
        session: shared::SessionName::new(&session)?,
        headless: false,
        max_steps: None,
        duration_s: Some(args.duration_s + 0.3),
        viewer_rate_hz: 30.0,
        status: !args.headless,
        scripts: vec![cavitron_script()],
        pose_timeout_ns: crate::server::poses::DEFAULT_POSE_TIMEOUT_NS,
        save_frames: args.save_frames.clone(),
        scene_name: src.name.clone(),
        rt_priority: args.rt_priority,
        implicit_step_iterations: super::implicit_step_iterations(args.implicit_iterations),
    };
    // The daemon starts once the backend is prepared (its scripted hand
    // runs on its own clock from then).
    let mut daemon = None;
    let result = super::run_scene(&src, scene, backend, &cfg, stop.clone(), || {
        let child = daemon_cmd
            .spawn()
            .with_context(|| format!("cannot start {}", daemon_bin.display()))?;
        daemon = Some(child);
        // Only the daemon holds these ends now: its exit closes the summary.
        drop((traj_read, json_write));
        Ok(())
    });
    if let Some(v) = &mut viewer {
        // SIGTERM: the window closes; nothing of the viewer's needs saving.
        // SAFETY: kill(2) on our own child's pid.
        unsafe { libc::kill(v.id() as libc::pid_t, libc::SIGTERM) };
        let _ = v.wait();
    }
    let summary = match result {
        Ok(s) => s,
        Err(e) => {
            if let Some(d) = &mut daemon {
                let _ = d.kill();
                let _ = d.wait();
            }
            return Err(e);
        }
    };
    let Some(mut daemon) = daemon else {
        bail!("the simulation ran without starting the haptic daemon");
    };
    if stop.load(Ordering::Relaxed) {
        // Interrupted: the daemon ramps its force down and ends now rather
        // than running out its duration.
        // SAFETY: kill(2) on our own child's pid.
        unsafe { libc::kill(daemon.id() as libc::pid_t, libc::SIGTERM) };
    }
    // The summary (a few hundred bytes) fits the pipe: read after exit.
    let status = daemon.wait()?;
    if !status.success() {
        bail!("haptic-daemon failed ({status})");
    }
    let mut text = String::new();
    {
        use std::io::Read;
        json_read
            .read_to_string(&mut text)
            .context("reading the haptic daemon's summary")?;
    }
    let d: serde_json::Value =
        serde_json::from_str(&text).context("the haptic daemon's summary")?;
    let out = DemoJson {
        sim_steps_per_s: summary.steps_per_s,
        haptic_ticks_per_s: d["rate_hz"].as_f64().unwrap_or(0.0),
        tets_removed: summary.tets_removed,
        contact_steps: summary.contact_steps,
        max_force_n: d["max_force_n"].as_f64().unwrap_or(f64::NAN),
        device_max_force_n: d["device_max_force_n"].as_f64().unwrap_or(f64::NAN),
        poses_received: summary.poses_received,
        samples_received_by_daemon: d["samples_received"].as_u64().unwrap_or(0),
        duration_s: args.duration_s,
        contact_fraction: summary.contact_fraction,
        sim_dropped_time_s: summary.dropped_time_s,
        sim_step_us: summary.step_us,
        sim_step_cpu_us: summary.step_cpu_us,
        sim_step_work_us: summary.step_work_us,
        sim_predicted_steps: summary.predicted_steps,
        sim_steps: summary.steps,
        sim_solve_iterations_mean: summary.solve_iterations_mean,
        sim_solve_iterations_max: summary.solve_iterations_max,
        sim_solve_capped_steps: summary.solve_capped_steps,
        sim_contact_law: summary.contact_law,
    };
    println!(
        "demo on {}: sim {:.0} steps/s, haptic {:.0} Hz | {} contact steps, {} tetrahedra removed, tools {:.1}% of the step | max rendered force {:.3} N (device limit {} N)",
        src.name,
        out.sim_steps_per_s,
        out.haptic_ticks_per_s,
        out.contact_steps,
        out.tets_removed,
        100.0 * out.contact_fraction,
        out.max_force_n,
        out.device_max_force_n
    );
    if let Some(path) = &args.json {
        write_json(path, &out)?;
    }
    Ok(())
}
