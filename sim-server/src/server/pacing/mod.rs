//! Real-time pacing of the simulation loop: when each step is due, how
//! early a step may start on a fresh pose, and what happens after a stall.
//!
//! Pure: the clock is passed in, nothing allocates.
//!
//! # The rules
//!
//! - Step `k` (counting from the last anchor) is due at
//!   `anchor_ns + (k - anchor_step) * step_ns`; the loop waits for it.
//! - A step may start up to `early_ns` (two steps, at most
//!   [`MAX_EARLY_NS`]) before it is due when a fresh pose has arrived, so that
//!   a pose gets its force one step later instead of waiting for the grid.
//!   Simulated time never runs ahead of wall time by more than the early
//!   window, half a step (the phase below) and the step in progress: never
//!   faster than real time. Two steps, not one: the daemon's ticks jitter
//!   (by up to +-0.4 ms at the 1st and 99th percentiles on this VM without
//!   SCHED_FIFO), and with a one-step window 7-35% of the poses came before
//!   it opened and waited up to half a millisecond for it (measured on the
//!   liver; with two steps the 90th percentile of a pose's wait from the
//!   device read to the step fell from 250-590 to 180-230 us).
//! - The grid locks onto the poses' phase (steps up to 1 ms, where the
//!   window is two whole steps): when a step starts on a pose,
//!   the grid is shifted a little (at most [`PHASE_SLEW_OF_EARLY`] of the
//!   early window per step) towards the phase at which poses arrive in the
//!   middle of the early window. Otherwise a daemon whose poses arrive just
//!   after a step fell due (its ticks and the grid started independently)
//!   has the loop start that step on the clock, with the previous pose,
//!   and the fresh pose then waits the whole step out: measured on the
//!   liver, device -> force 450-670 us at the median in some runs against
//!   320-340 in others, the same binaries. The shift is a phase, taken
//!   modulo a step within half a step either way, so the rate stays the
//!   real-time rate (simulated time ahead of wall time by at most the early
//!   window plus half a step): a pose stream slightly slower or faster than
//!   the grid makes it wrap now and then, one step without a fresh pose or
//!   two poses in one step. Poses more than four to every three steps
//!   (a 2-4 kHz device against 1 ms steps; the period estimated from their
//!   sequence numbers and device times) have one waiting whenever the
//!   window opens: the phase then follows the age of the pose each step
//!   takes instead ([`Pacing::observe_pose`]).
//! - After a stall (the process stopped, a long step) the loop does not
//!   fast-forward through the missed steps: when the next step is more than
//!   `bound_ns` (two steps or 5 ms, whichever is larger) overdue,
//!   the grid is re-anchored to now and the overdue time is counted as
//!   dropped. Simulated time (`ForceMsg::sim_time_ns`, steps x step) then runs
//!   behind wall time by everything dropped so far, at the real-time rate.

/// The early window's cap (ns): a step starts at most this long before it is due.
pub const MAX_EARLY_NS: u64 = 2_000_000;
/// How far the grid's phase moves per step started on a pose, as a
/// fraction of the early window at most (and 1/8 of the phase error).
pub const PHASE_SLEW_OF_EARLY: f64 = 1.0 / 32.0;
/// The smallest stall bound (ns).
pub const MIN_STALL_BOUND_NS: u64 = 5_000_000;

/// The pacing state.
#[derive(Clone, Debug)]
pub struct Pacing {
    step_ns: u64,
    anchor_ns: u64,
    anchor_step: u64,
    bound_ns: u64,
    early_ns: u64,
    /// The grid's shift towards the poses' phase (ns), within half a step.
    phase_ns: i64,
    /// The poses' period (ns), estimated from their sequence numbers and
    /// device times (0 until two have been seen).
    pose_period_ns: u64,
    /// The last pose seen: (sequence number, device time in ns).
    last_pose: Option<(u64, u64)>,
    /// Device read to step start of a pose that woke the waiting loop
    /// (ns, a moving average): the transport, without a wait.
    transport_ns: Option<u64>,
    dropped_ns: u64,
    stalls: u64,
}

impl Pacing {
    /// Steps of `step_ns` (at least 1 ns) from `start_ns`, step 0 due then.
    pub fn new(start_ns: u64, step_ns: u64) -> Self {
        let step_ns = step_ns.max(1);
        Self {
            step_ns,
            anchor_ns: start_ns,
            anchor_step: 0,
            bound_ns: (2 * step_ns).max(MIN_STALL_BOUND_NS),
            early_ns: (2 * step_ns).min(MAX_EARLY_NS),
            phase_ns: 0,
            pose_period_ns: 0,
            last_pose: None,
            transport_ns: None,
            dropped_ns: 0,
            stalls: 0,
        }
    }

    /// When the step after `steps` steps is due (ns).
    pub fn due(&self, steps: u64) -> u64 {
        (self.anchor_ns + steps.saturating_sub(self.anchor_step) * self.step_ns)
            .saturating_add_signed(self.phase_ns)
    }

    /// A fresh pose taken by a step that started at `start_ns`: its
    /// sequence number and device time (ns). Estimates the poses' period
    /// (sequence numbers that skip, as when the loop takes one pose a step
    /// of a faster stream, divide the time between the two; a moving
    /// average, 1/8 of each new interval) and, when poses come several to
    /// a step, moves the grid's phase so that the window opens just after
    /// one arrives (see [`Pacing::several_to_a_step`]).
    pub fn observe_pose(&mut self, seq: u64, t_ns: u64, start_ns: u64, on_arrival: bool) {
        if let Some((seq0, t0)) = self.last_pose
            && seq > seq0
            && t_ns > t0
        {
            let interval = (t_ns - t0) / (seq - seq0);
            // A gap longer than a stall bound (a paused publisher, a bad
            // device time) says nothing about the period.
            if interval <= self.bound_ns {
                self.pose_period_ns = if self.pose_period_ns == 0 {
                    interval
                } else {
                    (7 * self.pose_period_ns + interval) / 8
                };
            }
        }
        self.last_pose = Some((seq, t_ns));
        let age_ns = start_ns.saturating_sub(t_ns);
        if on_arrival {
            // A pose that woke the waiting loop: its age is the transport
            // alone (a moving average, 1/8 of each).
            self.transport_ns = Some(self.transport_ns.map_or(age_ns, |t| (7 * t + age_ns) / 8));
        } else if self.several_to_a_step() && self.early_ns >= 2 * self.step_ns {
            self.follow_fresh_pose(age_ns);
        }
    }

    /// Whether poses come more than four to every three steps (a 2-4 kHz
    /// device against 1 ms steps). A pose is then waiting whenever the
    /// window opens and every step starts at the opening: the phase is set
    /// by the age of the pose it takes (device read to step start), not by
    /// when a pose arrived in the window. Followed as at one pose a step,
    /// the first pose in the window always looked early, the phase drifted
    /// on and wrapped every few tens of steps, a step lost each time.
    fn several_to_a_step(&self) -> bool {
        self.pose_period_ns > 0 && 4 * self.pose_period_ns < 3 * self.step_ns
    }

    /// Poses several to a step: moves the window's opening towards just
    /// after the newest pose arrived. `age_ns` (device read to step start)
    /// is the transport (`transport_ns`, measured on poses that woke the
    /// waiting loop, never on these: a reference taken from the ages being
    /// steered, such as their minimum, moves with them and the lock ran
    /// away) plus the pose's wait for the opening; the error is the wait
    /// beyond an eighth of a period (room for jitter), taken modulo a
    /// period within half a period either way: a window that opens just
    /// before a pose arrives takes the one before it, a period older,
    /// which is the same phase error, so the lock settles instead of
    /// drifting. Once locked, poses seldom wake the loop, so the transport
    /// is mostly the one measured before (at start-up, while the loop
    /// caught up; re-measured after a stall): a path that became slower by
    /// most of a period since would leave the window opening just before
    /// arrivals. Without a transport (no pose-ready notifications), the
    /// phase stays.
    fn follow_fresh_pose(&mut self, age_ns: u64) {
        let Some(transport) = self.transport_ns else {
            return;
        };
        let period = self.pose_period_ns as i64;
        let wait = age_ns as i64 - transport as i64;
        let error = (wait - period / 8 + period / 2).rem_euclid(period) - period / 2;
        let slew = (self.early_ns as f64 * PHASE_SLEW_OF_EARLY) as i64;
        // Waited too long: the opening moves earlier, towards the arrival.
        self.shift_phase(-(error / 8).clamp(-slew, slew));
    }

    /// Moves the phase by `by_ns`, modulo a step within half a step.
    fn shift_phase(&mut self, by_ns: i64) {
        let (step, half) = (self.step_ns as i64, (self.step_ns / 2) as i64);
        self.phase_ns = (self.phase_ns + by_ns + half).rem_euclid(step) - half;
    }

    /// The step after `steps` steps starts at `now_ns` on a pose that
    /// arrived then: moves the grid's phase towards the one at which
    /// poses arrive in the middle of the early window.
    pub fn started_on_pose(&mut self, steps: u64, now_ns: u64) {
        if self.early_ns < 2 * self.step_ns {
            // Steps over 1 ms (the window capped below two steps): poses
            // come several to a step, there is no one phase to follow, and
            // a wrap of a long step could pass for a stall.
            return;
        }
        if self.several_to_a_step() {
            // Followed by the poses' age instead (`observe_pose`).
            return;
        }
        let target = self.due(steps) as i64 - (self.early_ns / 2) as i64;
        let error = now_ns as i64 - target;
        let slew = (self.early_ns as f64 * PHASE_SLEW_OF_EARLY) as i64;
        // Modulo a step, kept within half a step either way: poses a little
        // slower than the grid (a daemon whose ticks are sometimes late
        // publishes ~0.5% fewer) move the phase on until it wraps, which
        // costs one step without a fresh pose; a phase held at a bound
        // instead left them arriving at the window's edge, a third of them
        // waiting ~0.45 ms for it to open (measured on the liver).
        self.shift_phase((error / 8).clamp(-slew, slew));
    }

    /// The grid's current shift towards the poses' phase (ns).
    #[cfg(test)]
    pub fn phase_ns(&self) -> i64 {
        self.phase_ns
    }

    /// The earliest that step may start on a fresh pose (ns).
    pub fn earliest(&self, steps: u64) -> u64 {
        self.due(steps).saturating_sub(self.early_ns)
    }

    /// Called after `steps` steps at `now_ns`: when the next step is overdue
    /// by more than the bound, re-anchors the grid to now (the next step is
    /// due at once) and returns the time dropped (ns).
    pub fn catch_up(&mut self, steps: u64, now_ns: u64) -> Option<u64> {
        let due = self.due(steps);
        let behind = now_ns.saturating_sub(due);
        if behind <= self.bound_ns {
            return None;
        }
        self.anchor_ns = now_ns;
        self.anchor_step = steps;
        self.phase_ns = 0;
        // The path may have changed with whatever stalled.
        self.transport_ns = None;
        self.dropped_ns += behind;
        self.stalls += 1;
        Some(behind)
    }

    /// Simulated time dropped so far (ns): how far simulated time runs
    /// behind wall time since the start, besides the step in progress.
    pub fn dropped_ns(&self) -> u64 {
        self.dropped_ns
    }

    /// Times the grid was re-anchored.
    pub fn stalls(&self) -> u64 {
        self.stalls
    }
}

#[cfg(test)]
mod tests;
