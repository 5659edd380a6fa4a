//! The simulated tool (the proxy) follows the pose the device asks for no
//! faster and no more abruptly than a hand can move: a pose that jumps (a
//! glitch, a re-homed device, a client that starts mid-air) drags the
//! proxy along a bounded path instead of teleporting it through or into
//! the tissue. A god-object in the sense of Zilles and Salisbury (1995),
//! reduced to what a compliant contact needs: the contact keeps the proxy
//! out of the tissue, the proxy keeps it from tunnelling, and where tissue
//! slips past the tip all the same, [`super::surface_crossing`] puts the
//! proxy back outside ([`Proxy::stop_at`]).
//!
//! Each step the proxy heads for the requested tip at the speed that
//! reaches it this step, no faster than `max_speed_m_s`, no faster than it
//! can still stop by the target (sqrt(2 a d)), and changing its velocity
//! by at most `max_accel_m_s2 * dt`. A hand moving at v follows with a lag
//! of at most v^2 / (2 a) (0.05 mm at 0.1 m/s and 100 m/s^2).

use crate::math::{Real, Vec3};

/// A rate-limited follower of the requested tool tip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Proxy {
    at_m: Option<Vec3>,
    velocity_m_s: Vec3,
    max_speed_m_s: Real,
    max_accel_m_s2: Real,
}

impl Proxy {
    /// A proxy not yet placed.
    pub fn new(max_speed_m_s: Real, max_accel_m_s2: Real) -> Self {
        Self {
            at_m: None,
            velocity_m_s: Vec3::ZERO,
            max_speed_m_s,
            max_accel_m_s2,
        }
    }

    /// The tool was withdrawn: the next pose starts afresh.
    pub fn reset(&mut self) {
        self.at_m = None;
        self.velocity_m_s = Vec3::ZERO;
    }

    /// Where the proxy is after a step of `dt_s` towards `target_m`,
    /// starting from `start_m` if it was not placed.
    pub fn follow(&mut self, target_m: Vec3, start_m: Vec3, dt_s: Real) -> Vec3 {
        let at = self.at_m.unwrap_or(start_m);
        let e = target_m - at;
        let dist = e.length();
        let (a, v) = (self.max_accel_m_s2, self.velocity_m_s);
        let want = if dist > 0.0 {
            let speed = (dist / dt_s)
                .min((2.0 * a * dist).sqrt())
                .min(self.max_speed_m_s);
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
        let mut p = Proxy::new(1.0, 100.0);
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
        let mut p = Proxy::new(1.0, 100.0);
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
        // Far away: at most the speed limit.
        let mut p = Proxy::new(1.0, 100.0);
        let mut prev = Vec3::ZERO;
        for _ in 0..200 {
            let at = p.follow(Vec3::new(1.0, 0.0, 0.0), Vec3::ZERO, dt);
            assert!((at - prev).length() <= 1.0 * dt + 1e-12);
            prev = at;
        }
    }
}
