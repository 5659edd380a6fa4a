//! `sim-server run`: the simulation process.

use super::{load_scene, write_json};
use crate::server::{RunConfig, RunError};
use anyhow::{Result, bail};
use sim_server::scene::spec::BackendName;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// Flags of `sim-server run`.
#[derive(clap::Args)]
pub struct RunArgs {
    /// Scene file (default: the embedded liver scene).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Session shared with the daemon and the viewer.
    #[arg(long, default_value = "default")]
    pub session: String,
    /// Backend: tensor-mass (explicit, the paper's), implicit (backward
    /// Euler), precomputed (static responses, no cutting) or hybrid
    /// (precomputed joined to a cuttable tensor-mass part the scene's
    /// `[hybrid]` selects); default: the scene's `[simulation] backend`,
    /// else tensor-mass.
    #[arg(long, value_enum)]
    pub backend: Option<super::BackendArg>,
    /// Step as fast as possible instead of in real time.
    #[arg(long)]
    pub headless: bool,
    /// Stop after this many steps.
    #[arg(long, value_parser = super::count_u64)]
    pub steps: Option<u64>,
    /// Stop after this many seconds.
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// Mesh-state rate for viewers (Hz).
    #[arg(long, default_value_t = 30.0)]
    pub viewer_rate: f64,
    /// Write the run summary as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// No status line.
    #[arg(long)]
    pub quiet: bool,
    /// A tool whose pose is older than this (ms, from the device read), or
    /// whose pose publisher died, lets go until a fresh pose comes.
    #[arg(long, default_value_t = 50.0)]
    pub pose_timeout_ms: f64,
    /// Save the run as a ParaView series in this directory (created): a VTU
    /// per mesh frame (at --viewer-rate: rest positions, `displacement`,
    /// `elastic_force`, `original_id`, cell `tet_id`) and `frames.pvd`.
    /// Written by a thread of its own: a disk that cannot keep up drops
    /// frames (counted), never delays a step.
    #[arg(long, value_name = "DIR")]
    pub save_frames: Option<PathBuf>,
    /// The step (s) instead of the scene's `[simulation] dt_s`: the period
    /// of force samples and of pose intake. A shorter step answers a pose
    /// sooner (device -> force) for more CPU and a larger contact share;
    /// docs/results/latency.md.
    #[arg(long)]
    pub dt_s: Option<f64>,
    /// Run the stepping loop under SCHED_FIFO at this priority (1-98; 0:
    /// normal). Below the haptic daemon's RT thread (80 by default): the
    /// loop then wakes for a pose and steps without waiting for other
    /// processes' time slices. Needs CAP_SYS_NICE or an rtprio limit;
    /// refused, it runs at normal priority and says so.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(i32).range(0..=98))]
    pub rt_priority: i32,
    /// The implicit backend's CG iterations per step at most while its
    /// Cholesky factor preconditions (0: iterate to the tolerance). A grip
    /// or a cut makes the factor stale until its rebuild arrives from the
    /// worker thread (tens of ms); bounded, those steps cost what any step
    /// costs and stop short of the tolerance (counted in the summary's
    /// `solve_capped_steps`). docs/guide/backends.md.
    #[arg(long, default_value_t = crate::server::IMPLICIT_STEP_ITERATIONS)]
    pub implicit_iterations: usize,
    /// The contact law instead of the scene's `[contact] law` (penalty:
    /// tensor-mass and precomputed, their default; projection: every
    /// backend, the default of implicit and hybrid). docs/design/contact.md.
    #[arg(long, value_enum)]
    pub contact_law: Option<super::ContactLawArg>,
}

/// Runs until SIGINT/SIGTERM, the step count or the duration.
pub fn run(args: RunArgs) -> Result<()> {
    let backend = args.backend.map(BackendName::from);
    if !(args.viewer_rate.is_finite() && args.viewer_rate > 0.0) {
        bail!("--viewer-rate must be a positive number of Hz");
    }
    if let Some(d) = args.duration_s
        && !(d.is_finite() && d > 0.0)
    {
        bail!("--duration-s must be a positive number of seconds, got {d}");
    }
    if args.headless && args.rt_priority > 0 {
        // Headless never sleeps: under SCHED_FIFO it would hold its core.
        bail!(
            "--rt-priority is for real-time runs: --headless steps without pause and would hold a core under SCHED_FIFO"
        );
    }
    if !(args.pose_timeout_ms.is_finite() && args.pose_timeout_ms > 0.0) {
        bail!("--pose-timeout-ms must be a positive number of milliseconds");
    }
    let (src, mut scene) = load_scene(args.scene.as_deref())?;
    super::override_step(&mut scene, args.dt_s)?;
    super::override_contact_law(&mut scene, args.contact_law);
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, stop.clone())?;
    }
    let cfg = RunConfig {
        session: shared::SessionName::new(&args.session)?,
        headless: args.headless,
        max_steps: args.steps,
        duration_s: args.duration_s,
        viewer_rate_hz: args.viewer_rate,
        status: !args.quiet,
        scripts: Vec::new(),
        pose_timeout_ns: (args.pose_timeout_ms * 1e6).round() as u64,
        save_frames: args.save_frames.clone(),
        scene_name: src.name.clone(),
        rt_priority: args.rt_priority,
        implicit_step_iterations: super::implicit_step_iterations(args.implicit_iterations),
    };
    let summary = match super::run_scene(&src, scene, backend, &cfg, stop, || Ok(())) {
        Ok(summary) => summary,
        Err(e) => {
            // A diverged run still writes its JSON (`finite`: false).
            if let (Some(path), Some(RunError::Diverged { summary, .. })) =
                (&args.json, e.downcast_ref::<RunError>())
            {
                write_json(path, summary)?;
            }
            return Err(e);
        }
    };
    println!(
        "{}: {} steps ({:.0} steps/s, {:.2} s simulated) | {} poses in, {} force samples out | {} contact steps, {} tetrahedra removed, max force {:.3} N | step us p50 {:.0} p99 {:.0} p99.9 {:.0} max {:.0} (a step's whole work p50 {:.0} p99.9 {:.0}, its CPU time p50 {:.0} p99.9 {:.0}){}",
        src.name,
        summary.steps,
        summary.steps_per_s,
        summary.sim_time_s,
        summary.poses_received,
        summary.samples_published,
        summary.contact_steps,
        summary.tets_removed,
        summary.max_force_n,
        summary.step_us.p50,
        summary.step_us.p99,
        summary.step_us.p999,
        summary.step_us.max,
        summary.step_work_us.p50,
        summary.step_work_us.p999,
        summary.step_cpu_us.p50,
        summary.step_cpu_us.p999,
        if summary.stalls > 0 {
            format!(
                " | {} stalls: {:.3} s of simulated time dropped",
                summary.stalls, summary.dropped_time_s
            )
        } else {
            String::new()
        }
    );
    if summary.solve_iterations_max > 0 {
        println!(
            "{}: linear solves: {:.2} iterations a step on average, {} at most; {} steps stopped at the --implicit-iterations budget",
            src.name,
            summary.solve_iterations_mean,
            summary.solve_iterations_max,
            summary.solve_capped_steps
        );
    }
    if let Some(dir) = &args.save_frames {
        println!(
            "{}: {} frames saved to {} (open frames.pvd in ParaView){}",
            src.name,
            summary.frames_saved,
            dir.display(),
            if summary.frames_dropped > 0 {
                format!(
                    ", {} dropped because the disk was behind",
                    summary.frames_dropped
                )
            } else {
                String::new()
            }
        );
    }
    if summary.corotational_region_rebuilds > 0 {
        println!(
            "{}: the corotational region that follows the tools held at most {} tetrahedra and changed {} times",
            src.name,
            summary.corotational_region_largest_tets,
            summary.corotational_region_rebuilds
        );
    }
    if summary.multirate_fast_vertices > 0 {
        println!(
            "{}: multirate: {} fast vertices took {} sub-steps a step, the rest {}",
            src.name,
            summary.multirate_fast_vertices,
            summary.multirate_fine_substeps,
            summary.multirate_coarse_substeps
        );
    }
    if summary.nonlinear_tets > 0 {
        println!(
            "{}: {} nonlinear tetrahedra; at most {} StVK elements squeezed below half their volume at once (their volume barrier acted)",
            src.name, summary.nonlinear_tets, summary.max_barrier_elements
        );
    }
    if let Some(path) = &args.json {
        write_json(path, &summary)?;
    }
    Ok(())
}
