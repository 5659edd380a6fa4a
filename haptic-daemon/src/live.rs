//! Live force samples only: a simulation that catches up after a stall (or
//! anything that replays old steps) delivers simulated time faster than
//! wall time, and those samples must not be rendered as live force.
//!
//! Pure: the arrival time (the haptic tick that received the sample, the
//! daemon's own clock) and the sample's `sim_time_ns` are passed in;
//! nothing allocates, nothing panics.
//!
//! # The rule
//!
//! Between consecutive received samples (accepted or not), simulated time
//! should not advance by more than `max_rate` (1.5) times the wall time
//! between their arrivals. Several samples can arrive in one tick and a
//! late step is followed by a quick one, so single pairs are not judged
//! alone: the excess of simulated over allowed time is accumulated, leaking
//! away while the stream runs at real rate,
//!
//! `excess = clamp(excess + d_sim - max_rate d_wall, 0, 2 allowance)`,
//!
//! and a sample is not live while `excess > allowance`, with `allowance =
//! slack_ns + one typical simulation step` (a running mean of `d_sim` over
//! live samples, at most 100 ms). A paced simulation at any rate, with a
//! step or two of catch-up after a slow step, stays under it; a
//! fast-forward at 6x (1.9 s of simulated time in 0.3 s) is caught within
//! `allowance / (6 - 1.5)` of wall time, and real-rate samples are live
//! again within `allowance / (max_rate - 1)` of wall time after it ends.
//!
//! After a gap in arrivals longer than `gap_ns` plus one typical step (the
//! simulation stopped),
//! the first sample cannot be judged (its `d_wall` is the whole gap): it is
//! held back until the next one shows the rate ([`Live::NotLive`]).
//! `sim_time_ns` going backwards (a restarted simulation) starts over.
//!
//! [`Live::Resumed`] marks the first live sample after samples that were
//! not: the daemon ramps the force in from what it was holding.

use thiserror::Error;

/// Default largest ratio of simulated to wall time.
pub const DEFAULT_MAX_RATE: f64 = 1.5;
/// Default slack on top of one simulation step (ns): 10 ms.
pub const DEFAULT_SLACK_NS: u64 = 10_000_000;
/// Default gap in arrivals after which the next sample waits for a second
/// one (ns): 50 ms, the safety filter's sample-age bound.
pub const DEFAULT_GAP_NS: u64 = 50_000_000;
/// The typical step counted into the allowance is at most this (ns).
const MAX_STEP_NS: f64 = 100_000_000.0;

/// A configuration that cannot work.
#[derive(Clone, Copy, Debug, Error, PartialEq)]
pub enum LiveError {
    /// The rate bound is not a finite number above 1.
    #[error("the sample rate bound must be a finite number > 1 (simulated / wall time), got {0}")]
    MaxRate(f64),
    /// A duration is zero.
    #[error("{0} must be longer than 0 ns")]
    ZeroDuration(&'static str),
}

/// The limits of a live stream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LiveConfig {
    /// Largest simulated / wall time ratio.
    pub max_rate: f64,
    /// Slack on top of one simulation step (ns).
    pub slack_ns: u64,
    /// A gap in arrivals this long, plus one typical simulation step, puts
    /// the next sample on probation (ns).
    pub gap_ns: u64,
}

impl Default for LiveConfig {
    fn default() -> Self {
        Self {
            max_rate: DEFAULT_MAX_RATE,
            slack_ns: DEFAULT_SLACK_NS,
            gap_ns: DEFAULT_GAP_NS,
        }
    }
}

impl LiveConfig {
    /// Checks the ratio (finite, > 1) and the durations (non-zero).
    pub fn validate(&self) -> Result<(), LiveError> {
        if !(self.max_rate.is_finite() && self.max_rate > 1.0) {
            return Err(LiveError::MaxRate(self.max_rate));
        }
        if self.slack_ns == 0 {
            return Err(LiveError::ZeroDuration("slack_ns"));
        }
        if self.gap_ns == 0 {
            return Err(LiveError::ZeroDuration("gap_ns"));
        }
        Ok(())
    }
}

/// The judgement of one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Live {
    /// At real rate: render it.
    Live,
    /// Faster than real time, or on probation after a gap: do not render.
    NotLive,
    /// Live again after samples that were not: render it, ramping in.
    Resumed,
}

/// The guard's state (fixed size, no heap).
#[derive(Clone, Debug)]
pub struct LiveGuard {
    cfg: LiveConfig,
    /// The previous sample: (arrival, simulated time).
    prev: Option<(u64, u64)>,
    excess_ns: f64,
    /// Running mean of the simulated time per live sample (ns).
    step_ns: Option<f64>,
    probation: bool,
    holding: bool,
    not_live: u64,
}

impl LiveGuard {
    /// A guard with no sample yet. An invalid configuration is replaced by
    /// the defaults (the caller validates first).
    pub fn new(cfg: LiveConfig) -> Self {
        let cfg = if cfg.validate().is_ok() {
            cfg
        } else {
            LiveConfig::default()
        };
        Self {
            cfg,
            prev: None,
            excess_ns: 0.0,
            step_ns: None,
            probation: false,
            holding: false,
            not_live: 0,
        }
    }

    /// The configuration in use.
    pub fn config(&self) -> &LiveConfig {
        &self.cfg
    }

    /// Samples judged not live so far.
    pub fn not_live(&self) -> u64 {
        self.not_live
    }

    /// Forgets the stream (a new simulation); the counter is kept.
    pub fn reset(&mut self) {
        *self = Self {
            not_live: self.not_live,
            ..Self::new(self.cfg)
        };
    }

    /// Judges a sample of simulated time `sim_time_ns` received at
    /// `arrival_ns` (see the module documentation).
    pub fn observe(&mut self, arrival_ns: u64, sim_time_ns: u64) -> Live {
        let verdict = self.judge(arrival_ns, sim_time_ns);
        self.prev = Some((arrival_ns, sim_time_ns));
        match verdict {
            Live::NotLive => {
                self.not_live += 1;
                self.holding = true;
                Live::NotLive
            }
            _ if self.holding => {
                self.holding = false;
                Live::Resumed
            }
            v => v,
        }
    }

    fn judge(&mut self, arrival_ns: u64, sim_time_ns: u64) -> Live {
        let Some((prev_arrival, prev_sim)) = self.prev else {
            return Live::Live;
        };
        if sim_time_ns < prev_sim {
            // A restarted simulation: judge it afresh.
            let not_live = self.not_live;
            let holding = self.holding;
            *self = Self::new(self.cfg);
            self.not_live = not_live;
            self.holding = holding;
            return Live::Live;
        }
        let d_wall = arrival_ns.saturating_sub(prev_arrival);
        let d_sim = (sim_time_ns - prev_sim) as f64;
        let step_ns = self.step_ns.unwrap_or(d_sim.min(MAX_STEP_NS));
        if d_wall as f64 > self.cfg.gap_ns as f64 + step_ns {
            // The stream stopped: this sample's rate is unknown.
            self.excess_ns = 0.0;
            self.probation = true;
            return Live::NotLive;
        }
        let allowance = self.cfg.slack_ns as f64 + step_ns;
        self.excess_ns = (self.excess_ns + d_sim - self.cfg.max_rate * d_wall as f64)
            .clamp(0.0, 2.0 * allowance);
        if self.excess_ns > allowance {
            return Live::NotLive;
        }
        if self.probation {
            // The sample after a gap: live only if this pair was at real rate.
            self.probation = false;
            if d_sim > self.cfg.max_rate * d_wall as f64 + self.cfg.slack_ns as f64 {
                self.probation = true;
                return Live::NotLive;
            }
        }
        let d = d_sim.min(MAX_STEP_NS);
        self.step_ns = Some(self.step_ns.map_or(d, |s| s + (d - s) / 8.0));
        Live::Live
    }
}

#[cfg(test)]
mod tests;
