//! Safety filter between the extrapolator and the device.
//!
//! [`Safety::filter`] turns the requested force into the force sent to the
//! device. Time is passed in (u64 ns, never read here), nothing allocates,
//! nothing panics, whatever the inputs.
//!
//! # Invariants
//!
//! - `|output| <= max_force_n`: the request is clamped, direction kept.
//! - `|output - previous output| <= max_slew_n_per_s * dt`, with `dt` the
//!   advance of the filter's clock since the previous call. The clock is
//!   the largest `now_ns` seen so far: a first call, a repeated or an
//!   earlier `now_ns` all give `dt = 0`, so nothing moves (a backward clock
//!   freezes the output at its last safe value rather than letting a jump
//!   through).
//! - A non-finite request never reaches the output.
//! - Every ramp-down is linear from the output at its start to zero, ending
//!   `ramp_down_ns` after its start; its slope `|F0| / ramp_down` is within
//!   the slew limit because [`SafetyConfig::validate`] demands
//!   `max_slew_n_per_s >= max_force_n / ramp_down`.
//!
//! # States
//!
//! - [`SafetyState::Waiting`]: no sample yet (`sample_age_ns` is `None`);
//!   zero force.
//! - A fault, in priority order: peer dead ([`StopReason::PeerDead`]),
//!   sample older than `max_sample_age_ns` or no sample after there was one
//!   ([`StopReason::StaleSample`]), non-finite request
//!   ([`StopReason::NonFinite`]).
//! - `RampingIn` / `Active` + fault: `RampingDown(fault)`, from the last
//!   output (held on the tick that saw the fault, then decaying).
//! - `RampingDown(r)` always runs to zero, even if the fault clears
//!   meanwhile (a glitch costs a ramp-down and a ramp-in, never a jump
//!   back), then `Stopped(r)`.
//! - `Waiting` (once a sample exists) or `Stopped(r)` other than shutdown:
//!   zero force; the reason follows the current fault; with no fault, a
//!   ramp-in starts: the clamped request is scaled from 0 to 1 over
//!   `ramp_in_ns` (slew-limited too), then `Active`.
//! - [`Safety::shutdown`]: `RampingDown(Shutdown)` from the current output
//!   (an ongoing ramp-down keeps its earlier end), then
//!   `Stopped(Shutdown)`: exactly zero forever, whatever `filter` is given.
//!
//! A [`SafetyConfig`] that fails validation (its fields are public) makes
//! the filter output zero force forever: the limit is taken as 0 N.
//!
//! # Ramping in again while active
//!
//! [`Safety::ramp_in_from_output`] restarts the ramp-in from the current
//! output instead of from zero: over `ramp_in_ns` the output blends from
//! that force to the request (`F_from (1 - g) + g F_request`, the ordinary
//! ramp-in being the case `F_from = 0`), never larger than the request
//! (the blend is shortened to its magnitude: a force that fell meanwhile
//! is let go, not held), clamped and slew-limited as always. The daemon calls it when its inputs jump for a reason it knows
//! (the device pose was re-referenced after implausible samples, force
//! samples are live again after a fast-forward), so the jump reaches the
//! hand as a ramp, not a step. In any other state it does nothing (those
//! ramp in from zero by themselves).
//!
//! # Passivity
//!
//! [`Safety::filter_at`] also takes the device position: the passivity
//! observer/controller ([`passivity`], Hannaford and Ryu 2002) watches the
//! energy the output puts into the hand and, in `RampingIn` / `Active`,
//! adds damping along the motion while the environment has generated more
//! than its tolerance. The damping goes through the same clamp and slew
//! limit, so every invariant above still holds. [`Safety::filter`] (no
//! position) leaves it out.

mod config;
pub mod passivity;
#[cfg(test)]
mod tests;

pub use config::{
    DEFAULT_FULL_SCALE_NS, DEFAULT_MAX_SAMPLE_AGE_NS, DEFAULT_RAMP_DOWN_NS, DEFAULT_RAMP_IN_NS,
    SafetyConfig, SafetyError,
};

pub use passivity::{Passivity, PassivityConfig, PassivityError};

use crate::math::{V3, ZERO, add, clamp_norm, is_finite, norm, scale, step_toward};

/// Why the force was (or is being) brought to zero.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopReason {
    /// The latest sample is older than `max_sample_age_ns`.
    StaleSample,
    /// The simulation's node is gone.
    PeerDead,
    /// The requested force was NaN or infinite.
    NonFinite,
    /// [`Safety::shutdown`] was called; final.
    Shutdown,
}

/// The filter's state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SafetyState {
    /// No sample yet: zero force.
    Waiting,
    /// The force scale rises from 0 to 1.
    RampingIn,
    /// The (clamped, slew-limited) request passes.
    Active,
    /// The force decays linearly to zero.
    RampingDown(StopReason),
    /// Zero force; recovers with a ramp-in unless the reason is `Shutdown`.
    Stopped(StopReason),
}

/// The fault the inputs show, if any (priority: peer dead, stale or
/// missing sample, non-finite request).
pub fn fault_of(
    requested_n: V3,
    sample_age_ns: Option<u64>,
    peer_alive: bool,
    max_sample_age_ns: u64,
) -> Option<StopReason> {
    if !peer_alive {
        Some(StopReason::PeerDead)
    } else if sample_age_ns.is_none_or(|a| a > max_sample_age_ns) {
        Some(StopReason::StaleSample)
    } else if !is_finite(requested_n) {
        Some(StopReason::NonFinite)
    } else {
        None
    }
}

/// The linear ramp from `from_n` at `start_ns` to zero at
/// `start_ns + ramp_ns`, evaluated at `t_ns`; `None` once it has ended.
/// Before `start_ns` the ramp holds `from_n`.
pub fn ramp_down_value(from_n: V3, start_ns: u64, ramp_ns: u64, t_ns: u64) -> Option<V3> {
    let elapsed = t_ns.saturating_sub(start_ns);
    if elapsed >= ramp_ns {
        return None;
    }
    // elapsed < ramp_ns, so the fraction lies in (0, 1].
    Some(scale(from_n, 1.0 - elapsed as f64 / ramp_ns as f64))
}

/// The ramp-in gain at `t_ns`: 0 at `start_ns`, 1 from `start_ns + ramp_ns`
/// on (1 at once for a zero-length ramp).
pub fn ramp_in_gain(start_ns: u64, ramp_ns: u64, t_ns: u64) -> f64 {
    let elapsed = t_ns.saturating_sub(start_ns);
    if elapsed >= ramp_ns {
        1.0
    } else {
        elapsed as f64 / ramp_ns as f64
    }
}

/// The filter's state (fixed size, no heap).
#[derive(Clone, Debug)]
pub struct Safety {
    cfg: SafetyConfig,
    /// `cfg.max_force_n`, or 0 for an invalid configuration.
    limit_n: f64,
    state: SafetyState,
    out_n: V3,
    /// The filter's clock: the largest `now_ns` seen by `filter`.
    clock_ns: Option<u64>,
    /// Start of the current ramp (in or down).
    ramp_start_ns: u64,
    /// The output when the current ramp-down began.
    ramp_from_n: V3,
    /// The force the current ramp-in starts from (zero unless restarted by
    /// [`Safety::ramp_in_from_output`]).
    ramp_in_from_n: V3,
    passivity: Passivity,
}

impl Safety {
    /// A filter in [`SafetyState::Waiting`] with zero output.
    pub fn new(cfg: SafetyConfig) -> Self {
        let limit_n = if cfg.validate().is_ok() {
            cfg.max_force_n
        } else {
            0.0
        };
        Self {
            cfg,
            limit_n,
            state: SafetyState::Waiting,
            out_n: ZERO,
            clock_ns: None,
            ramp_start_ns: 0,
            ramp_from_n: ZERO,
            ramp_in_from_n: ZERO,
            passivity: Passivity::new(PassivityConfig::OFF),
        }
    }

    /// The same with the passivity observer/controller configured (off by
    /// default in [`Safety::new`]; the daemon turns it on).
    pub fn with_passivity(mut self, cfg: PassivityConfig) -> Self {
        self.passivity = Passivity::new(cfg);
        self
    }

    /// The passivity observer/controller.
    pub fn passivity(&self) -> &Passivity {
        &self.passivity
    }

    /// Forgets the previous device position (the pose was re-referenced:
    /// its jump is not motion under the force).
    pub fn rebase_motion(&mut self) {
        self.passivity.rebase();
    }

    /// Restarts the ramp-in from the current output (see the module
    /// documentation); only in `RampingIn` and `Active`.
    pub fn ramp_in_from_output(&mut self, now_ns: u64) {
        if matches!(self.state, SafetyState::RampingIn | SafetyState::Active) {
            self.state = SafetyState::RampingIn;
            self.ramp_start_ns = self.clock_ns.map_or(now_ns, |c| c.max(now_ns));
            self.ramp_in_from_n = self.out_n;
        }
    }

    /// The configuration.
    pub fn config(&self) -> &SafetyConfig {
        &self.cfg
    }

    /// The state after the last call.
    pub fn state(&self) -> SafetyState {
        self.state
    }

    /// The last output (N).
    pub fn output_n(&self) -> V3 {
        self.out_n
    }

    /// The force to send to the device at `now_ns` (N), given the requested
    /// force, the age of the latest sample (`None`: no sample yet) and
    /// whether the simulation is alive. See the module documentation.
    pub fn filter(
        &mut self,
        now_ns: u64,
        requested_n: V3,
        sample_age_ns: Option<u64>,
        peer_alive: bool,
    ) -> V3 {
        self.filter_inner(now_ns, requested_n, None, sample_age_ns, peer_alive)
    }

    /// [`Safety::filter`] with the device position at `now_ns` (m), for the
    /// passivity observer/controller (see the module documentation).
    pub fn filter_at(
        &mut self,
        now_ns: u64,
        requested_n: V3,
        position_m: V3,
        sample_age_ns: Option<u64>,
        peer_alive: bool,
    ) -> V3 {
        self.filter_inner(
            now_ns,
            requested_n,
            Some(position_m),
            sample_age_ns,
            peer_alive,
        )
    }

    fn filter_inner(
        &mut self,
        now_ns: u64,
        requested_n: V3,
        position_m: Option<V3>,
        sample_age_ns: Option<u64>,
        peer_alive: bool,
    ) -> V3 {
        let t = self.clock_ns.map_or(now_ns, |c| c.max(now_ns));
        let dt_ns = self.clock_ns.map_or(0, |c| t - c);
        self.clock_ns = Some(t);
        if let Some(x) = position_m {
            self.passivity.observe(x, dt_ns, self.out_n, requested_n);
        }
        let fault = fault_of(
            requested_n,
            sample_age_ns,
            peer_alive,
            self.cfg.max_sample_age_ns,
        );

        // Transitions.
        match self.state {
            SafetyState::Stopped(StopReason::Shutdown) | SafetyState::RampingDown(_) => {}
            SafetyState::Waiting if sample_age_ns.is_none() => {}
            SafetyState::Waiting | SafetyState::Stopped(_) => match fault {
                Some(r) => self.state = SafetyState::Stopped(r),
                None => {
                    self.state = SafetyState::RampingIn;
                    self.ramp_start_ns = t;
                    self.ramp_in_from_n = ZERO;
                }
            },
            SafetyState::RampingIn | SafetyState::Active => {
                if let Some(r) = fault {
                    self.begin_ramp_down(r, t);
                }
            }
        }

        // Output of the (new) state.
        let out = match self.state {
            SafetyState::Waiting | SafetyState::Stopped(_) => ZERO,
            SafetyState::RampingDown(r) => {
                match ramp_down_value(
                    self.ramp_from_n,
                    self.ramp_start_ns,
                    self.cfg.ramp_down_ns,
                    t,
                ) {
                    Some(v) => v,
                    None => {
                        self.state = SafetyState::Stopped(r);
                        ZERO
                    }
                }
            }
            SafetyState::RampingIn | SafetyState::Active => {
                let gain = if self.state == SafetyState::RampingIn {
                    ramp_in_gain(self.ramp_start_ns, self.cfg.ramp_in_ns, t)
                } else {
                    1.0
                };
                if gain >= 1.0 {
                    self.state = SafetyState::Active;
                }
                if self.state == SafetyState::Active {
                    self.ramp_in_from_n = ZERO;
                }
                // No fault, so the request is finite here. From zero the
                // blend is exactly `gain * request`.
                let request = clamp_norm(requested_n, self.limit_n);
                let blend = if self.ramp_in_from_n == ZERO {
                    scale(request, gain)
                } else {
                    // Never more than the request: a force that fell (the
                    // tool left the tissue while the pose jumped) is let go
                    // at the slew limit, not held on for the ramp (after a
                    // re-reference 50 mm out of the tissue the old force
                    // decayed over 230 ms).
                    let b = add(scale(self.ramp_in_from_n, 1.0 - gain), scale(request, gain));
                    let (nb, nr) = (norm(b), norm(request));
                    if nb > nr { scale(b, nr / nb) } else { b }
                };
                let damping = if position_m.is_some() {
                    self.passivity.damping_n(dt_ns)
                } else {
                    ZERO
                };
                let target = clamp_norm(add(blend, damping), self.limit_n);
                let max_step_n = self.cfg.max_slew_n_per_s * (dt_ns as f64 / 1e9);
                step_toward(self.out_n, target, max_step_n)
            }
        };
        // Defence in depth: every branch above is finite and inside the
        // limit by construction; the clamp only absorbs rounding.
        self.out_n = clamp_norm(out, self.limit_n);
        self.out_n
    }

    /// Begins the ramp to zero at `now_ns` (SIGTERM path): `filter` then
    /// ramps down whatever it is given and ends in `Stopped(Shutdown)`
    /// with zero output forever. Calling it again changes nothing.
    pub fn shutdown(&mut self, now_ns: u64) {
        let t = self.clock_ns.map_or(now_ns, |c| c.max(now_ns));
        match self.state {
            SafetyState::Stopped(StopReason::Shutdown)
            | SafetyState::RampingDown(StopReason::Shutdown) => {}
            // Already at zero: nothing to ramp.
            SafetyState::Waiting | SafetyState::Stopped(_) => {
                self.state = SafetyState::Stopped(StopReason::Shutdown);
                self.out_n = ZERO;
            }
            // Keep the ongoing ramp: it ends no later than a new one would.
            SafetyState::RampingDown(_) => {
                self.state = SafetyState::RampingDown(StopReason::Shutdown)
            }
            SafetyState::RampingIn | SafetyState::Active => {
                self.begin_ramp_down(StopReason::Shutdown, t)
            }
        }
    }

    fn begin_ramp_down(&mut self, reason: StopReason, t_ns: u64) {
        self.state = SafetyState::RampingDown(reason);
        self.ramp_start_ns = t_ns;
        self.ramp_from_n = self.out_n;
    }
}
