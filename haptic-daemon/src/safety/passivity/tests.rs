//! The passivity observer/controller and the ramp-in from the output,
//! through `Safety::filter_at` on a scripted 1 kHz clock.

use crate::math::{dot, norm, sub};
use crate::safety::*;

const MS: u64 = 1_000_000;
const T0: u64 = 1_000 * MS;
const K_N_PER_M: f64 = 300.0;
/// The hand starts this far above the surface z = 0 (m).
const ABOVE_M: f64 = 0.005;
/// And presses this far into it (m).
const DEPTH_M: f64 = 0.01;
/// One press per this many ticks (0.5 s).
const PERIOD: u64 = 500;

/// The hand height at tick `k`: from 5 mm above down to 10 mm deep and
/// back, every 0.5 s (peak speed 0.047 m/s).
fn hand_z(k: u64) -> f64 {
    let w = std::f64::consts::TAU / PERIOD as f64;
    ABOVE_M - (ABOVE_M + DEPTH_M) * 0.5 * (1.0 - (w * k as f64).cos())
}

/// A wall rendered from the position `lag` ticks ago, refreshed every
/// `hold` ticks (a 30 Hz simulation behind a 1 kHz loop: `hold` 33). With
/// lag 0 and hold 1 it is a plain spring sampled at the haptic rate.
fn wall(k: u64, lag: u64, hold: u64) -> V3 {
    let sampled = (k / hold) * hold;
    let z = hand_z(sampled.saturating_sub(lag));
    [0.0, 0.0, K_N_PER_M * (-z).max(0.0)]
}

struct Run {
    outputs: Vec<V3>,
    /// Net energy generated per press (J; positive: into the hand).
    per_press_j: Vec<f64>,
    safety: Safety,
}

/// Ramps the filter in (in free space), then runs `presses` presses against
/// `field`, returning the outputs after the ramp-in and the energy each
/// press put into the hand (the force applied over each interval times the
/// motion).
fn run(passivity: PassivityConfig, presses: u64, field: impl Fn(u64) -> V3) -> Run {
    let mut s = Safety::new(SafetyConfig::new(8.0).unwrap()).with_passivity(passivity);
    let start = 300u64;
    for k in 0..start {
        s.filter_at(T0 + k * MS, ZERO, [0.0, 0.0, ABOVE_M], Some(MS), true);
    }
    assert_eq!(s.state(), SafetyState::Active);
    let mut outputs = Vec::new();
    let mut per_press_j = Vec::new();
    let mut energy = 0.0;
    let mut prev: Option<(V3, V3)> = None;
    for i in 0..presses * PERIOD {
        let x = [0.0, 0.0, hand_z(i)];
        let f = s.filter_at(T0 + (start + i) * MS, field(i), x, Some(MS), true);
        if let Some((f0, x0)) = prev {
            energy += dot(f0, sub(x, x0));
        }
        prev = Some((f, x));
        outputs.push(f);
        if (i + 1) % PERIOD == 0 {
            per_press_j.push(energy);
            energy = 0.0;
        }
    }
    Run {
        outputs,
        per_press_j,
        safety: s,
    }
}

#[test]
fn a_passive_spring_is_not_changed() {
    let with = run(PassivityConfig::default(), 4, |k| wall(k, 0, 1));
    let without = run(PassivityConfig::OFF, 4, |k| wall(k, 0, 1));
    assert_eq!(with.outputs, without.outputs);
    assert_eq!(with.safety.passivity().active_ticks(), 0);
    // Sampling leaks k dx^2 / 2 per tick: under half the 1 mJ tolerance.
    for e in &without.per_press_j {
        assert!(*e < 0.5e-3, "{e}");
    }
    // A spring with a damper (passive too): unchanged.
    let damped = |k: u64| {
        let v = (hand_z(k) - hand_z(k.saturating_sub(1))) / 1e-3;
        let f = wall(k, 0, 1);
        if f[2] > 0.0 {
            [0.0, 0.0, f[2] - 2.0 * v]
        } else {
            f
        }
    };
    let with = run(PassivityConfig::default(), 2, damped);
    let without = run(PassivityConfig::OFF, 2, damped);
    assert_eq!(with.outputs, without.outputs);
}

#[test]
fn a_lagging_wall_is_made_passive() {
    // A 30 Hz simulation, its samples 15 ms old when they arrive: the wall
    // pushes harder on the way out than on the way in.
    let leaky = |k: u64| wall(k, 15, 33);
    let config = PassivityConfig {
        max_damping_n_s_per_m: 50.0,
        ..PassivityConfig::default()
    };
    let without = run(PassivityConfig::OFF, 4, leaky);
    for e in &without.per_press_j {
        assert!(*e > 3e-3, "the field should leak: {e} J");
    }
    let with = run(config, 4, leaky);
    for e in &with.per_press_j {
        assert!(
            *e <= config.tolerance_j + 0.2e-3,
            "{e} J generated (without the controller: {:?})",
            without.per_press_j
        );
    }
    let p = with.safety.passivity();
    assert!(p.active_ticks() > 0 && p.dissipated_j() > 0.0);
    // Every output is still clamped and slew-limited.
    for w in with.outputs.windows(2) {
        assert!(norm(w[1]) <= 8.0);
        assert!(norm(sub(w[1], w[0])) <= 1.6 + 1e-9);
    }
}

#[test]
fn the_damping_is_bounded_and_along_the_motion() {
    let mut p = Passivity::new(PassivityConfig {
        max_damping_n_s_per_m: 5.0,
        ..PassivityConfig::default()
    });
    // 1 N along the motion over 10 mm: 10 mJ generated.
    p.observe([0.0; 3], MS, [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]);
    p.observe([0.0, 0.0, 0.01], MS, [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]);
    assert!((p.energy_j() - 0.01).abs() < 1e-12);
    // v = 10 m/s; alpha = 9 mJ / (100 * 1 ms) = 0.09 N s/m.
    let d = p.damping_n(MS);
    assert!((d[2] + 0.9).abs() < 1e-9 && d[0] == 0.0, "{d:?}");
    // 10 N over 1 mm in 1 ms: alpha would be 9 N s/m; the bound is 5.
    let mut p = Passivity::new(PassivityConfig::default());
    p.observe([0.0; 3], MS, [0.0, 0.0, 10.0], [0.0, 0.0, 10.0]);
    p.observe([0.0, 0.0, 1e-3], MS, [0.0, 0.0, 10.0], [0.0, 0.0, 10.0]);
    let d = p.damping_n(MS);
    assert!((d[2] + 5.0).abs() < 1e-9, "{d:?}");
    // Free space restarts the balance; a rebase forgets the jump.
    p.observe([0.0, 0.0, 2e-3], MS, ZERO, ZERO);
    assert_eq!(p.energy_j(), 0.0);
    p.rebase();
    p.observe([0.0, 0.0, 1.0], MS, [0.0, 0.0, 10.0], [0.0, 0.0, 10.0]);
    assert_eq!(p.energy_j(), 0.0);
    // Off: nothing observed, no damping.
    let mut p = Passivity::new(PassivityConfig::OFF);
    p.observe([0.0; 3], MS, [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]);
    p.observe([0.0, 0.0, 0.01], MS, [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]);
    assert_eq!(p.energy_j(), 0.0);
    assert_eq!(p.damping_n(MS), ZERO);
}

#[test]
fn passivity_configuration_errors() {
    let good = PassivityConfig::default();
    assert_eq!(good.validate(), Ok(()));
    for bad in [-1.0, f64::NAN, f64::INFINITY] {
        let c = PassivityConfig {
            tolerance_j: bad,
            ..good
        };
        assert!(matches!(c.validate(), Err(PassivityError::Tolerance(_))));
        let c = PassivityConfig {
            max_damping_n_s_per_m: bad,
            ..good
        };
        assert!(matches!(c.validate(), Err(PassivityError::MaxDamping(_))));
        assert!(!Passivity::new(c).config().enabled);
    }
}

#[test]
fn ramp_in_from_output_blends_without_a_step() {
    let mut s = Safety::new(SafetyConfig::new(8.0).unwrap());
    let mut t = T0;
    for _ in 0..=200 {
        s.filter(t, [0.0, 0.0, 1.0], Some(MS), true);
        t += MS;
    }
    assert_eq!(s.state(), SafetyState::Active);
    // The request jumps from 1 N to 3 N: with a restarted ramp-in, the
    // output goes from 1 N to 3 N over 200 ms, 10 mN per tick.
    s.ramp_in_from_output(t);
    assert_eq!(s.state(), SafetyState::RampingIn);
    let mut prev = s.output_n();
    for k in 0..=200u64 {
        let f = s.filter(t, [0.0, 0.0, 3.0], Some(MS), true);
        let want = 1.0 + 2.0 * k as f64 / 200.0;
        assert!((f[2] - want).abs() < 1e-9, "tick {k}: {f:?}");
        assert!((f[2] - prev[2]).abs() <= 0.01 + 1e-9);
        prev = f;
        t += MS;
    }
    assert_eq!(s.state(), SafetyState::Active);
    // A request that falls is let go at the slew limit, not held for the
    // ramp: the blend is never larger than the request.
    s.ramp_in_from_output(t);
    let slew_per_tick = s.config().max_slew_n_per_s * 1e-3;
    let mut prev = s.output_n();
    for k in 0..20u64 {
        let f = s.filter(t, [0.0, 0.0, 0.5], Some(MS), true);
        let want = (3.0 - slew_per_tick * (k + 1) as f64).max(0.5);
        assert!((f[2] - want).abs() < 1e-9, "tick {k}: {f:?}, want {want}");
        assert!(f[2] <= prev[2] + 1e-12, "tick {k}: {f:?} after {prev:?}");
        prev = f;
        t += MS;
    }
    assert!((prev[2] - 0.5).abs() < 1e-9, "{prev:?}");
    // In any other state it does nothing.
    let mut s = Safety::new(SafetyConfig::new(8.0).unwrap());
    s.ramp_in_from_output(T0);
    assert_eq!(s.state(), SafetyState::Waiting);
    s.filter(T0, [0.0, 0.0, 1.0], Some(60 * MS), true);
    assert_eq!(s.state(), SafetyState::Stopped(StopReason::StaleSample));
    s.ramp_in_from_output(T0 + MS);
    assert_eq!(s.state(), SafetyState::Stopped(StopReason::StaleSample));
}
