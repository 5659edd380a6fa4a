//! Force extrapolators (paper section 7, "Force extrapolation", and the
//! local model of "Beyond the paper").
//!
//! The simulation sends force samples at ~30 Hz-1 kHz; the haptic loop needs
//! a force at 1-10 kHz. An [`Extrapolator`] keeps the last two accepted
//! samples (fixed size, no allocation) and evaluates the chosen [`Method`]
//! at the haptic loop's time and tool position. Time is passed in, never
//! read here, so tests drive it.
//!
//! # Degenerate cases (every method)
//!
//! - No sample yet: zero force.
//! - [`Extrapolator::push`] ignores a sample with a non-finite field or a
//!   `seq` not newer than the latest accepted one; the previous samples are
//!   kept. So stored samples are always finite.
//! - One sample only: the two-sample methods (linear in time, linear in
//!   position, signed) give the constant force `F_n`; the local model needs
//!   only the latest sample and applies.
//! - Linear in time: equal or decreasing sample times give `F_n`; the time
//!   factor is clamped to `[0, 1]` ([`MAX_TIME_FACTOR`]): a query before
//!   `t_n` gives `F_n`, a query more than one period after `t_n` holds
//!   the value one period ahead (staleness is the safety filter's watchdog's
//!   business).
//! - Linear in position (both forms): `|P_n - P_n-1| < MIN_STEP_M` (1 nm)
//!   gives `F_n`; the factor is clamped to `[-2, 2]` (signed) or `[0, 2]`
//!   (paper) ([`MAX_POSITION_FACTOR`]).
//! - Local model: a sample not in contact counts as zero stiffness, i.e.
//!   `F_n`. The stiffness is capped at [`Extrapolator::with_max_stiffness`]
//!   (the device's renderable maximum; no cap by default) and the result is
//!   made unilateral ([`local`]): it never pulls along the contact normal
//!   `F_n / |F_n|` and releases to exactly zero when the tool leaves. The
//!   displacement is not capped (the safety filter clamps the magnitude).
//! - A sample flagged `catching_up` (the simulated tool lags the hand):
//!   `F_n`, whatever the method.
//! - Any method whose result is not finite (a NaN or infinite query
//!   position, or an overflow from huge but finite samples) gives `F_n`,
//!   which is finite because only finite samples are stored. Hence
//!   [`Extrapolator::force`] is always finite.
//!
//! Bound: with `|factor| <= 2`, the two-sample methods give
//! `|F| <= 3 |F_n| + 2 |F_n-1|`, and the local model
//! `|F| <= |F_n| + min(|K|_2, cap) |P_n - P|` (the unilateral projection
//! only shortens the force).

mod formulas;
pub mod local;
pub mod local_problem;

pub use formulas::{
    MAX_POSITION_FACTOR, MAX_TIME_FACTOR, MIN_STEP_M, linear, local_model, paper_position_factor,
    signed_position_factor, time_factor,
};

pub use local::{
    MIN_NORMAL_FORCE_N, cap_stiffness, local_model_unilateral, local_normal_unilateral, unilateral,
};

use crate::math::{M3, V3, ZERO, is_finite, is_finite_m3};

/// One force sample from the simulation (tool 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceSample {
    /// Simulation time of the step (ns, same clock as the haptic loop).
    pub t_ns: u64,
    /// The simulation's sample counter (strictly increasing).
    pub seq: u64,
    /// Tool position the step used (m).
    pub position_m: V3,
    /// Force on the tool (N).
    pub force_n: V3,
    /// Contact stiffness, row-major: dF = -K dP (N/m).
    pub stiffness_n_per_m: M3,
    /// The tool touched the tissue in this step.
    pub in_contact: bool,
    /// The simulated tool was not at the pose asked for and did not follow
    /// the hand one for one (protocol flag `CATCHING_UP`): every method
    /// renders the sample's force as it is.
    pub catching_up: bool,
}

impl ForceSample {
    /// Tool `tool`'s sample in a force message (the only conversion from
    /// the wire to the extrapolators: the daemon and hapbench both use it);
    /// `None` past the message's tools.
    pub fn from_wire(msg: &shared::protocol::ForceMsg, tool: usize) -> Option<Self> {
        let n = (msg.tool_count as usize).min(shared::protocol::MAX_TOOLS);
        (tool < n).then(|| {
            let t = &msg.tools[tool];
            Self {
                t_ns: msg.t_ns,
                seq: msg.seq,
                position_m: t.position_m,
                force_n: t.force_n,
                stiffness_n_per_m: t.stiffness_n_per_m,
                in_contact: t.flags & shared::protocol::CONTACT != 0,
                catching_up: t.flags & shared::protocol::CATCHING_UP != 0,
            }
        })
    }

    /// Every floating-point field is finite.
    pub fn is_finite(&self) -> bool {
        is_finite(self.position_m)
            && is_finite(self.force_n)
            && is_finite_m3(&self.stiffness_n_per_m)
    }
}

/// An extrapolation method (`--extrapolation`: the names of [`Method::name`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// `F = F_n` (zero-order hold).
    Constant,
    /// Linear in time (eq 31).
    LinearTime,
    /// Linear in position as the paper writes it (eq 32, ratio of norms).
    LinearPosition,
    /// Linear in position with the signed factor.
    LinearPositionSigned,
    /// `F = F_n + K (P_n - P)` with the sample's contact stiffness.
    LocalModel,
    /// The local model along the contact normal only (a virtual plane):
    /// `F = F_n + n (n^T K n) n.(P_n - P)`, `n = F_n / |F_n|`. Sliding
    /// along the surface changes nothing (frictionless contact keeps its
    /// force while the dimple travels with the tool), pressing and
    /// withdrawing follow the contact's true normal stiffness.
    LocalNormal,
    /// The simulation's contact problem around the tool, stepped again at
    /// each tick ([`local_problem`]: the surface near the tool, its contact
    /// springs, the tissue's compliance and inertia, sent at most every
    /// 8 ms on the `local-contact` stream); the daemon's default. Without a
    /// problem (none received yet, a tool with friction or gripping, a
    /// backend or mesh that cannot give one) it renders as
    /// [`Method::LocalNormal`].
    LocalProblem,
}

impl Method {
    /// Every method, in telemetry code order.
    pub const ALL: [Method; 7] = [
        Method::Constant,
        Method::LinearTime,
        Method::LinearPosition,
        Method::LinearPositionSigned,
        Method::LocalModel,
        Method::LocalNormal,
        Method::LocalProblem,
    ];

    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Method::Constant => "constant",
            Method::LinearTime => "linear-time",
            Method::LinearPosition => "linear-position",
            Method::LinearPositionSigned => "linear-position-signed",
            Method::LocalModel => "local-model",
            Method::LocalNormal => "local-normal",
            Method::LocalProblem => "local-problem",
        }
    }

    /// The method with this exact command-line name (as `--extrapolation`
    /// parses it; a test checks that it gives back every [`Method::name`]).
    pub fn parse(s: &str) -> Option<Method> {
        <Method as clap::ValueEnum>::from_str(s, false).ok()
    }
}

/// Extrapolates the last two accepted samples with one method.
#[derive(Clone, Copy, Debug)]
pub struct Extrapolator {
    method: Method,
    /// Cap on the local model's stiffness (N/m; infinite: none).
    max_stiffness_n_per_m: f64,
    prev: Option<ForceSample>,
    last: Option<ForceSample>,
}

impl Extrapolator {
    /// No sample yet, no stiffness cap.
    pub fn new(method: Method) -> Self {
        Self {
            method,
            max_stiffness_n_per_m: f64::INFINITY,
            prev: None,
            last: None,
        }
    }

    /// The same with the local model's stiffness capped at
    /// `max_stiffness_n_per_m` (N/m, spectral norm; see [`cap_stiffness`]).
    /// A cap that is not a positive number means no cap.
    pub fn with_max_stiffness(mut self, max_stiffness_n_per_m: f64) -> Self {
        self.max_stiffness_n_per_m = if max_stiffness_n_per_m > 0.0 {
            max_stiffness_n_per_m
        } else {
            f64::INFINITY
        };
        self
    }

    /// The local model's stiffness cap (N/m; infinite: none).
    pub fn max_stiffness_n_per_m(&self) -> f64 {
        self.max_stiffness_n_per_m
    }

    /// The method.
    pub fn method(&self) -> Method {
        self.method
    }

    /// Accepts `s` as the latest sample, unless a field is non-finite or
    /// `s.seq` is not greater than the latest accepted `seq` (a duplicate or
    /// a reordered message): then `s` is ignored and the stored samples are
    /// kept. A simulation that restarts its counter must be announced with
    /// [`Extrapolator::reset`].
    pub fn push(&mut self, s: &ForceSample) {
        if !s.is_finite() {
            return;
        }
        if self.last.is_some_and(|l| s.seq <= l.seq) {
            return;
        }
        self.prev = self.last;
        self.last = Some(*s);
    }

    /// Forgets every sample (a new simulation, whose `seq` starts again).
    pub fn reset(&mut self) {
        self.prev = None;
        self.last = None;
    }

    /// The latest accepted sample.
    pub fn latest(&self) -> Option<&ForceSample> {
        self.last.as_ref()
    }

    /// The force at `now_ns` for the tool at `position_m` (N). Always
    /// finite; see the module documentation for the degenerate cases.
    pub fn force(&self, now_ns: u64, position_m: V3) -> V3 {
        let Some(last) = self.last.as_ref() else {
            return ZERO;
        };
        let f_n = last.force_n;
        let f = match (self.method, self.prev.as_ref()) {
            // Where the simulated tool is not where the hand asked, the
            // hand's motion from the sample's position is not the tool's:
            // extrapolating across that gap renders contact the simulation
            // does not have (a tool coming back to a still hand: 1.5 N
            // rendered against the simulation's 0 to 1 N).
            _ if last.catching_up => f_n,
            (Method::Constant, _) => f_n,
            (Method::LocalModel, _) if last.in_contact => local_model_unilateral(
                f_n,
                &last.stiffness_n_per_m,
                self.max_stiffness_n_per_m,
                last.position_m,
                position_m,
            ),
            (Method::LocalModel, _) => f_n,
            (Method::LocalNormal | Method::LocalProblem, _) if last.in_contact => {
                local_normal_unilateral(
                    f_n,
                    &last.stiffness_n_per_m,
                    self.max_stiffness_n_per_m,
                    last.position_m,
                    position_m,
                )
            }
            (Method::LocalNormal | Method::LocalProblem, _) => f_n,
            (_, None) => f_n,
            (Method::LinearTime, Some(prev)) => time_factor(prev.t_ns, last.t_ns, now_ns)
                .map_or(f_n, |k| linear(prev.force_n, f_n, k)),
            (Method::LinearPosition, Some(prev)) => {
                paper_position_factor(prev.position_m, last.position_m, position_m)
                    .map_or(f_n, |k| linear(prev.force_n, f_n, k))
            }
            (Method::LinearPositionSigned, Some(prev)) => {
                signed_position_factor(prev.position_m, last.position_m, position_m)
                    .map_or(f_n, |k| linear(prev.force_n, f_n, k))
            }
        };
        // Overflow of huge samples or a non-finite query position: hold the
        // (finite) latest force rather than let NaN or inf out.
        if is_finite(f) { f } else { f_n }
    }
}

#[cfg(test)]
mod tests;
