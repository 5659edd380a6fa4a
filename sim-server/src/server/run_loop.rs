//! The `sim-server run` loop, one method per phase of a step ([`super::run`]
//! calls them in order): [`RunLoop::intake`] (the live pose and the
//! scripts into the tools, contact detected and imposed), [`RunLoop::step`]
//! (the step with the penalty contact inside it, cuts counted),
//! [`RunLoop::publish`] (the force sample, then the viewer's streams at
//! their rate), [`RunLoop::status`] (the once-a-second line) and
//! [`RunLoop::pace`] (real time: wait for the step's time or a fresh pose,
//! drop the time a stall missed).

use super::follow_live::LiveRemesh;
use super::local_out::LocalOut;
use super::loop_stats::LoopStats;
use super::outputs::{self, MeshOut};
use super::pacing::Pacing;
use super::poses::{PoseIntake, WaitEnd};
use super::scene_out::SceneOut;
use super::{Prepared, RunConfig, RunError, RunSummary, publish_err};
use shared::monotonic_ns;
use shared::protocol::{ForceMsg, MAX_TOOLS, PROTOCOL_VERSION, PoseMsg};
use shared::services::{self, ForcePublisher, IpcNode};
use sim_server::backend::Backend;
use sim_server::contact::Tools;
use sim_server::frames::FrameRecorder;
use sim_server::math::{Real, Vec3};
use sim_server::tensor_mass::MultirateReport;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// How often the wait between steps looks for a finished contact problem
/// while one is wanted (ns).
const LOCAL_POLL_NS: u64 = 500_000;

/// What one step's tools did, for publishing and the status line.
pub struct StepOutcome {
    flags: [u32; MAX_TOOLS],
    any_contact: bool,
}

/// The loop's state between phases.
pub struct RunLoop<'a, B: Backend> {
    cfg: &'a RunConfig,
    stop: Arc<AtomicBool>,
    sim: B,
    contacts: Tools,
    dt_s: Real,
    /// The node the ports below were made from (they hold their own
    /// reference to it; kept so that it lives as long as the loop).
    _node: IpcNode,
    poses: PoseIntake,
    force_pub: ForcePublisher,
    local_out: LocalOut,
    mesh_out: MeshOut,
    scene_out: SceneOut,
    summary: RunSummary,
    stats: LoopStats,
    /// Whether the pose this step started on woke the waiting loop.
    pose_on_arrival: bool,
    /// The last pose taken (its seq), to time only new ones.
    last_pose_seq: Option<u64>,
    /// When the loop woke for this step (ns).
    woke_ns: u64,
    /// The thread's CPU clock at the end of the last step's work (ns).
    last_cpu_ns: u64,
    /// Linear-solver iterations summed over the steps (implicit backend).
    solve_iterations: u64,
    start_ns: u64,
    pacing: Pacing,
    told: Told,
    frame_every: u64,
    last_step_ns: u64,
    removed_total: u64,
    /// Steps finished from a prediction, and their rows, on the meshes
    /// swapped out (each integrator counts its own).
    predicted_before: (u64, u64),
    diverged_at: Option<u64>,
    /// `[contact] refine_radius_m`: the mesh made again round the tools.
    follow: Option<Box<dyn LiveRemesh<B>>>,
}

/// What the loop has told its user on stderr, so that each message comes
/// once (a refused cut) or at most once a second (status, stalls).
struct Told {
    /// When the last status line went out (ns).
    last_status_ns: u64,
    /// Stalls counted when the last stall message went out, and when (ns).
    stalls: u64,
    last_stall_ns: u64,
    /// A refused cut was told.
    cut_refusal: bool,
    /// A swapped-in mesh's step worker that stayed in the background was told.
    background_workers: bool,
}

impl<'a, B: Backend> RunLoop<'a, B> {
    /// Joins the session (refused if another simulation runs in it),
    /// opens every stream, publishes the scene and starts the clock.
    pub fn open(
        prepared: Prepared<B>,
        follow: Option<Box<dyn LiveRemesh<B>>>,
        cfg: &'a RunConfig,
        stop: Arc<AtomicBool>,
    ) -> Result<Self, RunError> {
        if follow.is_some()
            && let Some(dir) = &cfg.save_frames
        {
            return Err(RunError::FramesOfOneMesh { dir: dir.clone() });
        }
        let Prepared {
            mut sim,
            tools: mut contacts,
            dt_s,
            original_vertex_ids,
        } = prepared;
        // The stiffness hand-over after the force sample, not before it,
        // and the step's rows the force does not need too.
        contacts.hand_over_after_sample(true);
        sim.defer_far_rows(true);
        if cfg.status {
            super::outputs::announce(&sim);
        }
        let node = services::node("sim-server")?;
        let poses = PoseIntake::new(&node, &cfg.session, cfg.pose_timeout_ns)?;
        let force_service = services::force_service(&node, &cfg.session)?;
        // What a crashed simulation left behind goes first, so that only a
        // live one makes this session busy.
        services::reap_dead_nodes(&node);
        if services::publisher_count(&force_service) > 0 {
            return Err(RunError::SessionBusy {
                session: cfg.session.as_str().to_string(),
            });
        }
        let force_pub = services::publisher(&force_service)?;
        let local_out = LocalOut::new(&node, &cfg.session, sim.capabilities().dynamic)?;
        let n = sim.model().vertex_count();
        let max_tris = 4 * sim.model().mesh().tet_count();
        let recorder = match &cfg.save_frames {
            Some(dir) => {
                let r = FrameRecorder::start(dir, sim.model(), original_vertex_ids)?;
                // A region that turns corotational: -K u is not the force there.
                Some(match contacts.corotational_region() {
                    Some(_) => r.without_forces(),
                    None => r,
                })
            }
            None => None,
        };
        let mesh_out = MeshOut::new(
            &sim,
            services::slice_publisher(&services::mesh_service(&node, &cfg.session)?, n)?,
            services::slice_publisher(&services::topology_service(&node, &cfg.session)?, max_tris)?,
            recorder,
        )?;
        let scene_out = SceneOut::publish(&node, &cfg.session, &contacts, &sim, &cfg.scene_name)?;
        let summary = RunSummary {
            finite: true,
            nonlinear_tets: sim.model().nonlinear_tets(),
            contact_law: match contacts.law() {
                sim_server::contact::ContactLaw::Penalty => "penalty",
                sim_server::contact::ContactLaw::Projection => "projection",
            },
            ..RunSummary::default()
        };
        if !cfg.headless {
            // Wake-ups at the requested time, not up to 50 us later.
            let _ = shared::rt::minimal_timer_slack();
        }
        let start_ns = monotonic_ns();
        Ok(Self {
            cfg,
            stop,
            frame_every: ((1.0 / cfg.viewer_rate_hz.max(1.0)) / dt_s).max(1.0) as u64,
            pacing: Pacing::new(start_ns, (dt_s * 1e9) as u64),
            sim,
            contacts,
            dt_s,
            _node: node,
            poses,
            force_pub,
            local_out,
            mesh_out,
            scene_out,
            summary,
            stats: LoopStats::default(),
            pose_on_arrival: false,
            last_pose_seq: None,
            woke_ns: 0,
            last_cpu_ns: shared::thread_cpu_ns(),
            solve_iterations: 0,
            start_ns,
            told: Told {
                last_status_ns: start_ns,
                stalls: 0,
                last_stall_ns: 0,
                cut_refusal: false,
                background_workers: false,
            },
            last_step_ns: start_ns,
            removed_total: 0,
            predicted_before: (0, 0),
            diverged_at: None,
            follow,
        })
    }

    /// Whether a stop condition holds (signal, step count, duration).
    pub fn done(&self) -> bool {
        let cfg = self.cfg;
        self.stop.load(Ordering::Relaxed)
            || cfg.max_steps.is_some_and(|m| self.summary.steps >= m)
            || cfg
                .duration_s
                .is_some_and(|d| (monotonic_ns() - self.start_ns) as Real * 1e-9 >= d)
    }

    /// The newest live pose (fresh, its publisher alive) and the scripts
    /// into the tools: contact detected and imposed before the step.
    pub fn intake(&mut self) -> Result<Option<PoseMsg>, RunError> {
        self.woke_ns = monotonic_ns();
        self.poses.drain()?;
        let t0 = monotonic_ns();
        let pose = self.poses.active(t0);
        if let Some(p) = pose
            && self.last_pose_seq != Some(p.seq)
        {
            self.last_pose_seq = Some(p.seq);
            self.pacing
                .observe_pose(p.seq, p.t_ns, self.woke_ns, self.pose_on_arrival);
            // Told once: a step that starts on the clock next has none.
            self.pose_on_arrival = false;
            self.stats
                .pose_wait
                .record_elapsed_ns(self.woke_ns.saturating_sub(p.t_ns));
        }
        let sim_t_s = self.summary.steps as Real * self.dt_s;
        let inputs = outputs::tool_inputs(self.contacts.len(), &self.cfg.scripts, pose, sim_t_s);
        self.contacts.update(&mut self.sim, &inputs);
        self.summary.contact_s += (monotonic_ns() - t0) as Real * 1e-9;
        Ok(pose)
    }

    /// The step (the penalty contact is evaluated inside it: its cost
    /// counts as the step's), timed; cuts counted, a refused cut told once.
    pub fn step(&mut self) -> StepOutcome {
        let t0 = monotonic_ns();
        let c0 = shared::thread_cpu_ns();
        let reports = self.contacts.step(&mut self.sim);
        if let Some(r) = self.sim.large_strain() {
            self.summary.max_barrier_elements = self.summary.max_barrier_elements.max(r.collapsed);
        }
        if let Some(s) = self.sim.linear_solve() {
            self.solve_iterations += s.iterations as u64;
            let max = &mut self.summary.solve_iterations_max;
            *max = (*max).max(s.iterations);
            self.summary.solve_capped_steps += u64::from(s.capped);
        }
        let t1 = monotonic_ns();
        self.summary.step_s += (t1 - t0) as Real * 1e-9;
        self.stats.step.record_elapsed_ns(t1 - t0);
        self.stats
            .step_cpu
            .record_elapsed_ns(shared::thread_cpu_ns().saturating_sub(c0));
        if std::mem::take(&mut self.stats.swapped) {
            self.stats.first_after_swap.record_elapsed_ns(t1 - t0);
        }
        let outcome = StepOutcome {
            flags: sim_server::wire::tool_flags(reports),
            any_contact: reports.iter().any(|r| r.contact),
        };
        for (i, report) in reports.iter().enumerate() {
            if let Some(why) = report.cut_refused
                && !self.told.cut_refusal
            {
                self.told.cut_refusal = true;
                eprintln!(
                    "sim-server: tool {i} tried to cut, but the {} backend refused: {why}",
                    self.sim.capabilities().name
                );
            }
            if report.held_outside {
                if self.summary.held_outside_steps == 0 {
                    let advice = if self.sim.model().nonlinear_tets() > 0 {
                        "a finer mesh under the tool holds deeper"
                    } else {
                        "the linear model is far beyond its range: model = \"corotational\" in [material] holds deeper"
                    };
                    eprintln!(
                        "sim-server: the tissue slipped past tool {i}'s tip (or the tip would have entered it): the tool is held outside, at the surface; {advice} (docs/design/contact.md, the tip held outside the tissue)"
                    );
                }
                self.summary.held_outside_steps += 1;
            }
            self.summary.catching_up_steps += u64::from(report.catching_up);
            if report.tets_removed > 0 {
                self.removed_total += report.tets_removed as u64;
                self.mesh_out.topology_version += 1;
            }
        }
        self.summary.steps += 1;
        if outcome.any_contact {
            self.summary.contact_steps += 1;
        }
        outcome
    }

    /// Every 64 steps: whether the displacements are still finite. When not,
    /// a zero force sample goes out (the daemon lets go) and the loop ends
    /// with [`RunError::Diverged`].
    pub fn check_finite(&mut self) -> bool {
        let s = &mut self.summary;
        if !s.steps.is_multiple_of(64)
            || self
                .sim
                .displacements()
                .iter()
                .flatten()
                .all(|x| x.is_finite())
        {
            return true;
        }
        self.diverge();
        false
    }

    /// The run ends as diverged: `finite` false, a zero force sample out
    /// (the daemon lets go), [`RunError::Diverged`] at the end.
    fn diverge(&mut self) {
        let s = &mut self.summary;
        s.finite = false;
        let _ = self.force_pub.send_copy(ForceMsg {
            version: PROTOCOL_VERSION,
            seq: s.samples_published,
            t_ns: monotonic_ns(),
            ..ForceMsg::default()
        });
        self.diverged_at = Some(s.steps);
    }

    /// With `[contact] refine_radius_m`, after the sample is out: a mesh
    /// refined round where the tools are now swapped in when the worker
    /// has finished one (the viewer's streams then carry the new mesh: its
    /// rest state and original surface again, a new topology version), or
    /// one asked for when the tools have moved.
    pub fn remesh(&mut self) -> Result<(), RunError> {
        let Some(f) = &mut self.follow else {
            return Ok(());
        };
        let t0 = monotonic_ns();
        let predicted = self.sim.predicted();
        let partition = self.sim.multirate();
        if f.after_step(&mut self.sim, &mut self.contacts, self.dt_s) {
            // What the mesh swapped out counted goes on with the run's.
            if let Some((steps, rows)) = predicted {
                self.predicted_before.0 += steps;
                self.predicted_before.1 += rows;
            }
            note_partition(&mut self.summary, partition);
            self.step_workers_at_loop_priority();
            self.sim.defer_far_rows(true);
            // The new mesh's next step predicted now, as `publish` did for
            // the old one's: otherwise the first step on every mesh swapped
            // in ran whole after its pose (300-600 us on the refined
            // liver, a tail of its own in `step_us`). Counted in `step_s`
            // like every prediction, not in `remesh_s`.
            let t1 = monotonic_ns();
            self.sim.prepare_step();
            let predicted_ns = monotonic_ns() - t1;
            self.summary.step_s += predicted_ns as Real * 1e-9;
            self.summary.remesh_s -= predicted_ns as Real * 1e-9;
            self.mesh_out.rebind(&self.sim);
            self.scene_out
                .send(&self.contacts, &self.sim, &self.cfg.scene_name)?;
            self.summary.remesh_swaps += 1;
            self.stats.swapped = true;
        }
        self.summary.remesh_s += (monotonic_ns() - t0) as Real * 1e-9;
        Ok(())
    }

    /// Whether the run diverged (its displacements or a tool's force).
    pub fn diverged(&self) -> bool {
        self.diverged_at.is_some()
    }

    /// The force sample (every step), a look for dead pose publishers once
    /// it is out, and the viewer's streams at their rate.
    pub fn publish(&mut self, pose: Option<PoseMsg>, step: &StepOutcome) -> Result<(), RunError> {
        let now = monotonic_ns();
        let s = &mut self.summary;
        let header = ForceMsg {
            version: PROTOCOL_VERSION,
            seq: s.samples_published,
            t_ns: now,
            sim_time_ns: (s.steps as Real * self.dt_s * 1e9) as u64,
            step_period_ns: now - self.last_step_ns,
            ..ForceMsg::default()
        };
        self.last_step_ns = now;
        let t0 = monotonic_ns();
        let pose_seq = pose.map_or(0, |p| p.seq);
        let msg = sim_server::wire::force_sample(
            header,
            &self.contacts,
            &self.sim,
            pose_seq,
            &step.flags,
        );
        // A force no hand can take is never published: non-finite, or so
        // large that its length overflows (a 1e300 stiffness factor sent
        // 5.9e294 N once, and the summary said "max force inf N" beside
        // `finite: true`). The run ends as diverged instead.
        let tools = &msg.tools[..self.contacts.len()];
        let sane = tools.iter().all(|t| {
            Vec3::from_array(t.force_n).length().is_finite()
                && t.stiffness_n_per_m.iter().flatten().all(|k| k.is_finite())
        });
        if !sane {
            self.diverge();
            return Ok(());
        }
        for t in tools {
            s.max_force_n = s.max_force_n.max(Vec3::from_array(t.force_n).length());
        }
        s.contact_s += (monotonic_ns() - t0) as Real * 1e-9;
        self.force_pub
            .send_copy(msg)
            .map_err(|e| publish_err("force sample")(format!("{e:?}")))?;
        s.samples_published += 1;
        self.stats
            .turnaround
            .record_elapsed_ns(monotonic_ns().saturating_sub(self.woke_ns));
        // The rest of the step, which the force did not need (its rows far
        // from the tools), before anything else reads the state. Counted in
        // `step_s` with the step, not in `step_us` (its own `step_rest_us`).
        let t0 = monotonic_ns();
        self.sim.finish_step();
        let t1 = monotonic_ns();
        s.step_s += (t1 - t0) as Real * 1e-9;
        self.stats.rest.record_elapsed_ns(t1 - t0);
        // The contact stiffness's hand-over, left by the step until the
        // sample was out (`Tools::hand_over_after_sample`); its time counts
        // in `step_s` (contact_fraction compares as before), not in
        // `step_us` (its own `hand_over_us`).
        let t0 = monotonic_ns();
        self.contacts.hand_over(&self.sim);
        let t1 = monotonic_ns();
        s.step_s += (t1 - t0) as Real * 1e-9;
        self.stats.hand_over.record_elapsed_ns(t1 - t0);
        // After the force sample: the problem reaches the daemon later
        // than the force it explains, never before.
        self.local_out.after_sample(
            &mut self.contacts,
            s.samples_published - 1,
            now,
            pose.map_or(now, |p| p.t_ns),
        );
        self.poses.check_publishers();
        // Viewer: topology when it changed, positions at the viewer rate.
        if s.steps.is_multiple_of(self.frame_every) {
            self.mesh_out
                .publish(&self.sim, now, s.steps as Real * self.dt_s)?;
            self.scene_out.refresh();
            s.frames_published = self.mesh_out.frames;
        }
        // What the next step can do before its pose: the wait below would
        // otherwise idle through it. Its time counts as the step's in
        // `step_s` (so `contact_fraction` compares the tools with all of
        // the elastic work), not in `step_us` (the step after its pose).
        let t0 = monotonic_ns();
        self.sim.prepare_step();
        s.step_s += (monotonic_ns() - t0) as Real * 1e-9;
        // Read here, off the pose's path (the clock is a system call, about
        // 0.6 us on this VM): from the last step's end to this one's, the
        // blocking wait between them costing only its few microseconds of
        // wake-up.
        let cpu_ns = shared::thread_cpu_ns();
        self.stats
            .work_cpu
            .record_elapsed_ns(cpu_ns.saturating_sub(self.last_cpu_ns));
        self.last_cpu_ns = cpu_ns;
        self.stats
            .work
            .record_elapsed_ns(monotonic_ns().saturating_sub(self.woke_ns));
        Ok(())
    }

    /// The once-a-second status line (with `cfg.status`).
    pub fn status(&mut self, pose: Option<PoseMsg>, step: &StepOutcome) {
        let now = monotonic_ns();
        if !self.cfg.status || now - self.told.last_status_ns < 1_000_000_000 {
            return;
        }
        let s = &self.summary;
        let secs = (now - self.start_ns) as Real * 1e-9;
        let stalls = if self.pacing.stalls() > 0 {
            format!(
                " | dropped {:.3} s in {} stalls",
                self.pacing.dropped_ns() as Real * 1e-9,
                self.pacing.stalls()
            )
        } else {
            String::new()
        };
        eprintln!(
            "{:8.0} steps/s | sim time {:.2} s | poses {}{} | contact {} | removed {} tets | max force {:.3} N | step p50 {:.0} us p99.9 {:.0} us{stalls}",
            s.steps as Real / secs,
            s.steps as Real * self.dt_s,
            self.poses.received,
            if pose.is_some() { "" } else { " (none live)" },
            if step.any_contact { "yes" } else { "no" },
            self.removed_total,
            s.max_force_n,
            self.stats.step.quantile_us(0.5),
            self.stats.step.quantile_us(0.999),
        );
        self.told.last_status_ns = now;
    }

    /// Real time: the next step starts when it is due, or on a fresh pose
    /// up to two steps (at most 2 ms) earlier, the grid's phase following
    /// the poses' ([`Pacing::started_on_pose`]); after a stall the missed
    /// time is dropped (the grid re-anchored to now), never run fast.
    /// Headless: no wait.
    pub fn pace(&mut self) {
        if self.cfg.headless {
            return;
        }
        let steps = self.summary.steps;
        let now = monotonic_ns();
        if let Some(dropped) = self.pacing.catch_up(steps, now)
            && self.cfg.status
            && now.saturating_sub(self.told.last_stall_ns) >= 1_000_000_000
        {
            // A backend stable at any step has a remedy to name for steps
            // that take longer than they simulate.
            let hint = if self.sim.capabilities().stable_at_any_step {
                "; this backend is stable at any step: a longer --dt-s (e.g. 0.004) lets it keep real time"
            } else {
                ""
            };
            eprintln!(
                "sim-server: {:.1} ms behind real time (a stall): the missed time is dropped, not run fast ({} stall(s) since the last message, {:.3} s dropped in all: simulated time now runs that far behind wall time){hint}",
                dropped as Real * 1e-6,
                self.pacing.stalls() - self.told.stalls,
                self.pacing.dropped_ns() as Real * 1e-9
            );
            self.told.stalls = self.pacing.stalls();
            self.told.last_stall_ns = now;
        }
        let (earliest, due) = (self.pacing.earliest(steps), self.pacing.due(steps));
        loop {
            // While a daemon takes contact problems: a look every
            // LOCAL_POLL_NS for one the stiffness worker finished, so that
            // it goes out at once rather than after the next step (a
            // whole sample late at 30 Hz).
            let until = if self.local_out.wanted() {
                due.min(monotonic_ns() + LOCAL_POLL_NS)
            } else {
                due
            };
            match self.poses.wait(earliest, until, &self.stop) {
                WaitEnd::Pose { on_arrival } => {
                    self.summary.steps_on_pose += 1;
                    self.pose_on_arrival = on_arrival;
                    self.pacing.started_on_pose(steps, monotonic_ns());
                    break;
                }
                WaitEnd::Due if until < due => self.local_out.publish_ready(&mut self.contacts),
                WaitEnd::Due | WaitEnd::Stop => {
                    self.pose_on_arrival = false;
                    break;
                }
            }
        }
    }

    /// Puts the step's worker threads (see [`Backend::on_step_workers`])
    /// under SCHED_FIFO at `priority`, as the stepping thread is; returns
    /// how many took it (a refusal is reported once).
    pub fn raise_step_workers(&self, priority: i32) -> usize {
        let raised = std::sync::atomic::AtomicUsize::new(0);
        let refused = std::sync::Mutex::new(None);
        self.sim
            .on_step_workers(&|| match shared::rt::set_fifo(priority) {
                Ok(_) => {
                    raised.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => {
                    if let Ok(mut r) = refused.lock() {
                        r.get_or_insert(e);
                    }
                }
            });
        if let Ok(Some(e)) = refused.into_inner() {
            eprintln!(
                "sim-server: a step worker thread stays at normal priority: {}",
                shared::rt::fifo_refused_hint(&e)
            );
        }
        raised.into_inner()
    }

    /// A mesh swapped in steps on its own worker pool, started by the
    /// follower's background thread and so under SCHED_IDLE, where a
    /// worker runs only on a core nothing else wants and the step waits
    /// for it: its workers are put where the stepping thread is,
    /// SCHED_FIFO at the run's priority as the first mesh's were at start,
    /// or normal.
    fn step_workers_at_loop_priority(&mut self) {
        let p = self.summary.rt_priority;
        if p > 0 {
            self.summary.rt_step_workers = self.raise_step_workers(p);
            return;
        }
        let refused = std::sync::Mutex::new(None);
        self.sim.on_step_workers(&|| {
            if let Err(e) = shared::rt::normal()
                && let Ok(mut r) = refused.lock()
            {
                r.get_or_insert(e);
            }
        });
        if let Ok(Some(e)) = refused.into_inner()
            && !self.told.background_workers
        {
            self.told.background_workers = true;
            eprintln!("sim-server: a step worker of a refined mesh stays under SCHED_IDLE: {e}");
        }
    }

    /// The summary so far, for what the loop's caller records in it.
    pub fn summary_mut(&mut self) -> &mut RunSummary {
        &mut self.summary
    }

    /// The run's summary (and the frame recorder stopped), or
    /// [`RunError::Diverged`] with it.
    pub fn finish(self) -> Result<RunSummary, RunError> {
        let mut summary = self.summary;
        let secs = ((monotonic_ns() - self.start_ns) as Real * 1e-9).max(1e-9);
        summary.steps_per_s = summary.steps as Real / secs;
        summary.sim_time_s = summary.steps as Real * self.dt_s;
        if let Some((steps, rows)) = self.sim.predicted() {
            summary.predicted_steps = self.predicted_before.0 + steps;
            summary.predicted_rows = self.predicted_before.1 + rows;
        }
        summary.tets_removed = self.removed_total;
        summary.contact_fraction =
            summary.contact_s / (summary.contact_s + summary.step_s).max(1e-12);
        summary.poses_received = self.poses.received;
        summary.pose_timeouts = self.poses.timeouts;
        self.stats.write_into(&mut summary);
        summary.solve_iterations_mean =
            self.solve_iterations as Real / (summary.steps.max(1)) as Real;
        summary.dropped_time_s = self.pacing.dropped_ns() as Real * 1e-9;
        summary.stalls = self.pacing.stalls();
        note_partition(&mut summary, self.sim.multirate());
        if let Some(r) = self.contacts.corotational_region_stats() {
            summary.corotational_region_largest_tets = r.largest_tets;
            summary.corotational_region_rebuilds = r.rebuilds;
        }
        if let Some(f) = &self.follow {
            let r = f.report();
            summary.remesh_most_tets = r.most_tets;
            summary.remesh_tets = r.tets;
            summary.remesh_build_wall_s = r.rebuild_wall_s;
            summary.remesh_longest_build_wall_s = r.longest_rebuild_wall_s;
            summary.remesh_pinned = r.pinned;
            summary.remesh_stopped_at_budget = r.stopped_at_budget;
        }
        summary.local_problems = self.local_out.published;
        summary.local_problems_dropped = self.local_out.dropped;
        if let Some((counts, error)) = self.mesh_out.finish() {
            summary.frames_saved = counts.saved;
            summary.frames_dropped = counts.dropped;
            if let Some(e) = error {
                // The run's own results stand; the series stops where it failed.
                eprintln!("sim-server: {e} (the frames before it are kept)");
            }
        }
        match self.diverged_at {
            Some(step) => Err(RunError::Diverged {
                step,
                summary: Box::new(summary),
            }),
            None => Ok(summary),
        }
    }
}

/// Keeps the largest engaged multirate partition of the run in `summary`
/// (each mesh the tools are followed with has its own).
fn note_partition(summary: &mut RunSummary, partition: Option<MultirateReport>) {
    if let Some(m) = partition.filter(|m| m.engaged)
        && m.fast_vertices >= summary.multirate_fast_vertices
    {
        summary.multirate_fast_vertices = m.fast_vertices;
        summary.multirate_coarse_substeps = m.coarse_substeps;
        summary.multirate_fine_substeps = m.fine_substeps;
    }
}
