//! The real-time loop: read device -> plausibility -> publish pose -> drain
//! force samples (live ones only) -> extrapolate -> safety (with passivity)
//! -> write device -> telemetry. Everything it needs is
//! allocated in [`RtLoop::new`]; [`RtLoop::tick`] allocates nothing, takes
//! no lock, and makes no system call other than what the device needs and
//! one non-blocking futex wake of the I/O thread when it sleeps
//! ([`Shared::wake_io`]: `Thread::unpark`), so that the pose is published
//! at once (iceoryx2's `receive` is allocation-free; publishing happens on
//! the I/O thread, because iceoryx2 0.10's `loan` allocates).
//!
//! The daemon's own checks ([`ChainConfig`]):
//!
//! - [`crate::plausible`]: a device sample no hand could produce (or a NaN)
//!   is rejected and the last good pose held for the simulation, the
//!   extrapolator and the safety filter; after a run longer than its bound
//!   the new pose becomes the reference and the force ramps in from what it
//!   was ([`Safety::ramp_in_from_output`]). A failed read or a reading
//!   with any non-finite field is a bad read, rejected the same way (the
//!   last good pose held, the force kept); a run of bad reads as long as
//!   that bound stops the force (as a non-finite request).
//! - [`crate::live`]: a force sample whose simulated time runs faster than
//!   wall time (a simulation fast-forwarding after a stall) is not rendered;
//!   the extrapolator keeps the last live sample (so the safety filter's age
//!   watchdog ramps the force down if that lasts) and the force ramps in
//!   again from what it was when live samples resume. A gap in samples
//!   longer than the sample-age bound already ramps down and in again.
//! - The local model's stiffness is capped at the device's renderable
//!   maximum, and the safety filter's passivity observer/controller sees the
//!   device position.
//!
//! Counts of what these rejected land in [`Shared`] for the summary (the
//! telemetry tick is a protocol struct and has no field for them).

use crate::device::{Device, DeviceError, DeviceState};
use crate::extrapolate::local_problem::LocalProblem;
use crate::extrapolate::{Extrapolator, ForceSample, Method};
use crate::live::{Live, LiveConfig, LiveError, LiveGuard};
use crate::math::is_finite;
use crate::plausible::{Plausible, PlausibleConfig, PlausibleError, Verdict};
use crate::pose_history::PoseHistory;
use crate::safety::{PassivityConfig, PassivityError, Safety, SafetyConfig, SafetyState};
use crate::slots::{Flags, PoseSlot};
use crossbeam_queue::ArrayQueue;
use shared::loop_stats::LoopHistogram;
use shared::monotonic_ns;
use shared::protocol::{ForceMsg, PROTOCOL_VERSION, TelemetryTick};
use shared::source::Source;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::thread::Thread;
use thiserror::Error;

/// What the threads share.
pub struct Shared {
    /// Stop / liveness / error flags.
    pub flags: Flags,
    /// Latest pose for the I/O thread to publish.
    pub pose: PoseSlot,
    /// The device's recent positions (the contact-problem set-up steps a
    /// problem through them).
    pub pose_history: PoseHistory,
    /// Ticks for the I/O thread (telemetry, recording, statistics).
    pub telemetry: ArrayQueue<TelemetryTick>,
    /// Ticks that did not fit in the queue (the I/O thread fell behind).
    pub telemetry_dropped: AtomicU64,
    /// Force samples accepted.
    pub samples: AtomicU64,
    /// Device samples rejected as implausible or non-finite.
    pub poses_rejected: AtomicU64,
    /// Device reads that failed or carried a non-finite field (each also
    /// counts in `poses_rejected` unless it ended a long run).
    pub device_bad_reads: AtomicU64,
    /// Device poses taken as a new reference after a long rejection run.
    pub pose_rereferences: AtomicU64,
    /// Force samples not rendered because they ran faster than wall time.
    pub samples_not_live: AtomicU64,
    /// Contact problems set up for `local-problem`.
    pub local_problems: AtomicU64,
    /// Of those, set up with the tissue's inertia.
    pub local_problems_inertial: AtomicU64,
    /// Contact problems refused (another protocol version, malformed).
    pub local_problems_refused: AtomicU64,
    /// Ticks on which the passivity controller added damping.
    pub passivity_ticks: AtomicU64,
    /// Energy the passivity controller set out to dissipate (J, f64 bits).
    pub passivity_dissipated_j_bits: AtomicU64,
    /// The I/O thread, woken after each pose write (set by the I/O thread).
    pub io_thread: OnceLock<Thread>,
}

impl Shared {
    /// With room for `queue` ticks of telemetry.
    pub fn new(queue: usize) -> Self {
        Self {
            flags: Flags::default(),
            pose: PoseSlot::default(),
            pose_history: PoseHistory::default(),
            telemetry: ArrayQueue::new(queue.max(1)),
            telemetry_dropped: AtomicU64::new(0),
            samples: AtomicU64::new(0),
            poses_rejected: AtomicU64::new(0),
            device_bad_reads: AtomicU64::new(0),
            pose_rereferences: AtomicU64::new(0),
            samples_not_live: AtomicU64::new(0),
            local_problems: AtomicU64::new(0),
            local_problems_inertial: AtomicU64::new(0),
            local_problems_refused: AtomicU64::new(0),
            passivity_ticks: AtomicU64::new(0),
            passivity_dissipated_j_bits: AtomicU64::new(0f64.to_bits()),
            io_thread: OnceLock::new(),
        }
    }

    /// Wakes the I/O thread if it registered (allocation-free and
    /// non-blocking: an atomic swap, and a futex wake if it sleeps).
    pub fn wake_io(&self) {
        if let Some(t) = self.io_thread.get() {
            t.unpark();
        }
    }

    /// [`Shared::passivity_dissipated_j_bits`] as joules.
    pub fn passivity_dissipated_j(&self) -> f64 {
        f64::from_bits(self.passivity_dissipated_j_bits.load(Ordering::Relaxed))
    }
}

/// The daemon's checks between the device, the simulation and the safety
/// filter (see the module documentation), all on by default.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ChainConfig {
    /// Device pose plausibility.
    pub plausible: PlausibleConfig,
    /// Force samples at real rate only.
    pub live: LiveConfig,
    /// The safety filter's passivity observer/controller.
    pub passivity: PassivityConfig,
    /// Cap on the local model's stiffness (N/m); `None`: the device's
    /// `max_stiffness_n_per_m`.
    pub max_stiffness_n_per_m: Option<f64>,
}

/// A [`ChainConfig`] that cannot work.
#[derive(Clone, Copy, Debug, Error, PartialEq)]
pub enum ChainError {
    /// The pose plausibility limits.
    #[error(transparent)]
    Plausible(#[from] PlausibleError),
    /// The live-sample limits.
    #[error(transparent)]
    Live(#[from] LiveError),
    /// The passivity observer/controller.
    #[error(transparent)]
    Passivity(#[from] PassivityError),
    /// The stiffness cap is not a positive finite number.
    #[error("the stiffness cap must be a positive finite number of N/m, got {0}")]
    MaxStiffness(f64),
}

impl ChainConfig {
    /// Validates every part.
    pub fn validate(&self) -> Result<(), ChainError> {
        self.plausible.validate()?;
        self.live.validate()?;
        self.passivity.validate()?;
        if let Some(k) = self.max_stiffness_n_per_m
            && !(k.is_finite() && k > 0.0)
        {
            return Err(ChainError::MaxStiffness(k));
        }
        Ok(())
    }
}

/// Numeric code of a safety state in telemetry (see docs/protocol.md).
pub fn state_code(s: SafetyState) -> u32 {
    match s {
        SafetyState::Waiting => 0,
        SafetyState::RampingIn => 1,
        SafetyState::Active => 2,
        SafetyState::RampingDown(_) => 3,
        SafetyState::Stopped(_) => 4,
    }
}

/// The name of a safety-state code (the record CSV's `safety_state`):
/// `waiting`, `ramping-in`, `active`, `ramping-down`, `stopped`; `unknown`
/// for a code no daemon writes.
pub fn state_name(code: u32) -> &'static str {
    match code {
        0 => "waiting",
        1 => "ramping-in",
        2 => "active",
        3 => "ramping-down",
        4 => "stopped",
        _ => "unknown",
    }
}

/// The name of a method code (the record CSV's `method`: the
/// `--extrapolation` name); `unknown` for a code no daemon writes.
pub fn method_name(code: u32) -> &'static str {
    Method::ALL
        .get(code as usize)
        .map_or("unknown", |m| m.name())
}

/// Whether every field of a device reading is finite (the gripper is
/// clamped by the device; a NaN one is still a bad read).
fn state_is_finite(s: &DeviceState) -> bool {
    is_finite(s.position_m) && is_finite(s.velocity_m_s) && s.gripper.is_finite()
}

/// Numeric code of a method in telemetry.
pub fn method_code(m: Method) -> u32 {
    Method::ALL.iter().position(|x| *x == m).unwrap_or(0) as u32
}

/// The loop's state, generic over the device (no `dyn` per tick).
pub struct RtLoop<D: Device> {
    device: D,
    extrapolator: Extrapolator,
    safety: Safety,
    plausible: Plausible,
    live: LiveGuard,
    method: Method,
    subscriber: Option<Source<ForceMsg>>,
    shared: Arc<Shared>,
    last: DeviceState,
    last_sample_t_ns: Option<u64>,
    last_force_n: [f64; 3],
    tick: u64,
    /// Reads that failed or carried a non-finite field.
    bad_reads: u64,
    /// `local-problem`: the newest contact problem, set up off this thread.
    local: Option<triple_buffer::Output<LocalProblem>>,
    /// `local-problem`: the time each tick's render took (an HDR histogram,
    /// allocated with the loop).
    render_times: Option<LoopHistogram>,
}

impl<D: Device> RtLoop<D> {
    /// Everything allocated here, before the loop. `subscriber` None runs
    /// without a simulation (tests, device checks). The checks of
    /// [`ChainConfig::default`].
    pub fn new(
        device: D,
        method: Method,
        safety: SafetyConfig,
        subscriber: Option<Source<ForceMsg>>,
        shared: Arc<Shared>,
    ) -> Self {
        Self::with_chain(
            device,
            method,
            safety,
            ChainConfig::default(),
            subscriber,
            shared,
        )
    }

    /// [`RtLoop::new`] with the checks of `chain`.
    pub fn with_chain(
        device: D,
        method: Method,
        safety: SafetyConfig,
        chain: ChainConfig,
        subscriber: Option<Source<ForceMsg>>,
        shared: Arc<Shared>,
    ) -> Self {
        let max_stiffness = chain
            .max_stiffness_n_per_m
            .unwrap_or(device.specs().max_stiffness_n_per_m);
        Self {
            device,
            extrapolator: Extrapolator::new(method).with_max_stiffness(max_stiffness),
            safety: Safety::new(safety).with_passivity(chain.passivity),
            plausible: Plausible::new(chain.plausible),
            live: LiveGuard::new(chain.live),
            method,
            subscriber,
            shared,
            last: DeviceState::default(),
            last_sample_t_ns: None,
            last_force_n: [0.0; 3],
            tick: 0,
            bad_reads: 0,
            local: None,
            render_times: None,
        }
    }

    /// Renders `local-problem` from the contact problems `output` receives
    /// (set up on their own thread: [`crate::local_setup::run_local_setup`]); without them,
    /// or while none fits the newest sample, it renders as `local-normal`.
    pub fn with_local_problems(mut self, output: triple_buffer::Output<LocalProblem>) -> Self {
        self.local = Some(output);
        self.render_times = Some(LoopHistogram::new());
        self
    }

    /// `local-problem`: how long each tick's render took, the update of the
    /// triple buffer included (`None` for other methods).
    pub fn render_times(&self) -> Option<&LoopHistogram> {
        self.render_times.as_ref()
    }

    /// The extrapolated force at `now_ns` for the current device position:
    /// the contact problem's answer with `local-problem` when there is one
    /// for the newest sample, else the extrapolator's.
    fn extrapolate(&mut self, now_ns: u64) -> [f64; 3] {
        let position = self.last.position_m;
        if self.method == Method::LocalProblem
            && let (Some(out), Some(latest)) = (self.local.as_mut(), self.extrapolator.latest())
        {
            let latest = *latest;
            let t0 = monotonic_ns();
            out.update();
            let rendered = out.output_buffer_mut().render(
                &latest,
                now_ns,
                position,
                self.extrapolator.max_stiffness_n_per_m(),
            );
            if let Some(h) = &mut self.render_times {
                h.record_elapsed_ns(monotonic_ns().saturating_sub(t0));
            }
            if let Some(f) = rendered
                && is_finite(f)
            {
                return f;
            }
        }
        self.extrapolator.force(now_ns, position)
    }

    /// Enables the device output.
    pub fn enable(&mut self, now_ns: u64) -> Result<(), DeviceError> {
        self.device.enable(now_ns)
    }

    /// One tick at `now_ns`, `lateness_ns` after its deadline.
    pub fn tick(&mut self, now_ns: u64, lateness_ns: i64) {
        // 1. Device. A failed read keeps the last good state and poisons the
        // request, so the safety filter ramps the force down.
        self.shared
            .flags
            .heartbeat_ns
            .store(now_ns, Ordering::Relaxed);
        // A failed read and a sample with any non-finite field are one
        // bad read: rejected like an implausible pose (the last good one
        // held, counted), and only a run of them longer than the
        // plausibility bound stops the force (`Verdict::Lost`). One glitch
        // of a device driver must not drop a held force.
        let read = match self.device.read(now_ns) {
            Ok(s) if state_is_finite(&s) => Some(s),
            _ => {
                self.bad_reads += 1;
                None
            }
        };
        let p = read.map_or([f64::NAN; 3], |s| s.position_m);
        let mut poisoned = false;
        match self.plausible.check(now_ns, p) {
            Verdict::Accept => self.last = read.unwrap_or(self.last),
            Verdict::Rereference => {
                self.last = read.unwrap_or(self.last);
                self.safety.rebase_motion();
                self.safety.ramp_in_from_output(now_ns);
            }
            Verdict::Reject => {}
            Verdict::Lost => poisoned = true,
        }
        // 2. Pose for the simulation (published by the I/O thread, woken
        // for it).
        self.shared.pose.write(
            now_ns,
            self.last.position_m,
            self.last.gripper,
            self.last.buttons,
        );
        self.shared.wake_io();
        self.shared.pose_history.push(now_ns, self.last.position_m);
        // 3. Force samples: drain, newest wins (the extrapolator keeps two);
        // samples faster than wall time are not rendered.
        let mut resumed = false;
        if let Some(sub) = &mut self.subscriber {
            while let Some(sample) = sub.pop() {
                if sample.version != PROTOCOL_VERSION {
                    self.shared
                        .flags
                        .version_mismatch
                        .store(true, Ordering::Relaxed);
                    continue;
                }
                // Tool 0 is the device's; a message without tools is
                // "nothing": no contact, no force.
                let fs = ForceSample::from_wire(&sample, 0).unwrap_or(ForceSample {
                    t_ns: sample.t_ns,
                    seq: sample.seq,
                    position_m: sample.tools[0].position_m,
                    force_n: [0.0; 3],
                    stiffness_n_per_m: [[0.0; 3]; 3],
                    in_contact: false,
                    catching_up: false,
                });
                // A restarted simulation counts from 0 again: start over
                // rather than ignore it until its seq passes the old one.
                if self.extrapolator.latest().is_some_and(|l| fs.seq < l.seq) {
                    self.extrapolator.reset();
                    self.live.reset();
                }
                match self.live.observe(now_ns, sample.sim_time_ns) {
                    Live::NotLive => continue,
                    Live::Resumed => resumed = true,
                    Live::Live => {}
                }
                self.extrapolator.push(&fs);
                self.shared.samples.fetch_add(1, Ordering::Relaxed);
            }
        }
        // The age of the newest *accepted* sample: a simulation sending only
        // rejected (non-finite) samples must look stale, not fresh.
        self.last_sample_t_ns = self.extrapolator.latest().map(|s| s.t_ns);
        // 4-5. Extrapolate and make safe.
        let mut requested = self.extrapolate(now_ns);
        if poisoned {
            requested = [f64::NAN; 3];
        }
        let age = self.last_sample_t_ns.map(|t| now_ns.saturating_sub(t));
        let alive = self.shared.flags.peer_alive.load(Ordering::Relaxed);
        if resumed {
            self.safety.ramp_in_from_output(now_ns);
        }
        let out = self
            .safety
            .filter_at(now_ns, requested, self.last.position_m, age, alive);
        // 6. Device. A refused command is a fault: the next ticks ramp down.
        if self.device.write_force(out, now_ns).is_err() {
            self.safety.shutdown(now_ns);
        }
        self.last_force_n = out;
        self.publish_counts();
        // 7. Telemetry (dropped, and counted, if the I/O thread is behind).
        let tick = TelemetryTick {
            t_ns: now_ns,
            seq: self.tick,
            position_m: self.last.position_m,
            force_n: out,
            lateness_ns,
            sample_age_ns: age.unwrap_or(u64::MAX),
            method: method_code(self.method),
            safety_state: state_code(self.safety.state()),
        };
        if self.shared.telemetry.push(tick).is_err() {
            self.shared
                .telemetry_dropped
                .fetch_add(1, Ordering::Relaxed);
        }
        self.tick += 1;
    }

    /// The checks' counters, for the main thread's summary.
    fn publish_counts(&self) {
        let s = &self.shared;
        let p = self.safety.passivity();
        s.poses_rejected
            .store(self.plausible.rejected(), Ordering::Relaxed);
        s.device_bad_reads.store(self.bad_reads, Ordering::Relaxed);
        s.pose_rereferences
            .store(self.plausible.rereferences(), Ordering::Relaxed);
        s.samples_not_live
            .store(self.live.not_live(), Ordering::Relaxed);
        s.passivity_ticks.store(p.active_ticks(), Ordering::Relaxed);
        s.passivity_dissipated_j_bits
            .store(p.dissipated_j().to_bits(), Ordering::Relaxed);
    }

    /// The pose the loop uses (the last plausible one, m).
    pub fn position_m(&self) -> [f64; 3] {
        self.last.position_m
    }

    /// Begins the ramp to zero (stop requested).
    pub fn shutdown(&mut self, now_ns: u64) {
        self.safety.shutdown(now_ns);
    }

    /// The safety filter's state.
    pub fn safety_state(&self) -> SafetyState {
        self.safety.state()
    }

    /// Commands zero force and disables the device.
    pub fn disable(&mut self) {
        let _ = self.device.write_force([0.0; 3], 0);
        self.device.disable();
    }

    /// Ticks run.
    pub fn ticks(&self) -> u64 {
        self.tick
    }

    /// The device's specifications.
    pub fn device_specs(&self) -> crate::device::DeviceSpecs {
        self.device.specs()
    }

    /// The last force written (N).
    pub fn last_force_n(&self) -> [f64; 3] {
        self.last_force_n
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::safety::StopReason;

    #[test]
    fn every_code_written_has_its_name() {
        for m in Method::ALL {
            assert_eq!(method_name(method_code(m)), m.name());
        }
        let states = [
            (SafetyState::Waiting, "waiting"),
            (SafetyState::RampingIn, "ramping-in"),
            (SafetyState::Active, "active"),
            (
                SafetyState::RampingDown(StopReason::StaleSample),
                "ramping-down",
            ),
            (SafetyState::Stopped(StopReason::Shutdown), "stopped"),
        ];
        for (s, name) in states {
            assert_eq!(state_name(state_code(s)), name);
        }
        assert_eq!(state_name(99), "unknown");
        assert_eq!(method_name(99), "unknown");
    }
}
