//! Time-domain passivity observer and controller: B. Hannaford and J.-H.
//! Ryu, "Time-domain passivity control of haptic interfaces", IEEE
//! Transactions on Robotics and Automation 18(1):1-10, 2002.
//!
//! The rendered environment (simulation, extrapolation, sampling) is a
//! one-port between the device and the hand. A sampled spring, a late
//! sample, an extrapolator that overshoots: each can make it give more
//! energy back than it received, which the hand feels as buzz or
//! instability.
//!
//! # Observer
//!
//! Per tick the force applied over the last interval (the previous output,
//! held by the device) times the device motion over it:
//! `E += F_prev . (x - x_prev)`. Sign: positive `E` is energy the
//! environment has *generated*, delivered into the hand (a passive
//! environment keeps `E <= 0`).
//!
//! # Controller
//!
//! While `E > tolerance_j`, a damping force `-alpha v` is added along the
//! motion, `v = (x - x_prev) / dt`, with
//! `alpha = (E - tolerance_j) / (|v|^2 dt)` (the damping that dissipates
//! the excess over the next interval at the current velocity), bounded by
//! `max_damping_n_s_per_m` (the device's stable damping). The dissipated
//! energy shows in the observer through the applied force on the next
//! tick, as in the paper.
//!
//! In free space (no force applied or requested) nothing is stored in the
//! environment and `E` restarts from zero, so a long session's dissipation
//! (negative `E`) cannot mask a later leak, and energy leaked in one contact
//! is not charged to the next one.

use crate::math::{V3, ZERO, dot, norm, scale, sub};
use thiserror::Error;

/// Default energy tolerance (J): 1 mJ, a tenth of what a 300 N/m contact
/// stores 8 mm deep, and above the leak of a spring sampled at 1 kHz over a
/// slow press (`k dx^2 / 2` per tick).
pub const DEFAULT_TOLERANCE_J: f64 = 1e-3;
/// Default largest controller damping (N s/m): 5 N s/m, the order of the
/// nominal maximum damping of a Touch-class device (OpenHaptics'
/// `HD_NOMINAL_MAX_DAMPING`); larger devices render more.
pub const DEFAULT_MAX_DAMPING_N_S_PER_M: f64 = 5.0;
/// Below this force (N) the environment counts as free space.
const FREE_SPACE_N: f64 = 1e-6;

/// A passivity configuration that cannot work.
#[derive(Clone, Copy, Debug, Error, PartialEq)]
pub enum PassivityError {
    /// The tolerance is negative or not finite.
    #[error("the passivity energy tolerance must be a finite number >= 0 J, got {0}")]
    Tolerance(f64),
    /// The damping bound is negative or not finite.
    #[error("the passivity damping bound must be a finite number >= 0 N s/m, got {0}")]
    MaxDamping(f64),
}

/// The observer/controller's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PassivityConfig {
    /// Observe and control (off: the filter adds no damping).
    pub enabled: bool,
    /// Generated energy tolerated before damping (J).
    pub tolerance_j: f64,
    /// Largest damping the controller adds (N s/m).
    pub max_damping_n_s_per_m: f64,
}

impl Default for PassivityConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            tolerance_j: DEFAULT_TOLERANCE_J,
            max_damping_n_s_per_m: DEFAULT_MAX_DAMPING_N_S_PER_M,
        }
    }
}

impl PassivityConfig {
    /// Off.
    pub const OFF: Self = Self {
        enabled: false,
        tolerance_j: DEFAULT_TOLERANCE_J,
        max_damping_n_s_per_m: DEFAULT_MAX_DAMPING_N_S_PER_M,
    };

    /// Checks that the tolerance and the damping bound are finite and
    /// non-negative.
    pub fn validate(&self) -> Result<(), PassivityError> {
        if !(self.tolerance_j.is_finite() && self.tolerance_j >= 0.0) {
            return Err(PassivityError::Tolerance(self.tolerance_j));
        }
        if !(self.max_damping_n_s_per_m.is_finite() && self.max_damping_n_s_per_m >= 0.0) {
            return Err(PassivityError::MaxDamping(self.max_damping_n_s_per_m));
        }
        Ok(())
    }
}

/// The observer's state (fixed size, no heap).
#[derive(Clone, Debug)]
pub struct Passivity {
    cfg: PassivityConfig,
    energy_j: f64,
    prev_m: Option<V3>,
    velocity_m_s: V3,
    active_ticks: u64,
    dissipated_j: f64,
}

impl Passivity {
    /// An observer with no motion seen. An invalid configuration turns it
    /// off (the caller validates first).
    pub fn new(cfg: PassivityConfig) -> Self {
        let cfg = if cfg.validate().is_ok() {
            cfg
        } else {
            PassivityConfig::OFF
        };
        Self {
            cfg,
            energy_j: 0.0,
            prev_m: None,
            velocity_m_s: ZERO,
            active_ticks: 0,
            dissipated_j: 0.0,
        }
    }

    /// The configuration in use.
    pub fn config(&self) -> &PassivityConfig {
        &self.cfg
    }

    /// The observed generated energy (J; positive: generated).
    pub fn energy_j(&self) -> f64 {
        self.energy_j
    }

    /// Ticks on which the controller added damping.
    pub fn active_ticks(&self) -> u64 {
        self.active_ticks
    }

    /// Energy the controller set out to dissipate (J, sum of the excesses).
    pub fn dissipated_j(&self) -> f64 {
        self.dissipated_j
    }

    /// Forgets the previous position (the device was re-referenced: its
    /// jump is not motion under the force).
    pub fn rebase(&mut self) {
        self.prev_m = None;
        self.velocity_m_s = ZERO;
    }

    /// Observes the motion to `x_m` over `dt_ns` under the force applied
    /// since the previous call, `applied_n`; `requested_n` is this tick's
    /// request (for the free-space reset). Non-finite positions are ignored.
    pub fn observe(&mut self, x_m: V3, dt_ns: u64, applied_n: V3, requested_n: V3) {
        if !self.cfg.enabled || !x_m.iter().all(|v| v.is_finite()) {
            return;
        }
        let prev = self.prev_m.replace(x_m);
        let Some(prev) = prev else {
            return;
        };
        let dx = sub(x_m, prev);
        let work = dot(applied_n, dx);
        if work.is_finite() {
            self.energy_j += work;
        }
        self.velocity_m_s = if dt_ns > 0 {
            scale(dx, 1e9 / dt_ns as f64)
        } else {
            ZERO
        };
        let requesting = norm(requested_n) > FREE_SPACE_N;
        if norm(applied_n) <= FREE_SPACE_N && !requesting {
            self.energy_j = 0.0;
        }
    }

    /// The controller's damping force for the next interval of `dt_ns`
    /// (N): zero while the observed energy is within the tolerance.
    pub fn damping_n(&mut self, dt_ns: u64) -> V3 {
        let excess = self.energy_j - self.cfg.tolerance_j;
        if !self.cfg.enabled || excess.is_nan() || excess <= 0.0 || dt_ns == 0 {
            return ZERO;
        }
        let v = self.velocity_m_s;
        let v2 = dot(v, v);
        let alpha_max = self.cfg.max_damping_n_s_per_m;
        let alpha = if v2 > 0.0 {
            (excess / (v2 * dt_ns as f64 * 1e-9)).min(alpha_max)
        } else {
            alpha_max
        };
        if alpha.is_nan() || alpha <= 0.0 || v2 == 0.0 {
            return ZERO;
        }
        self.active_ticks += 1;
        self.dissipated_j += alpha * v2 * dt_ns as f64 * 1e-9;
        scale(v, -alpha)
    }
}

#[cfg(test)]
mod tests;
