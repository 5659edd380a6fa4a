//! The sim-server process loop (`sim-server run`): reads tool poses from the
//! haptic daemon, applies the tool contact models, steps the tensor-mass
//! simulation in real time (or as fast as it can, headless), publishes a
//! force sample per step and the mesh state at the viewer rate, with the
//! topology when cuts change it. It keeps running when the daemon or the
//! viewer disappear and serves them again when they come back.
//!
//! Real time ([`pacing`]): a step starts when it is due, or up to one step
//! (at most 2 ms) earlier when a fresh pose arrives ([`poses`]: the daemon
//! notifies the `pose-ready` event after each pose, which wakes the wait),
//! so a pose gets its force one step after it arrives. After a stall the
//! missed time is dropped, not fast-forwarded. A pose older than
//! [`RunConfig::pose_timeout_ns`], or whose publisher died, drives no tool.

pub mod frames;
pub mod outputs;
pub mod pacing;
pub mod poses;
pub mod scene_out;
pub mod step_time;

use crate::backend::Backend;
use crate::contact::Tools;
use crate::math::{Real, Vec3};
use crate::scene::BuiltScene;
use crate::tensor_mass::{Explicit, ExplicitConfig, Storage};
use outputs::MeshOut;
use pacing::Pacing;
use poses::{PoseIntake, WaitEnd};
use scene_out::SceneOut;
use serde::Serialize;
use shared::protocol::{ForceMsg, MAX_TOOLS, PROTOCOL_VERSION};
use shared::services::{self, ServiceError};
use shared::{SessionName, monotonic_ns};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use step_time::{StepHistogram, StepPercentiles};
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
}

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
    /// Live tetrahedra with a nonlinear (StVK, corotational) model at the start.
    pub nonlinear_tets: usize,
    /// Most StVK elements compressed below half their volume (in the
    /// volume barrier) at the end of any step: tissue squeezed beyond
    /// what the model is meant for.
    pub max_barrier_elements: usize,
    /// With `--save-frames`: frames written to the VTU series.
    pub frames_saved: u64,
    /// With `--save-frames`: frames not written because the disk was
    /// behind (the step is never delayed for them).
    pub frames_dropped: u64,
}

/// Why a run failed.
#[derive(Debug, Error)]
pub enum RunError {
    /// Shared memory.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// The integrator refused the scene's step.
    #[error(transparent)]
    Explicit(#[from] crate::tensor_mass::ExplicitError),
    /// The implicit backend refused the scene.
    #[error(transparent)]
    Implicit(#[from] crate::backend::ImplicitError),
    /// `--save-frames` could not start or write.
    #[error(transparent)]
    Frames(#[from] frames::FramesError),
    /// A peer sent another protocol version.
    #[error(transparent)]
    Version(#[from] shared::protocol::VersionError),
    /// The simulation diverged (non-finite displacements); forces were zeroed.
    #[error(
        "the simulation diverged at step {step} (non-finite displacements): the step is too large for this scene or a tool pushed too hard; forces were set to zero"
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

/// Why a scene could not be set up on a backend.
#[derive(Debug, Error)]
pub enum PrepareError<E: std::error::Error + 'static> {
    /// The backend refused the model or the step.
    #[error(transparent)]
    Backend(E),
    /// The contact cannot run as the scene asks.
    #[error(transparent)]
    Contact(#[from] crate::contact::ContactError),
}

/// A scene ready to step: the integrator with the scene's fixed vertices,
/// prescribed displacements and loads applied, and its tools.
pub struct Prepared<B: Backend> {
    /// The backend.
    pub sim: B,
    /// The scene's tools (at most `MAX_TOOLS`), scene-held vertices reserved.
    pub tools: Tools,
    /// The step (s).
    pub dt_s: Real,
    /// Each vertex's index before the scene renumbered them, if it did.
    pub original_vertex_ids: Option<Vec<u32>>,
}

/// Sets `scene` up for stepping with the explicit tensor-mass integrator at
/// `dt_s` (default: the scene's, else 90% of the stable step; a larger one
/// is sub-stepped or refused as the scene says).
pub fn prepare<S: Storage>(
    scene: BuiltScene,
    dt_s: Option<Real>,
) -> Result<Prepared<Explicit<S>>, PrepareError<crate::tensor_mass::ExplicitError>> {
    prepare_with(scene, dt_s, |model, settings, dt_s| {
        Explicit::<S>::new(
            model,
            ExplicitConfig {
                dt_s,
                policy: settings.policy,
                bound: settings.bound,
                threads: settings.threads,
            },
        )
    })
}

/// Sets `scene` up on the backend `make` builds from the model, the
/// scene's settings and the step (`dt_s`, else the scene's, else 90% of the
/// explicit stable step).
pub fn prepare_with<B: Backend, E: std::error::Error + 'static>(
    scene: BuiltScene,
    dt_s: Option<Real>,
    make: impl FnOnce(
        crate::tensor_mass::ElasticModel,
        &crate::scene::SimSettings,
        Real,
    ) -> Result<B, E>,
) -> Result<Prepared<B>, PrepareError<E>> {
    let BuiltScene {
        model,
        fixed,
        prescribed,
        loads_n,
        tools,
        settings,
        contact,
        original_vertex_ids,
        ..
    } = scene;
    // The bound only when no step is given: backends that need it compute
    // their own, and it costs an eigenproblem per tetrahedron.
    let dt_s = dt_s
        .or(settings.dt_s)
        .unwrap_or_else(|| 0.9 * crate::tensor_mass::element_bound(&model).dt_max_s);
    let mut sim = make(model, &settings, dt_s).map_err(PrepareError::Backend)?;
    for v in &fixed {
        sim.fix(*v);
    }
    for (v, d) in &prescribed {
        sim.prescribe(*v, *d);
    }
    for (v, f) in loads_n.iter().enumerate() {
        if *f != Vec3::ZERO {
            sim.set_external_force(crate::ids::VertexId::from(v), *f);
        }
    }
    let decls = &tools[..tools.len().min(MAX_TOOLS)];
    // A tool never takes over (or releases) a vertex the scene holds.
    let held: Vec<_> = fixed
        .iter()
        .copied()
        .chain(prescribed.iter().map(|(v, _)| *v))
        .collect();
    let contacts = Tools::with_config(decls, &mut sim, &contact, &held)?;
    Ok(Prepared {
        sim,
        tools: contacts,
        dt_s,
        original_vertex_ids,
    })
}

/// Runs a prepared scene until a stop condition or `stop` is set.
pub fn run<B: Backend>(
    prepared: Prepared<B>,
    cfg: &RunConfig,
    stop: Arc<AtomicBool>,
) -> Result<RunSummary, RunError> {
    let Prepared {
        mut sim,
        tools: mut contacts,
        dt_s,
        original_vertex_ids,
    } = prepared;
    if cfg.status {
        let (cut, live) = crate::backend::cuttable(&sim);
        eprintln!(
            "sim-server: {} backend, {}, cuts {}",
            sim.name(),
            if sim.dynamic() {
                "dynamic"
            } else {
                "quasi-static"
            },
            match cut {
                0 => "nowhere".to_string(),
                c if c == live => "anywhere".to_string(),
                c => format!("in {c} of {live} tetrahedra"),
            }
        );
    }
    let node = services::node("sim-server")?;
    let mut poses = PoseIntake::new(&node, &cfg.session, cfg.pose_timeout_ns)?;
    let force_service = services::force_service(&node, &cfg.session)?;
    // What a crashed simulation left behind goes first, so that only a live
    // one makes this session busy.
    services::reap_dead_nodes(&node);
    if services::publisher_count(&force_service) > 0 {
        return Err(RunError::SessionBusy {
            session: cfg.session.as_str().to_string(),
        });
    }
    let force_pub = services::publisher(&force_service)?;
    let n = sim.model().vertex_count();
    let max_tris = 4 * sim.model().mesh().tet_count();
    let recorder = match &cfg.save_frames {
        Some(dir) => Some(frames::FrameRecorder::start(
            dir,
            sim.model(),
            original_vertex_ids,
        )?),
        None => None,
    };
    let mut mesh_out = MeshOut::new(
        &sim,
        services::slice_publisher(&services::mesh_service(&node, &cfg.session)?, n)?,
        services::slice_publisher(&services::topology_service(&node, &cfg.session)?, max_tris)?,
        recorder,
    )?;
    let scene_out = SceneOut::publish(&node, &cfg.session, &contacts, &sim, &cfg.scene_name)?;

    let mut summary = RunSummary {
        finite: true,
        nonlinear_tets: sim.model().nonlinear_tets(),
        ..RunSummary::default()
    };
    if !cfg.headless {
        // Wake-ups at the requested time, not up to 50 us later.
        // SAFETY: prctl(2) on this thread's timer slack; no pointers.
        unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1u64) };
    }
    let mut step_times = StepHistogram::new();
    let start_ns = monotonic_ns();
    let step_ns = (dt_s * 1e9) as u64;
    let mut pacing = Pacing::new(start_ns, step_ns);
    let mut stalls_told = 0u64;
    let mut last_stall_told = 0u64;
    let frame_every = ((1.0 / cfg.viewer_rate_hz.max(1.0)) / dt_s).max(1.0) as u64;
    let mut last_status = start_ns;
    let mut last_step_ns = start_ns;
    let mut removed_total = 0u64;
    let mut diverged_at = None;
    let mut cut_refusal_told = false;
    loop {
        if stop.load(Ordering::Relaxed)
            || cfg.max_steps.is_some_and(|m| summary.steps >= m)
            || cfg
                .duration_s
                .is_some_and(|d| (monotonic_ns() - start_ns) as Real * 1e-9 >= d)
        {
            break;
        }
        // Poses: newest wins, if fresh and its publisher alive.
        poses.drain()?;
        let contact_t0 = monotonic_ns();
        let latest_pose = poses.active(contact_t0);
        // Contact: detect and impose before the step.
        let sim_t_s = summary.steps as Real * dt_s;
        let inputs = outputs::tool_inputs(contacts.len(), &cfg.scripts, latest_pose, sim_t_s);
        contacts.update(&mut sim, &inputs);
        let step_t0 = monotonic_ns();
        summary.contact_s += (step_t0 - contact_t0) as Real * 1e-9;
        // The penalty contact is evaluated inside the step: its cost counts
        // as the step's.
        let reports = contacts.step(&mut sim);
        if let Some(r) = sim.large_strain() {
            summary.max_barrier_elements = summary.max_barrier_elements.max(r.collapsed);
        }
        let step_t1 = monotonic_ns();
        summary.step_s += (step_t1 - step_t0) as Real * 1e-9;
        step_times.record(step_t1 - step_t0);
        let flags = outputs::tool_flags(reports);
        let any_contact = reports.iter().any(|r| r.contact);
        for (i, report) in reports.iter().enumerate() {
            if let Some(why) = report.cut_refused
                && !cut_refusal_told
            {
                cut_refusal_told = true;
                eprintln!(
                    "sim-server: tool {i} tried to cut, but the {} backend refused: {why}",
                    sim.name()
                );
            }
            if report.tets_removed > 0 {
                removed_total += report.tets_removed as u64;
                mesh_out.topology_version += 1;
            }
        }
        summary.steps += 1;
        if any_contact {
            summary.contact_steps += 1;
        }
        if summary.steps.is_multiple_of(64)
            && !sim.displacements().iter().flatten().all(|x| x.is_finite())
        {
            summary.finite = false;
            let _ = force_pub.send_copy(ForceMsg {
                version: PROTOCOL_VERSION,
                seq: summary.samples_published,
                t_ns: monotonic_ns(),
                ..ForceMsg::default()
            });
            diverged_at = Some(summary.steps);
            break;
        }
        // Force sample: every step.
        let now = monotonic_ns();
        let header = ForceMsg {
            version: PROTOCOL_VERSION,
            seq: summary.samples_published,
            t_ns: now,
            sim_time_ns: (summary.steps as Real * dt_s * 1e9) as u64,
            step_period_ns: now - last_step_ns,
            ..ForceMsg::default()
        };
        last_step_ns = now;
        let reaction_t0 = monotonic_ns();
        let pose_seq = latest_pose.map_or(0, |p| p.seq);
        let msg = outputs::force_sample(header, &contacts, &sim, pose_seq, &flags);
        for t in &msg.tools[..contacts.len()] {
            summary.max_force_n = summary
                .max_force_n
                .max(Vec3::from_array(t.force_n).length());
        }
        summary.contact_s += (monotonic_ns() - reaction_t0) as Real * 1e-9;
        force_pub
            .send_copy(msg)
            .map_err(|e| publish_err("force sample")(format!("{e:?}")))?;
        summary.samples_published += 1;
        // The sample is out: now there is time to look for dead publishers.
        poses.check_publishers(&node, monotonic_ns());
        // Viewer: topology when it changed, positions at the viewer rate.
        if summary.steps.is_multiple_of(frame_every) {
            mesh_out.publish(&sim, now, summary.steps as Real * dt_s)?;
            scene_out.refresh();
            summary.frames_published = mesh_out.frames;
        }
        if cfg.status && now - last_status >= 1_000_000_000 {
            let secs = (now - start_ns) as Real * 1e-9;
            let stalls = if pacing.stalls() > 0 {
                format!(
                    " | dropped {:.3} s in {} stalls",
                    pacing.dropped_ns() as Real * 1e-9,
                    pacing.stalls()
                )
            } else {
                String::new()
            };
            eprintln!(
                "{:8.0} steps/s | sim time {:.2} s | poses {}{} | contact {} | removed {} tets | max force {:.3} N | step p50 {:.0} us p99.9 {:.0} us{stalls}",
                summary.steps as Real / secs,
                summary.steps as Real * dt_s,
                poses.received,
                if latest_pose.is_some() {
                    ""
                } else {
                    " (none live)"
                },
                if any_contact { "yes" } else { "no" },
                removed_total,
                summary.max_force_n,
                step_times.quantile_ns(0.5) * 1e-3,
                step_times.quantile_ns(0.999) * 1e-3,
            );
            last_status = now;
        }
        // Real time: the next step starts when it is due, or on a fresh
        // pose up to one step earlier; after a stall the missed time is
        // dropped (the grid re-anchored to now), never run fast.
        if !cfg.headless {
            let now = monotonic_ns();
            if let Some(dropped) = pacing.catch_up(summary.steps, now)
                && cfg.status
                && now.saturating_sub(last_stall_told) >= 1_000_000_000
            {
                eprintln!(
                    "sim-server: {:.1} ms behind real time (a stall): the missed time is dropped, not run fast ({} stall(s) since the last message, {:.3} s dropped in all: simulated time now runs that far behind wall time)",
                    dropped as Real * 1e-6,
                    pacing.stalls() - stalls_told,
                    pacing.dropped_ns() as Real * 1e-9
                );
                stalls_told = pacing.stalls();
                last_stall_told = now;
            }
            match poses.wait(
                pacing.earliest(summary.steps),
                pacing.due(summary.steps),
                &stop,
            ) {
                WaitEnd::Pose => summary.steps_on_pose += 1,
                WaitEnd::Due | WaitEnd::Stop => {}
            }
        }
    }
    let secs = ((monotonic_ns() - start_ns) as Real * 1e-9).max(1e-9);
    summary.steps_per_s = summary.steps as Real / secs;
    summary.sim_time_s = summary.steps as Real * dt_s;
    summary.tets_removed = removed_total;
    summary.contact_fraction = summary.contact_s / (summary.contact_s + summary.step_s).max(1e-12);
    summary.poses_received = poses.received;
    summary.pose_timeouts = poses.timeouts;
    summary.step_us = step_times.percentiles_us();
    summary.dropped_time_s = pacing.dropped_ns() as Real * 1e-9;
    summary.stalls = pacing.stalls();
    if let Some((counts, error)) = mesh_out.finish() {
        summary.frames_saved = counts.saved;
        summary.frames_dropped = counts.dropped;
        if let Some(e) = error {
            // The run's own results stand; the series stops where it failed.
            eprintln!("sim-server: {e} (the frames before it are kept)");
        }
    }
    match diverged_at {
        Some(step) => Err(RunError::Diverged {
            step,
            summary: Box::new(summary),
        }),
        None => Ok(summary),
    }
}
