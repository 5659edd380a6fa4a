//! The real-time loop: read device -> publish pose -> drain force samples ->
//! extrapolate -> safety -> write device -> telemetry. Everything it needs is
//! allocated in [`RtLoop::new`]; [`RtLoop::tick`] allocates nothing, takes
//! no lock, and makes no system call other than what the device needs
//! (iceoryx2's `receive` is allocation-free; publishing happens on the I/O
//! thread, because iceoryx2 0.10's `loan` allocates).

use crate::device::{Device, DeviceError, DeviceState};
use crate::extrapolate::{Extrapolator, ForceSample, Method};
use crate::safety::{Safety, SafetyConfig, SafetyState};
use crate::slots::{Flags, PoseSlot};
use crossbeam_queue::ArrayQueue;
use iceoryx2::port::subscriber::Subscriber;
use shared::protocol::{ForceMsg, PROTOCOL_VERSION, TelemetryTick};
use shared::services::Ipc;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// What the threads share.
pub struct Shared {
    /// Stop / liveness / error flags.
    pub flags: Flags,
    /// Latest pose for the I/O thread to publish.
    pub pose: PoseSlot,
    /// Ticks for the I/O thread (telemetry, recording, statistics).
    pub telemetry: ArrayQueue<TelemetryTick>,
    /// Ticks that did not fit in the queue (the I/O thread fell behind).
    pub telemetry_dropped: AtomicU64,
    /// Force samples accepted.
    pub samples: AtomicU64,
}

impl Shared {
    /// With room for `queue` ticks of telemetry.
    pub fn new(queue: usize) -> Self {
        Self {
            flags: Flags::default(),
            pose: PoseSlot::default(),
            telemetry: ArrayQueue::new(queue.max(1)),
            telemetry_dropped: AtomicU64::new(0),
            samples: AtomicU64::new(0),
        }
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

/// Numeric code of a method in telemetry.
pub fn method_code(m: Method) -> u32 {
    Method::ALL.iter().position(|x| *x == m).unwrap_or(0) as u32
}

/// The loop's state, generic over the device (no `dyn` per tick).
pub struct RtLoop<D: Device> {
    device: D,
    extrapolator: Extrapolator,
    safety: Safety,
    method: Method,
    subscriber: Option<Subscriber<Ipc, ForceMsg, ()>>,
    shared: Arc<Shared>,
    last: DeviceState,
    last_sample_t_ns: Option<u64>,
    last_force_n: [f64; 3],
    tick: u64,
}

impl<D: Device> RtLoop<D> {
    /// Everything allocated here, before the loop. `subscriber` None runs
    /// without a simulation (tests, device checks).
    pub fn new(
        device: D,
        method: Method,
        safety: SafetyConfig,
        subscriber: Option<Subscriber<Ipc, ForceMsg, ()>>,
        shared: Arc<Shared>,
    ) -> Self {
        Self {
            device,
            extrapolator: Extrapolator::new(method),
            safety: Safety::new(safety),
            method,
            subscriber,
            shared,
            last: DeviceState::default(),
            last_sample_t_ns: None,
            last_force_n: [0.0; 3],
            tick: 0,
        }
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
        let read = self.device.read(now_ns);
        let mut poisoned = false;
        match read {
            Ok(s)
                if s.position_m
                    .iter()
                    .chain(&s.velocity_m_s)
                    .all(|x| x.is_finite()) =>
            {
                self.last = s
            }
            _ => poisoned = true,
        }
        // 2. Pose for the simulation (published by the I/O thread).
        self.shared.pose.write(
            now_ns,
            self.last.position_m,
            self.last.gripper,
            self.last.buttons,
        );
        // 3. Force samples: drain, newest wins (the extrapolator keeps two).
        if let Some(sub) = &self.subscriber {
            while let Ok(Some(sample)) = sub.receive() {
                if sample.version != PROTOCOL_VERSION {
                    self.shared
                        .flags
                        .version_mismatch
                        .store(true, Ordering::Relaxed);
                    continue;
                }
                let t = &sample.tools[0];
                let fs = ForceSample {
                    t_ns: sample.t_ns,
                    seq: sample.seq,
                    position_m: t.position_m,
                    force_n: t.force_n,
                    stiffness_n_per_m: t.stiffness_n_per_m,
                    in_contact: t.flags & shared::protocol::CONTACT != 0,
                };
                // A restarted simulation counts from 0 again: start over
                // rather than ignore it until its seq passes the old one.
                if self.extrapolator.latest().is_some_and(|l| fs.seq < l.seq) {
                    self.extrapolator.reset();
                }
                self.extrapolator.push(&fs);
                self.shared.samples.fetch_add(1, Ordering::Relaxed);
            }
        }
        // The age of the newest *accepted* sample: a simulation sending only
        // rejected (non-finite) samples must look stale, not fresh.
        self.last_sample_t_ns = self.extrapolator.latest().map(|s| s.t_ns);
        // 4-5. Extrapolate and make safe.
        let mut requested = self.extrapolator.force(now_ns, self.last.position_m);
        if poisoned {
            requested = [f64::NAN; 3];
        }
        let age = self.last_sample_t_ns.map(|t| now_ns.saturating_sub(t));
        let alive = self.shared.flags.peer_alive.load(Ordering::Relaxed);
        let out = self.safety.filter(now_ns, requested, age, alive);
        // 6. Device. A refused command is a fault: the next ticks ramp down.
        if self.device.write_force(out, now_ns).is_err() {
            self.safety.shutdown(now_ns);
        }
        self.last_force_n = out;
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
