//! The sim-server process loop (`sim-server run`): reads tool poses from the
//! haptic daemon, applies the tool contact models, steps the tensor-mass
//! simulation in real time (or as fast as it can, headless), publishes a
//! force sample per step and the mesh state at the viewer rate, with the
//! topology when cuts change it. It keeps running when the daemon or the
//! viewer disappear and serves them again when they come back.
//!
//! Real time ([`pacing`]): a step starts when it is due, or up to two steps
//! (at most 2 ms) earlier when a fresh pose arrives ([`poses`]: the daemon
//! notifies the `pose-ready` event after each pose, which wakes the wait),
//! so a pose gets its force one step after it arrives; the grid's phase
//! follows the poses' so that they arrive mid-window. After a stall the
//! missed time is dropped, not fast-forwarded. A pose older than
//! [`RunConfig::pose_timeout_ns`], or whose publisher died, drives no tool.

pub mod follow_live;
pub mod local_out;
mod loop_stats;
pub mod outputs;
pub mod pacing;
pub mod poses;
pub mod run_loop;
pub mod scene_out;

use serde::Serialize;
use shared::SessionName;
use shared::services::ServiceError;
use sim_server::backend::Backend;
use sim_server::math::{Real, Vec3};
use sim_server::prepare::Prepared;
use sim_server::step_time::StepPercentiles;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use thiserror::Error;

/// How to run.
#[derive(Clone, Debug)]
pub struct RunConfig {
    /// Session shared with the daemon and the viewer.
    pub session: SessionName,
    /// Step as fast as possible instead of in real time.
    pub headless: bool,
    /// Stop after this many steps.
    pub max_steps: Option<u64>,
    /// Stop after this much wall-clock time (s).
    pub duration_s: Option<Real>,
    /// Mesh-state rate for viewers (Hz).
    pub viewer_rate_hz: Real,
    /// Print a status line every second.
    pub status: bool,
    /// Tools driven by a script instead of the daemon (e.g. the demo's cavitron).
    pub scripts: Vec<ToolScript>,
    /// A pose older than this (ns, its `t_ns` against now) drives no tool;
    /// scripted tools are not affected.
    pub pose_timeout_ns: u64,
    /// Save the mesh frames (at the viewer rate) as a VTU series with
    /// `frames.pvd` in this directory ([`frames`]).
    pub save_frames: Option<std::path::PathBuf>,
    /// The scene's name, for clients ([`scene_out`]).
    pub scene_name: String,
    /// SCHED_FIFO priority for the stepping loop (0: normal priority).
    pub rt_priority: i32,
    /// The implicit backend's CG iterations per step at most while its
    /// factor preconditions (`None`: to the tolerance);
    /// [`sim_server::backend::ImplicitConfig::step_iterations`].
    pub implicit_step_iterations: Option<usize>,
}

/// The implicit backend's default per-step iteration budget in a
/// real-time run: a step with a current factor takes one or two.
pub const IMPLICIT_STEP_ITERATIONS: usize = 2;

/// A scripted tool: tip position and jaw opening against simulated time,
/// linearly interpolated, held after the last point.
#[derive(Clone, Debug)]
pub struct ToolScript {
    /// Index of the scene's `[[tool]]`.
    pub tool: usize,
    /// (time s, tip m, jaw opening), times increasing.
    pub points: Vec<(Real, Vec3, Real)>,
}

impl ToolScript {
    /// The tip and jaw at simulated time `t_s`.
    pub fn at(&self, t_s: Real) -> (Vec3, Real) {
        let p = &self.points;
        let k = p.partition_point(|x| x.0 <= t_s);
        if k == 0 {
            return (p[0].1, p[0].2);
        }
        if k >= p.len() {
            let last = p[p.len() - 1];
            return (last.1, last.2);
        }
        let (a, b) = (p[k - 1], p[k]);
        let w = (t_s - a.0) / (b.0 - a.0);
        (a.1 + (b.1 - a.1) * w, a.2 + (b.2 - a.2) * w)
    }
}

/// What a run did (the JSON of `sim-server run --json`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct RunSummary {
    /// Steps taken.
    pub steps: u64,
    /// Steps per wall-clock second.
    pub steps_per_s: Real,
    /// Simulated time (s).
    pub sim_time_s: Real,
    /// Force samples published.
    pub samples_published: u64,
    /// Pose messages received.
    pub poses_received: u64,
    /// Steps with a tool in contact.
    pub contact_steps: u64,
    /// Steps where the tissue's surface held a tool's tip short of its
    /// pose (it slipped past the tip, or the tip would have entered it:
    /// the linear model far beyond its range; docs/design/contact.md).
    pub held_outside_steps: u64,
    /// Steps where a tool was catching up with its pose near the tissue
    /// (coming back in at the entry speed after a let-go or a jump, or
    /// held outside): its samples carry the `CATCHING_UP` flag.
    pub catching_up_steps: u64,
    /// Tetrahedra removed by tools.
    pub tets_removed: u64,
    /// Largest |reaction force| on any tool (N).
    pub max_force_n: Real,
    /// Mesh frames published.
    pub frames_published: u64,
    /// Whether the displacements stayed finite (false = diverged, stopped).
    pub finite: bool,
    /// Wall-clock time in contact detection, response and reaction (s).
    pub contact_s: Real,
    /// Wall-clock time in the simulation steps (s).
    pub step_s: Real,
    /// contact_s / (contact_s + step_s): what the tools cost per step.
    pub contact_fraction: Real,
    /// Wall time of each physics step (us): p50, p99, p99.9, max.
    pub step_us: StepPercentiles,
    /// The stepping thread's CPU time for each step's whole work (us):
    /// pose intake and the tools, the step, the sample, the hand-over, the
    /// next step's prediction and the status line, from one step's end to
    /// the next's (the blocking wait between them costs only its wake-up). Unlike the wall times it leaves out what the machine took
    /// away (preemption by other threads or the hypervisor): a long step
    /// here is the simulation's own work, a long `step_us` alone is not.
    pub step_cpu_us: StepPercentiles,
    /// The stepping thread's CPU time for the step after the pose alone
    /// (the span of `step_us`): what of a long `step_us` was the
    /// simulation's own work; the rest was the machine (other threads,
    /// the hypervisor). Its two reads of the CPU clock are system calls on
    /// the pose's path, counted in `step_us` (about a microsecond; read
    /// outside the wall span, the CPU span came out up to 20 us longer at
    /// p99.9 than the wall one on a 2-core VM).
    pub step_after_pose_cpu_us: StepPercentiles,
    /// Wall time of each step's whole work (us): from the loop's wake-up
    /// (a pose or the step's due time) to the end of the next step's
    /// prediction, the same work as `step_cpu_us` but on the wall clock
    /// and without the wait (so without the CPU time some VMs charge a
    /// thread that only sleeps). Beside `step_us` (the step after the
    /// pose alone, most of it predicted ahead) this is the step's whole
    /// cost, the figure to compare between backends and with a step
    /// made without a prediction.
    pub step_work_us: StepPercentiles,
    /// Wall time from the loop's wake-up (a pose or the step's due time)
    /// to its force sample sent (us): pose intake and the tools' update,
    /// the step, the sample; the simulation's share of device -> force.
    pub turnaround_us: StepPercentiles,
    /// The contact stiffness's hand-over after each sample (us; a
    /// snapshot for the stiffness solver and a contact problem's sampling
    /// every few steps, nearly nothing otherwise): work that ran inside
    /// the step, before the sample, until 2026-11-26.
    pub hand_over_us: StepPercentiles,
    /// The rest of each step, after its force sample went out: the rows
    /// of a predicted step too far from the tools for the force to depend
    /// on them (`Backend::defer_far_rows`; 0 for backends without).
    pub step_rest_us: StepPercentiles,
    /// From a pose's device read (its `t_ns`) to the loop waking for the
    /// step that takes it, over the steps that took a new pose: the pose's
    /// transport plus the loop's wake-up, or the step in progress it waited
    /// for.
    pub pose_wait_us: StepPercentiles,
    /// Simulated time dropped after stalls instead of fast-forwarded (s):
    /// simulated time ends this far behind wall time.
    pub dropped_time_s: Real,
    /// Stalls after which time was dropped (the loop fell more than two
    /// steps or 5 ms behind real time).
    pub stalls: u64,
    /// Steps started early because a fresh pose arrived.
    pub steps_on_pose: u64,
    /// Times the daemon-driven tools let go because the pose went stale or
    /// its publisher died.
    pub pose_timeouts: u64,
    /// Mean linear-solver iterations a step (implicit backend; 0 for the
    /// others).
    pub solve_iterations_mean: Real,
    /// Most linear-solver iterations in one step.
    pub solve_iterations_max: usize,
    /// Steps whose solve the per-step iteration budget stopped above its
    /// tolerance (`--implicit-iterations`): the stale factor's steps after
    /// a grip or a cut, until the rebuilt one arrives.
    pub solve_capped_steps: u64,
    /// Live tetrahedra with a nonlinear (StVK, corotational) model at the start.
    pub nonlinear_tets: usize,
    /// The tools' contact law: "penalty" or "projection".
    pub contact_law: &'static str,
    /// Most StVK elements compressed below half their volume (in the
    /// volume barrier) at the end of any step: tissue squeezed beyond
    /// what the model is meant for.
    pub max_barrier_elements: usize,
    /// With `--save-frames`: frames written to the VTU series.
    pub frames_saved: u64,
    /// Contact problems published on `local-contact` (while a daemon
    /// rendering `local-problem` subscribed), and those that could not be.
    pub local_problems: u64,
    /// See `local_problems`.
    pub local_problems_dropped: u64,
    /// The stepping loop's SCHED_FIFO priority (`--rt-priority`; 0: normal
    /// priority, as asked or because it was refused).
    pub rt_priority: i32,
    /// The step's worker threads (`threads` above 1 on the tensor-mass
    /// backend) put at the stepping loop's SCHED_FIFO priority with it: a
    /// step waits for them, so at normal priority they made it theirs.
    /// With `[contact] refine_radius_m`, those of the mesh in use at the
    /// end: each mesh swapped in has its own, raised when it comes in.
    pub rt_step_workers: usize,
    /// Steps finished from the prediction made while the loop waited for
    /// the pose (the tensor-mass backend, one thread; the rest ran whole),
    /// and the rows they recomputed in all.
    pub predicted_steps: u64,
    /// See `predicted_steps`.
    pub predicted_rows: u64,
    /// With `--save-frames`: frames not written because the disk was
    /// behind (the step is never delayed for them).
    pub frames_dropped: u64,
    /// With `[contact] corotational_radius_m`: the most tetrahedra the
    /// corotational region that follows the tools held at once (0 without).
    pub corotational_region_largest_tets: usize,
    /// See `corotational_region_largest_tets`: times the region changed.
    pub corotational_region_rebuilds: u64,
    /// With `[contact] refine_radius_m`: meshes made again round the tools
    /// and swapped in (0 without).
    pub remesh_swaps: u64,
    /// See `remesh_swaps`: the mesh's tetrahedra at the end, and the most.
    pub remesh_tets: usize,
    /// See `remesh_swaps`.
    pub remesh_most_tets: usize,
    /// See `remesh_swaps`: wall time of the loop's part (looking where the
    /// tools are, swapping meshes in; s).
    pub remesh_s: Real,
    /// See `remesh_swaps`: the worker's wall time making the meshes, in all
    /// and the longest (s).
    pub remesh_build_wall_s: Real,
    /// See `remesh_build_wall_s`.
    pub remesh_longest_build_wall_s: Real,
    /// See `remesh_swaps`: the first step on each mesh swapped in, apart
    /// (also in `step_us`): whether the swaps make the step's tail.
    pub remesh_first_step_us: StepPercentiles,
    /// See `remesh_swaps`: why the mesh once stayed when the tools moved
    /// (a grip, a cut).
    pub remesh_pinned: Option<&'static str>,
    /// See `remesh_swaps`: whether a mesh stopped at `refine_max_tets`.
    pub remesh_stopped_at_budget: bool,
    /// With `[simulation] multirate`: the vertices stepped at the fine
    /// step, in the largest partition of the run (the end's, or with
    /// `[contact] refine_radius_m` the largest over the meshes; 0 without,
    /// or when it did not pay).
    pub multirate_fast_vertices: usize,
    /// See `multirate_fast_vertices`: whole passes a step (coarse sub-steps).
    pub multirate_coarse_substeps: usize,
    /// See `multirate_fast_vertices`: the fast vertices' sub-steps a step.
    pub multirate_fine_substeps: usize,
}

/// Why a run failed.
#[derive(Debug, Error)]
pub enum RunError {
    /// Shared memory.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// The integrator refused the scene's step.
    #[error(transparent)]
    Explicit(#[from] sim_server::tensor_mass::ExplicitError),
    /// The implicit backend refused the scene.
    #[error(transparent)]
    Implicit(#[from] sim_server::backend::ImplicitError),
    /// `--save-frames` could not start or write.
    #[error(transparent)]
    Frames(#[from] sim_server::frames::FramesError),
    /// A peer sent another protocol version.
    #[error(transparent)]
    Version(#[from] shared::protocol::VersionError),
    /// The simulation diverged (non-finite displacements, or a tool force
    /// no hand can take); forces were zeroed.
    #[error(
        "the simulation diverged at step {step} (non-finite displacements or tool force): the step is too large for this scene or a tool pushed too hard; forces were set to zero"
    )]
    Diverged {
        /// The step.
        step: u64,
        /// What the run did until then (`finite` false), to be written out
        /// like a finished run's: nothing recorded is lost.
        summary: Box<RunSummary>,
    },
    /// Another simulation already publishes in the session.
    #[error(
        "session {session:?} already has a running simulation (a force publisher); stop it or pick another --session"
    )]
    SessionBusy {
        /// The session.
        session: String,
    },
    /// A publish failed.
    /// `--save-frames` with a mesh that follows the tools.
    #[error(
        "--save-frames {dir} records the frames of one mesh, and [contact] refine_radius_m makes the mesh again as the tools move: run without --save-frames, or refine the working region at load with a [[refine]]"
    )]
    FramesOfOneMesh {
        /// The directory asked for.
        dir: std::path::PathBuf,
    },
    #[error("publishing {what} failed: {reason}")]
    Publish {
        /// What.
        what: &'static str,
        /// Why.
        reason: String,
    },
}

fn publish_err(what: &'static str) -> impl Fn(String) -> RunError {
    move |reason| RunError::Publish { what, reason }
}

/// Runs a prepared scene until a stop condition or `stop` is set.
pub fn run<B: Backend>(
    prepared: Prepared<B>,
    cfg: &RunConfig,
    stop: Arc<AtomicBool>,
) -> Result<RunSummary, RunError> {
    run_following(prepared, None, cfg, stop)
}

/// Runs a prepared scene whose mesh `follow` makes again round the tools
/// as they move (`[contact] refine_radius_m`), until a stop condition or
/// `stop` is set.
pub fn run_following<B: Backend>(
    prepared: Prepared<B>,
    follow: Option<Box<dyn follow_live::LiveRemesh<B>>>,
    cfg: &RunConfig,
    stop: Arc<AtomicBool>,
) -> Result<RunSummary, RunError> {
    let mut l = run_loop::RunLoop::open(prepared, follow, cfg, stop)?;
    if cfg.rt_priority > 0 {
        // After the worker threads started (and, reset on fork, not
        // passed to any started later).
        match shared::rt::set_fifo(cfg.rt_priority) {
            Ok(p) => {
                l.summary_mut().rt_priority = p;
                l.summary_mut().rt_step_workers = l.raise_step_workers(p);
            }
            Err(e) => eprintln!("sim-server: {}", shared::rt::fifo_refused_hint(&e)),
        }
    }
    while !l.done() {
        let pose = l.intake()?;
        let step = l.step();
        if !l.check_finite() {
            break;
        }
        l.publish(pose, &step)?;
        if l.diverged() {
            break;
        }
        l.remesh()?;
        l.status(pose, &step);
        l.pace();
    }
    l.finish()
}
