//! The simulated tool (the proxy) follows the pose the device asks for no
//! faster and no more abruptly than a hand can move: a pose that jumps (a
//! glitch, a re-homed device, a client that starts mid-air) drags the
//! proxy along a bounded path instead of teleporting it through or into
//! the tissue. A god-object in the sense of Zilles and Salisbury (1995),
//! reduced to what a compliant contact needs: the contact keeps the proxy
//! out of the tissue, the proxy keeps it from tunnelling, and where tissue
//! slips past the tip all the same, [`crate::contact::surface::crossing`] puts the
//! proxy back outside ([`Proxy::stop_at`]).
//!
//! Each step the proxy heads for the requested tip at the speed that
//! reaches it this step, no faster than `max_speed_m_s`, no faster than it
//! can still stop by the target (sqrt(2 a d)), and changing its velocity
//! by at most `max_accel_m_s2 * dt`. A hand moving at v follows with a lag
//! of at most v^2 / (2 a) (0.05 mm at 0.1 m/s and 100 m/s^2).
//!
//! Near the tissue a proxy that is catching up (coming in from its fulcrum
//! after a let-go, following a jump) moves no faster than the hand itself
//! plus an entry speed ([`Proxy::slow_to`]; the tool decides when, from
//! the surface ahead, in `tool/approach.rs`): a still hand whose tool
//! comes back must not feel the tool hit the tissue at the speed limit (the
//! liver, held at 0.146 N, took a 1.08 N blow and rang for a second), while
//! a hand that moves is followed as before. The hand's speed is the
//! target's over the last 40 ms ([`HAND_WINDOW_S`]).

use crate::math::{Real, Vec3};

/// How much further than a followed hand's braking lag the proxy may be
/// from its target and still count as following it (m).
pub const TRACKING_SLACK_M: Real = 1e-4;
/// The hand's speed is measured over this much simulated time (s).
pub const HAND_WINDOW_S: Real = 0.04;

/// A rate-limited follower of the requested tool tip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Proxy {
    at_m: Option<Vec3>,
    velocity_m_s: Vec3,
    max_speed_m_s: Real,
    max_accel_m_s2: Real,
    /// Near the tissue, at most this much faster than the hand (m/s).
    entry_speed_m_s: Real,
    /// Where and how fast the proxy was before the last step (for
    /// [`Proxy::slow_to`]).
    before: (Option<Vec3>, Vec3),
    /// The last step's target and start.
    target_m: Vec3,
    start_m: Vec3,
    /// Where the target was, every quarter of [`HAND_WINDOW_S`] (oldest
    /// first), and the simulated time (s).
    marks: [(Vec3, Real); 4],
    marked: usize,
    clock_s: Real,
}

impl Proxy {
    /// A proxy not yet placed, following at most `max_speed_m_s` and
    /// `max_accel_m_s2`, and near the tissue at most `entry_speed_m_s`
    /// faster than the hand.
    pub fn new(max_speed_m_s: Real, max_accel_m_s2: Real, entry_speed_m_s: Real) -> Self {
        Self {
            at_m: None,
            velocity_m_s: Vec3::ZERO,
            max_speed_m_s,
            max_accel_m_s2,
            entry_speed_m_s,
            before: (None, Vec3::ZERO),
            target_m: Vec3::ZERO,
            start_m: Vec3::ZERO,
            marks: [(Vec3::ZERO, 0.0); 4],
            marked: 0,
            clock_s: 0.0,
        }
    }

    /// The tool was withdrawn: the next pose starts afresh (from a still
    /// hand).
    pub fn reset(&mut self) {
        *self = Self::new(
            self.max_speed_m_s,
            self.max_accel_m_s2,
            self.entry_speed_m_s,
        );
    }

    /// Where the proxy is after a step of `dt_s` towards `target_m`,
    /// starting from `start_m` if it was not placed.
    pub fn follow(&mut self, target_m: Vec3, start_m: Vec3, dt_s: Real) -> Vec3 {
        self.clock_s += dt_s;
        self.mark(target_m);
        self.before = (self.at_m, self.velocity_m_s);
        self.target_m = target_m;
        self.start_m = start_m;
        self.advance(dt_s, self.max_speed_m_s)
    }

    /// Keeps where the target is every quarter window.
    fn mark(&mut self, target_m: Vec3) {
        let quarter_s = 0.25 * HAND_WINDOW_S;
        if self.marked > 0 && self.clock_s - self.marks[self.marked - 1].1 < quarter_s {
            return;
        }
        if self.marked == self.marks.len() {
            self.marks.rotate_left(1);
            self.marked -= 1;
        }
        self.marks[self.marked] = (target_m, self.clock_s);
        self.marked += 1;
    }

    /// The hand's speed (m/s): how far the target is from where it was
    /// about `HAND_WINDOW_S` ago, over that time. Not its speed over a
    /// step: a pose published slower than the simulation steps moves in
    /// jumps, and one that jumps away and back is not a hand that moved.
    pub fn hand_speed_m_s(&self) -> Real {
        if self.marked == 0 {
            return 0.0;
        }
        let (then_m, t_s) = self.marks[0];
        let age_s = self.clock_s - t_s;
        if age_s > 0.0 {
            self.target_m.distance(then_m) / age_s
        } else {
            0.0
        }
    }

    /// The proxy's speed over the last step (m/s).
    pub fn speed_m_s(&self) -> Real {
        self.velocity_m_s.length()
    }

    /// How far the proxy is from the target of the last step (m).
    pub fn lag_m(&self) -> Real {
        self.at_m.map_or(0.0, |at| at.distance(self.target_m))
    }

    /// Whether the proxy is further from its target than it would be
    /// following it: a proxy following a hand, or braking onto a target
    /// that stopped, is at most v^2 / (2 a) behind at its speed v (plus
    /// `TRACKING_SLACK_M`); further, it is catching up (after a let-go or
    /// a jump) or was stopped short.
    pub fn catching_up(&self) -> bool {
        let v = self.speed_m_s();
        self.lag_m() > v * v / (2.0 * self.max_accel_m_s2) + TRACKING_SLACK_M
    }

    /// How fast the proxy may move near the tissue (m/s): the hand's
    /// speed plus the entry speed.
    pub fn near_tissue_speed_m_s(&self) -> Real {
        self.hand_speed_m_s() + self.entry_speed_m_s
    }

    /// The speed from which the proxy can still slow to
    /// [`Proxy::near_tissue_speed_m_s`] within `distance_m` (m/s).
    pub fn approach_speed_m_s(&self, distance_m: Real) -> Real {
        let v = self.near_tissue_speed_m_s();
        (v * v + 2.0 * self.max_accel_m_s2 * distance_m.max(0.0)).sqrt()
    }

    /// How far the proxy needs to slow from its speed to
    /// [`Proxy::near_tissue_speed_m_s`] (m).
    pub fn braking_distance_m(&self) -> Real {
        let (v, c) = (self.speed_m_s(), self.near_tissue_speed_m_s());
        ((v * v - c * c) / (2.0 * self.max_accel_m_s2)).max(0.0)
    }

    /// The last step taken again no faster than `limit_m_s` (it still
    /// changes the velocity by at most the acceleration limit); where the
    /// proxy then is.
    pub fn slow_to(&mut self, limit_m_s: Real, dt_s: Real) -> Vec3 {
        (self.at_m, self.velocity_m_s) = self.before;
        self.advance(dt_s, limit_m_s.min(self.max_speed_m_s))
    }

    /// A step of `dt_s` towards the target at most `max_speed_m_s`.
    fn advance(&mut self, dt_s: Real, max_speed_m_s: Real) -> Vec3 {
        let at = self.at_m.unwrap_or(self.start_m);
        let e = self.target_m - at;
        let dist = e.length();
        let (a, v) = (self.max_accel_m_s2, self.velocity_m_s);
        let want = if dist > 0.0 {
            let speed = (dist / dt_s)
                .min((2.0 * a * dist).sqrt())
                .min(max_speed_m_s);
            e * (speed / dist)
        } else {
            Vec3::ZERO
        };
        let v_new = v + (want - v).clamp_length_max(a * dt_s);
        let mut step = v_new * dt_s;
        // Never past the target along the way to it.
        if dist > 0.0 && step.dot(e) > dist * dist {
            step = e;
        }
        let next = at + step;
        self.velocity_m_s = step / dt_s;
        self.at_m = Some(next);
        next
    }

    /// The step that [`Proxy::follow`] just took ends at `at_m` instead
    /// (the tissue's surface stopped it on the way from `from_m`): the
    /// proxy keeps only the motion it made.
    pub fn stop_at(&mut self, at_m: Vec3, from_m: Vec3, dt_s: Real) {
        self.velocity_m_s = (at_m - from_m) / dt_s;
        self.at_m = Some(at_m);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn follows_a_hand_closely_and_a_glitch_boundedly() {
        let dt = 1e-3;
        let mut p = Proxy::new(1.0, 100.0, 0.05);
        // A hand at 0.1 m/s along x, after it got going: within 0.1 mm.
        let mut lag: Real = 0.0;
        for k in 0..500 {
            let hand = Vec3::new(0.1 * k as Real * dt, 0.0, 0.0);
            let at = p.follow(hand, Vec3::ZERO, dt);
            if k > 50 {
                lag = lag.max((hand - at).length());
            }
        }
        assert!(lag < 1e-4, "lag {lag}");
        // A 5 ms glitch 1 m away and back: the proxy strays a few mm at
        // most and comes back to rest where it was.
        let mut p = Proxy::new(1.0, 100.0, 0.05);
        let home = Vec3::ZERO;
        p.follow(home, home, dt);
        let mut stray: Real = 0.0;
        for k in 0..300 {
            let target = if k < 5 {
                Vec3::new(0.0, 0.0, 1.0)
            } else {
                home
            };
            stray = stray.max(p.follow(target, home, dt).length());
        }
        assert!(stray < 0.003, "strayed {stray} m");
        assert!(p.follow(home, home, dt).length() < 1e-9);
        // A glitch is catching up, following is not.
        let mut p = Proxy::new(1.0, 100.0, 0.05);
        for k in 0..100 {
            p.follow(Vec3::new(0.1 * k as Real * dt, 0.0, 0.0), Vec3::ZERO, dt);
            assert!(k < 50 || !p.catching_up(), "step {k}: lag {}", p.lag_m());
        }
        assert!((p.hand_speed_m_s() - 0.1).abs() < 1e-9);
        p.follow(Vec3::new(0.0, 0.0, 1.0), Vec3::ZERO, dt);
        assert!(p.catching_up());
        // Slowed, the step is taken again from where it started.
        let fast = p.speed_m_s();
        p.slow_to(0.05, dt);
        assert!(p.speed_m_s() < fast);
        // Far away: at most the speed limit.
        let mut p = Proxy::new(1.0, 100.0, 0.05);
        let mut prev = Vec3::ZERO;
        for _ in 0..200 {
            let at = p.follow(Vec3::new(1.0, 0.0, 0.0), Vec3::ZERO, dt);
            assert!((at - prev).length() <= 1.0 * dt + 1e-12);
            prev = at;
        }
    }
}
