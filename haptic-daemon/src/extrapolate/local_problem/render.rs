//! [`LocalProblem::render`]: the force at the hand from the newest sample
//! and the problem solved (or stepped) for the tool's position, re-based
//! on a sample newer than the problem, capped.

use super::{CHANGE_OF_STIFFNESS, LocalProblem, MAX_AGE_NS, MAX_TOOL_SPEED_M_S, RELEASE_SHARE};
use crate::extrapolate::ForceSample;
use crate::math::{V3, ZERO, add, dot, mat_vec, norm, scale, spectral_norm, sub};

/// Whether the tool at `tool_m` is still in the newest sample's contact:
/// the sample touches with a force, and the tool has moved out along that
/// force by less than [`RELEASE_SHARE`] of the distance at which the
/// sample's linearisation lets go (`|F| / k_n`, `k_n = n^T K n`; without a
/// stiffness, not out at all).
fn hand_still_in_contact(latest: &ForceSample, tool_m: V3) -> bool {
    let f = norm(latest.force_n);
    if !latest.in_contact || f <= 0.0 || !f.is_finite() {
        return false;
    }
    let n = scale(latest.force_n, 1.0 / f);
    let out_m = dot(sub(tool_m, latest.position_m), n);
    let k_n = dot(n, mat_vec(&latest.stiffness_n_per_m, n));
    if k_n > 0.0 {
        out_m < RELEASE_SHARE * f / k_n
    } else {
        out_m <= 0.0
    }
}

/// The tool's last two positions given (renders and catch-up steps) at
/// distinct times (ns), the newer second: its speed.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct ToolTrack {
    positions: [Option<(u64, V3)>; 2],
}

impl ToolTrack {
    /// Keeps the tool's position at `t_ns` (one older than the newest kept
    /// is not kept).
    pub(super) fn keep(&mut self, t_ns: u64, tool_m: V3) {
        match self.positions[1] {
            Some((t, _)) if t == t_ns => self.positions[1] = Some((t, tool_m)),
            Some((t, _)) if t > t_ns => {}
            _ => self.positions = [self.positions[1], Some((t_ns, tool_m))],
        }
    }

    /// Whether the tool at `tool_m` at `now_ns` moves faster than
    /// [`MAX_TOOL_SPEED_M_S`] since the last position kept before then.
    pub(super) fn too_fast(&self, now_ns: u64, tool_m: V3) -> bool {
        let before = match self.positions {
            [_, Some((t, x))] if t < now_ns => Some((t, x)),
            [Some((t, x)), _] if t < now_ns => Some((t, x)),
            _ => None,
        };
        before.is_some_and(|(t_ns, at_m)| {
            norm(sub(tool_m, at_m)) > MAX_TOOL_SPEED_M_S * (now_ns - t_ns) as f64 * 1e-9
        })
    }
}

impl LocalProblem {
    /// The force to render (N) at `now_ns` with the tool at `tool_m`,
    /// `latest` being the newest force sample (taken at the problem's step
    /// or after it): the sample's force plus the change of the points'
    /// force on the tool from the sample to `tool_m`; zero when no point
    /// touches the tool there. `None` (the caller falls back to another
    /// method) also when the tool moves faster than
    /// [`super::MAX_TOOL_SPEED_M_S`]. Quasi-static, the change is from the
    /// sample's position; with inertia ([`LocalProblem::set_inertia`]) each
    /// call is a time step of the problem from its own step on, and the
    /// change is from where the problem was at the sample's `t_ns` (its
    /// ticks' history, interpolated). The change is capped at
    /// `max_stiffness_n_per_m` times the tool's distance from the sample's
    /// position (the secant stiffness a device renders stably; infinite:
    /// no cap), and in contact at [`CHANGE_OF_STIFFNESS`] times the
    /// sample's contact stiffness, direction kept. `None` without a
    /// problem or when a solve fails (the caller falls back to another
    /// method).
    pub fn render(
        &mut self,
        latest: &ForceSample,
        now_ns: u64,
        tool_m: V3,
        max_stiffness_n_per_m: f64,
    ) -> Option<V3> {
        // A problem newer than the sample (a restarted simulation) or
        // much older (the simulation stopped sending them) says nothing
        // about it; nor does any while the simulated tool lags the hand
        // (the sample is rendered as it is).
        if !self.ready
            || latest.catching_up
            || latest.seq < self.seq
            || latest.t_ns.saturating_sub(self.t_ns) > MAX_AGE_NS
        {
            return None;
        }
        // The tool's speed since the last position the problem was given
        // (this tick's is rendered from the sample if it is too fast; the
        // problem is stepped all the same, so that it goes on from the
        // hand's path when the tool slows).
        let too_fast = self.track.too_fast(now_ns, tool_m);
        self.track.keep(now_ns, tool_m);
        // One budget for the whole tick.
        self.budget.begin(true);
        // Quasi-static, the base first (its solve moves the warm start);
        // with inertia after this tick's step, which the history then has.
        let inertia = !self.inertia.m_red.is_empty();
        let early = if inertia {
            None
        } else {
            Some(self.base_for(latest)?)
        };
        let (change, touching) = self.solve_within_budget(tool_m)?;
        if inertia {
            self.history.remember(now_ns, change);
        }
        let base = match early {
            Some(base) => base,
            None => self.base_for(latest)?,
        };
        if too_fast {
            return None;
        }
        if !touching {
            // A release the hand did not make is the problem's, not the
            // tissue's: its few vertices, stepped with their condensed
            // mass, bounce off the tool for ~10 ms while the tissue stays
            // on it (0 N rendered against the simulation's 0.3-0.4 N).
            // Then the sample's own linearisation renders instead.
            if hand_still_in_contact(latest, tool_m) {
                return None;
            }
            return Some(ZERO);
        }
        let mut d = sub(change, base);
        // In contact, the change is also held to CHANGE_OF_STIFFNESS times
        // the contact's own stiffness: a problem that snaps (a dragged
        // vertex slipping around the tool, at once where the damped tissue
        // follows some 15 ms later) would jump far faster than the contact
        // stiffens; onsets (no stiffness yet) are not held.
        let contact = spectral_norm(&latest.stiffness_n_per_m);
        let cap = if latest.in_contact && contact > 0.0 {
            max_stiffness_n_per_m.min(CHANGE_OF_STIFFNESS * contact)
        } else {
            max_stiffness_n_per_m
        };
        let limit = cap * norm(sub(tool_m, latest.position_m));
        let size = norm(d);
        if size > limit {
            d = scale(d, limit / size);
        }
        Some(add(latest.force_n, d))
    }

    /// Where the problem puts sample `latest` (the points' force change
    /// there), once per sample: zero for the problem's own sample;
    /// quasi-static, the problem solved at the sample's position; with
    /// inertia, where the stepped problem was at the sample's `t_ns`.
    fn base_for(&mut self, latest: &ForceSample) -> Option<V3> {
        if let Some((seq, base)) = self.base
            && seq == latest.seq
        {
            return Some(base);
        }
        let base = if latest.seq == self.seq {
            ZERO
        } else if self.inertia.m_red.is_empty() {
            self.solve_within_budget(latest.position_m)?.0
        } else {
            self.history.change_at(latest.t_ns, self.t_ns)?
        };
        self.base = Some((latest.seq, base));
        Some(base)
    }
}
