//! Coulomb friction on the penalty contact: an elasto-plastic tangential
//! spring per contact point (the stick-slip spring of discrete-element
//! codes, Cundall and Strack 1979, and of haptic friction rendering,
//! Hayward and Armstrong 2000; SOFA's penalty contacts carry the same
//! kind of tangential spring).
//!
//! Each point in contact keeps `delta`, its tangential displacement
//! relative to the tool surface since it stuck. Every integrator sub-step
//! the point's motion relative to the tool, tangential part, is added to
//! it (after projecting the old one on the new tangent plane), and the
//! tissue point feels f_t = -k_t delta, the tool the opposite:
//!
//! ```text
//! stick:  |k_t delta| <= mu_s f_n   (f_n the point's normal force)
//! slip:   otherwise delta is scaled back to |k_t delta| = mu_d f_n,
//!         and the point keeps sliding (limit mu_d) until its relative
//!         motion stops or reverses.
//! ```
//!
//! Why a spring and not a force opposed to the sliding velocity (regularised
//! Coulomb): static friction then really holds (a velocity law creeps under
//! any sustained load), and the spring's stiffness is the point's normal
//! penalty stiffness, so the sub-steps the contact springs already need keep
//! it stable (a velocity law steep enough to feel like friction would need a
//! damping coefficient hundreds of times what an explicit sub-step can
//! integrate). It is passive: the spring stores what it is given and a slip
//! only dissipates.
//!
//! The state survives the re-selection of the contact points between steps:
//! it is keyed by the point's triangle, lattice weights and tool part
//! ([`point_key`]). A triangle stretched enough to change its lattice
//! (see `penalty::sampling::subdivisions`) starts its new points unstuck.

use super::{ContactPoint, PartSweep};
use crate::contact::instrument::Friction;
use crate::math::{Real, Vec3};

/// One contact point's friction state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stick {
    /// Tangential displacement relative to the tool since the point stuck
    /// (m).
    pub delta_m: Vec3,
    /// Whether it slid at its last evaluation (its limit is then mu_d).
    pub sliding: bool,
}

impl Stick {
    /// Advances the state by the point's relative motion `slip_m` (its
    /// displacement minus the tool surface's over the sub-step) under
    /// normal `n` and normal force `normal_n`, with tangential stiffness
    /// `k_t_n_per_m`. Returns the tangential force on the tissue point (N).
    pub fn advance(
        &mut self,
        n: Vec3,
        slip_m: Vec3,
        normal_n: Real,
        k_t_n_per_m: Real,
        mu: &Friction,
    ) -> Vec3 {
        // The old displacement on the new tangent plane, plus the new
        // tangential motion.
        let trial = along_surface(self.delta_m, n) + along_surface(slip_m, n);
        let limit = if self.sliding {
            mu.dynamic_coefficient
        } else {
            mu.static_coefficient
        } * normal_n.max(0.0);
        let size = k_t_n_per_m * trial.length();
        if size > limit {
            // Slip: the spring is drawn back to the dynamic limit, along
            // the direction it was pulled.
            let kept = mu.dynamic_coefficient * normal_n.max(0.0);
            self.delta_m = if size > 0.0 {
                trial * (kept / size)
            } else {
                Vec3::ZERO
            };
            self.sliding = true;
        } else {
            self.delta_m = trial;
            self.sliding = false;
        }
        -self.delta_m * k_t_n_per_m
    }

    /// The tangential force on the tissue point now, without advancing
    /// (N).
    pub fn force_n(&self, n: Vec3, k_t_n_per_m: Real) -> Vec3 {
        -along_surface(self.delta_m, n) * k_t_n_per_m
    }
}

/// The part of `v` across the normal `n` (along the surface).
pub fn along_surface(v: Vec3, n: Vec3) -> Vec3 {
    v - n * v.dot(n)
}

/// A contact point's identity across selections: its triangle, its
/// lattice weights and the tool part it faces (64-bit mix, FNV-1a over the
/// words then a final avalanche).
pub fn point_key(p: &ContactPoint, part: &PartSweep) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut mix = |x: u64| {
        h ^= x;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    };
    for v in p.vertices {
        mix(u64::from(v));
    }
    for w in p.weights {
        mix(w.to_bits());
    }
    mix(((part.tool as u64) << 1) | u64::from(part.tip));
    h ^= h >> 33;
    h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
    h ^ (h >> 33)
}

/// The friction states of the last points, kept sorted by key so the next
/// selection's points find theirs (buffers reused across steps).
#[derive(Clone, Debug, Default)]
pub struct Carried {
    states: Vec<(u64, Stick)>,
}

impl Carried {
    /// Keeps the states of `keys` that hold something (stuck or sliding),
    /// forgetting the earlier ones.
    pub fn save(&mut self, keys: &[u64], sticks: &[Stick]) {
        self.states.clear();
        self.states.extend(
            keys.iter()
                .zip(sticks)
                .filter(|(_, s)| **s != Stick::default())
                .map(|(k, s)| (*k, *s)),
        );
        self.states.sort_unstable_by_key(|(k, _)| *k);
    }

    /// The state saved for `key` (unstuck if none).
    pub fn get(&self, key: u64) -> Stick {
        match self.states.binary_search_by_key(&key, |(k, _)| *k) {
            Ok(i) => self.states[i].1,
            Err(_) => Stick::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MU: Friction = Friction {
        static_coefficient: 0.5,
        dynamic_coefficient: 0.3,
    };

    #[test]
    fn a_point_sticks_below_the_static_limit_then_slides_at_the_dynamic_one() {
        let n = Vec3::Z;
        let mut s = Stick::default();
        let k = 100.0;
        // 1 N normal: holds up to 0.5 N, i.e. 5 mm of spring.
        for i in 1..=4 {
            let f = s.advance(n, Vec3::new(0.001, 0.0, 0.0), 1.0, k, &MU);
            assert!(!s.sliding);
            assert!((f.x + 0.1 * i as Real).abs() < 1e-12, "{f}");
        }
        // Past the static limit: slides, the force drops to mu_d f_n.
        let f = s.advance(n, Vec3::new(0.0015, 0.0, 0.0), 1.0, k, &MU);
        assert!(s.sliding);
        assert!((f.x + 0.3).abs() < 1e-12, "{f}");
        // Keeps sliding at mu_d while the motion goes on.
        let f = s.advance(n, Vec3::new(0.0001, 0.0, 0.0), 1.0, k, &MU);
        assert!(s.sliding && (f.x + 0.3).abs() < 1e-12);
        // Motion stops: it sticks again (the spring as it is), and holds
        // up to mu_s once more.
        let f = s.advance(n, Vec3::ZERO, 1.0, k, &MU);
        assert!(!s.sliding && (f.x + 0.3).abs() < 1e-12);
        let f = s.advance(n, Vec3::new(0.0015, 0.0, 0.0), 1.0, k, &MU);
        assert!(!s.sliding && (f.x + 0.45).abs() < 1e-12);
        // Reversing unloads the spring elastically.
        let f = s.advance(n, Vec3::new(-0.006, 0.0, 0.0), 1.0, k, &MU);
        assert!(!s.sliding && (f.x - 0.15).abs() < 1e-12, "{f}");
    }

    #[test]
    fn only_tangential_motion_loads_the_spring_and_the_old_one_turns_with_the_normal() {
        let mut s = Stick::default();
        let f = s.advance(Vec3::Z, Vec3::new(0.001, 0.0, 0.005), 10.0, 100.0, &MU);
        assert!((f - Vec3::new(-0.1, 0.0, 0.0)).length() < 1e-12);
        // The normal tilts towards x: the stored displacement loses its
        // component along the new normal.
        let n = Vec3::new(1.0, 0.0, 1.0).normalize();
        let f = s.advance(n, Vec3::ZERO, 10.0, 100.0, &MU);
        assert!(f.dot(n).abs() < 1e-15 && (f.length() - 0.1 / 2f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn no_normal_force_no_friction_and_slipping_only_dissipates() {
        let mut s = Stick::default();
        let f = s.advance(Vec3::Z, Vec3::new(0.001, 0.0, 0.0), 0.0, 100.0, &MU);
        assert_eq!(f, Vec3::ZERO);
        // Energy: dragged twice around a 3 mm circle (the spring holds
        // 5 mm, so it sticks and slips), the work done on the contact is
        // at least what its spring stores: it never gives back more than
        // it was given.
        let mut s = Stick::default();
        let mut work = 0.0;
        let steps = 20_000;
        let at = |i: usize| {
            let a = std::f64::consts::TAU * 2.0 * i as Real / steps as Real;
            Vec3::new(a.cos() - 1.0, a.sin(), 0.0) * 3e-3
        };
        let mut slid = false;
        for i in 1..=steps {
            let slip = at(i) - at(i - 1);
            let before = s.force_n(Vec3::Z, 100.0);
            let f = s.advance(Vec3::Z, slip, 1.0, 100.0, &MU);
            slid |= s.sliding;
            work -= 0.5 * (before + f).dot(slip);
        }
        let stored = 0.5 * 100.0 * s.delta_m.length_squared();
        assert!(slid);
        assert!(work > stored + 1e-4, "work {work} stored {stored}");
    }

    #[test]
    fn coefficients_are_checked() {
        assert!(MU.check().is_ok() && Friction::NONE.check().is_ok());
        let bad = Friction {
            static_coefficient: 0.2,
            dynamic_coefficient: 0.3,
        };
        assert!(bad.check().unwrap_err().contains("exceeds friction_static"));
        let bad = Friction {
            static_coefficient: Real::NAN,
            dynamic_coefficient: 0.0,
        };
        assert!(bad.check().unwrap_err().contains("friction_static"));
    }

    #[test]
    fn carried_states_are_found_by_key() {
        let mut c = Carried::default();
        let stuck = Stick {
            delta_m: Vec3::X,
            sliding: false,
        };
        c.save(&[9, 3, 5], &[stuck, Stick::default(), stuck]);
        assert_eq!(c.get(9), stuck);
        assert_eq!(c.get(5), stuck);
        assert_eq!(c.get(3), Stick::default());
        assert_eq!(c.get(4), Stick::default());
    }
}
