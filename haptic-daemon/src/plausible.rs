//! Plausible device poses only: a sample the hand could not have produced
//! (a tracking or bus glitch, a NaN) is rejected, and the last good pose is
//! held for the simulation, the extrapolator and the safety filter.
//!
//! Pure: time is passed in (u64 ns), nothing allocates, nothing panics.
//!
//! # The envelope
//!
//! From the last accepted pose `p_g` at `t_g`, with `v_g` the velocity over
//! the last few accepted poses, a sample `p` at `t` (`dt = t - t_g`) is
//! plausible when both
//!
//! - speed: `|p - p_g| <= max_speed_m_s dt + tolerance_m`, and
//! - acceleration: `|p - (p_g + v_g dt)| <= max_accel_m_s2 dt^2 / 2 + tolerance_m`
//!
//! hold. The tolerance absorbs sensor quantisation (0.01-0.06 mm on common
//! devices) and the timing jitter of devices that deliver poses on their own
//! thread (a sample 1 ms late at 2 m/s is 2 mm off). Because `dt` counts
//! from the last *good* pose, the envelope widens during a run of
//! rejections, so a hand that really moved is soon inside it again.
//!
//! # Runs of rejections
//!
//! A run that ends on a plausible sample more than `tolerance_m` away from
//! where the hand was heading (the envelope widened enough to take it in)
//! hid a real move: the sample is used but reported as
//! [`Verdict::Rereference`], so the daemon ramps the force in rather than
//! let the pose jump. A run that lasts [`PlausibleConfig::max_reject_run_ns`]
//! (20 ms) means the device really is elsewhere (re-homed, picked up and put down): the next
//! finite sample is accepted as the new reference ([`Verdict::Rereference`],
//! velocity history cleared) and the daemon ramps the force in again. A run
//! of non-finite samples that long gives [`Verdict::Lost`] (the daemon stops
//! the force). A glitch shorter than the bound (e.g. 5 ms at 1 m, or 20 mm
//! deeper) is rejected entirely: the pose, hence the force, before and
//! after are the same.

use crate::math::{V3, add, is_finite, norm, scale, sub};
use thiserror::Error;

/// Default largest hand speed (m/s). A surgeon's hand peaks around
/// 1-2 m/s in fast gestures (and far lower when operating); 3 m/s leaves a
/// margin over that while a glitch of a few mm per 1 ms tick (3+ m/s) or a
/// jump across the workspace is far beyond it.
pub const DEFAULT_MAX_SPEED_M_S: f64 = 3.0;
/// Default largest hand acceleration (m/s^2). Fast human arm and hand
/// movements reach 10-50 m/s^2 (ballistic flicks up to ~100); a device
/// handle stopped by the rendered contact decelerates by at most its force
/// limit over its mass (~8 N / 0.1-0.3 kg, 30-80 m/s^2).
pub const DEFAULT_MAX_ACCEL_M_S2: f64 = 100.0;
/// Default position tolerance (m): 2 mm, see the module documentation.
pub const DEFAULT_TOLERANCE_M: f64 = 2e-3;
/// Default longest run of rejections before the device's pose is taken as
/// the new reference (ns): 20 ms.
pub const DEFAULT_MAX_REJECT_RUN_NS: u64 = 20_000_000;

/// Accepted poses kept for the velocity estimate.
const HISTORY: usize = 8;
/// The velocity estimate spans at most this much time (ns); older history
/// (after a pause of the device) gives zero velocity.
const MAX_VELOCITY_SPAN_NS: u64 = 50_000_000;

/// A plausibility configuration that cannot work.
#[derive(Clone, Copy, Debug, Error, PartialEq)]
pub enum PlausibleError {
    /// A limit is not a positive finite number.
    #[error("the pose limit {name} must be a positive finite number, got {value}")]
    Limit {
        /// The field.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// The tolerance is negative or not finite.
    #[error("the pose tolerance must be a finite number >= 0 m, got {0}")]
    Tolerance(f64),
    /// The run bound is zero.
    #[error("max_reject_run_ns must be longer than 0 ns")]
    ZeroRun,
}

/// The limits of a plausible pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlausibleConfig {
    /// Largest speed of the handle (m/s).
    pub max_speed_m_s: f64,
    /// Largest acceleration of the handle (m/s^2).
    pub max_accel_m_s2: f64,
    /// Slack added to both bounds (m).
    pub tolerance_m: f64,
    /// A run of rejections this long ends in a new reference (ns).
    pub max_reject_run_ns: u64,
}

impl Default for PlausibleConfig {
    fn default() -> Self {
        Self {
            max_speed_m_s: DEFAULT_MAX_SPEED_M_S,
            max_accel_m_s2: DEFAULT_MAX_ACCEL_M_S2,
            tolerance_m: DEFAULT_TOLERANCE_M,
            max_reject_run_ns: DEFAULT_MAX_REJECT_RUN_NS,
        }
    }
}

impl PlausibleConfig {
    /// Checks that the limits are positive and finite, the tolerance finite
    /// and non-negative, and the run bound non-zero.
    pub fn validate(&self) -> Result<(), PlausibleError> {
        for (value, name) in [
            (self.max_speed_m_s, "max_speed_m_s"),
            (self.max_accel_m_s2, "max_accel_m_s2"),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(PlausibleError::Limit { name, value });
            }
        }
        if !(self.tolerance_m.is_finite() && self.tolerance_m >= 0.0) {
            return Err(PlausibleError::Tolerance(self.tolerance_m));
        }
        if self.max_reject_run_ns == 0 {
            return Err(PlausibleError::ZeroRun);
        }
        Ok(())
    }
}

/// What to do with a sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Plausible: use it.
    Accept,
    /// Implausible or non-finite: hold the last good pose.
    Reject,
    /// A run of rejections outlasted the bound and this finite sample is
    /// the new reference: use it, and ramp the force in again.
    Rereference,
    /// Non-finite samples for longer than the bound: stop the force.
    Lost,
}

/// The plausibility filter's state (fixed size, no heap).
#[derive(Clone, Debug)]
pub struct Plausible {
    cfg: PlausibleConfig,
    /// Accepted poses (t, p), a ring; `len` valid, newest at `head`.
    history: [(u64, V3); HISTORY],
    len: usize,
    head: usize,
    /// Start of the current run of rejections.
    run_start_ns: Option<u64>,
    rejected: u64,
    rereferences: u64,
}

impl Plausible {
    /// A filter with no reference yet: the first finite sample is accepted.
    /// An invalid configuration is replaced by the defaults (the caller
    /// validates first; this keeps the real-time path total).
    pub fn new(cfg: PlausibleConfig) -> Self {
        let cfg = if cfg.validate().is_ok() {
            cfg
        } else {
            PlausibleConfig::default()
        };
        Self {
            cfg,
            history: [(0, [0.0; 3]); HISTORY],
            len: 0,
            head: 0,
            run_start_ns: None,
            rejected: 0,
            rereferences: 0,
        }
    }

    /// The configuration in use.
    pub fn config(&self) -> &PlausibleConfig {
        &self.cfg
    }

    /// Samples rejected so far.
    pub fn rejected(&self) -> u64 {
        self.rejected
    }

    /// New references taken after a long run of rejections.
    pub fn rereferences(&self) -> u64 {
        self.rereferences
    }

    /// The last accepted pose (m), if any.
    pub fn last_good_m(&self) -> Option<V3> {
        (self.len > 0).then(|| self.history[self.head].1)
    }

    /// Judges the sample `p_m` read at `now_ns` (see the module
    /// documentation) and, when it is used, makes it the last good pose.
    pub fn check(&mut self, now_ns: u64, p_m: V3) -> Verdict {
        let finite = is_finite(p_m);
        if finite && self.len == 0 {
            self.accept(now_ns, p_m);
            return Verdict::Accept;
        }
        let off = if finite {
            self.deviation_m(now_ns, p_m)
        } else {
            None
        };
        if let Some(off) = off {
            // Plausible. After a run of rejections, a pose away from where
            // the hand was heading is a move that was hidden: ramp it in.
            let hidden_move = self.run_start_ns.is_some() && off > self.cfg.tolerance_m;
            if hidden_move {
                self.len = 0;
                self.rereferences += 1;
            }
            self.accept(now_ns, p_m);
            return if hidden_move {
                Verdict::Rereference
            } else {
                Verdict::Accept
            };
        }
        let start = *self.run_start_ns.get_or_insert(now_ns);
        let long = now_ns.saturating_sub(start) >= self.cfg.max_reject_run_ns;
        if long && finite {
            // The device really is elsewhere: start again from here.
            self.len = 0;
            self.accept(now_ns, p_m);
            self.rereferences += 1;
            return Verdict::Rereference;
        }
        self.rejected += 1;
        if long { Verdict::Lost } else { Verdict::Reject }
    }

    /// The distance of `p_m` from the constant-velocity prediction (m) when
    /// it lies inside the envelope, `None` when it does not.
    fn deviation_m(&self, now_ns: u64, p_m: V3) -> Option<f64> {
        let (t_g, p_g) = self.history[self.head];
        let dt = now_ns.saturating_sub(t_g) as f64 * 1e-9;
        let tol = self.cfg.tolerance_m;
        let moved = norm(sub(p_m, p_g));
        let predicted = add(p_g, scale(self.velocity_m_s(), dt));
        let off = norm(sub(p_m, predicted));
        (moved <= self.cfg.max_speed_m_s * dt + tol
            && off <= 0.5 * self.cfg.max_accel_m_s2 * dt * dt + tol)
            .then_some(off)
    }

    fn accept(&mut self, now_ns: u64, p_m: V3) {
        self.run_start_ns = None;
        self.head = if self.len == 0 {
            0
        } else {
            (self.head + 1) % HISTORY
        };
        self.history[self.head] = (now_ns, p_m);
        self.len = (self.len + 1).min(HISTORY);
    }

    /// The velocity over the accepted history (m/s): newest minus oldest
    /// over their time; zero with one pose, equal times, or a span longer
    /// than 50 ms.
    fn velocity_m_s(&self) -> V3 {
        if self.len < 2 {
            return [0.0; 3];
        }
        let oldest = (self.head + HISTORY + 1 - self.len) % HISTORY;
        let (t0, p0) = self.history[oldest];
        let (t1, p1) = self.history[self.head];
        let span = t1.saturating_sub(t0);
        if span == 0 || span > MAX_VELOCITY_SPAN_NS {
            return [0.0; 3];
        }
        scale(sub(p1, p0), 1e9 / span as f64)
    }
}

#[cfg(test)]
mod tests;
