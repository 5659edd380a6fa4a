//! Every transition, with a scripted 1 kHz clock. Default configuration for
//! 8 N: slew 1600 N/s (1.6 N per tick), age 50 ms, ramp-down 10 ms,
//! ramp-in 200 ms.

use super::*;
use crate::math::norm;

const MS: u64 = 1_000_000;
const UP: V3 = [0.0, 0.0, 1.0];

/// A filter and a clock that advances 1 ms per tick.
struct Script {
    s: Safety,
    t_ns: u64,
}

impl Script {
    fn new() -> Self {
        Self {
            s: Safety::new(SafetyConfig::new(8.0).unwrap()),
            t_ns: 1_000 * MS,
        }
    }

    /// One tick with a fresh sample and a live peer.
    fn fresh(&mut self, req: V3) -> V3 {
        self.tick(req, Some(MS), true)
    }

    fn tick(&mut self, req: V3, age: Option<u64>, alive: bool) -> V3 {
        let f = self.s.filter(self.t_ns, req, age, alive);
        self.t_ns += MS;
        f
    }

    /// Ramps in with `req` until Active.
    fn active(req: V3) -> Self {
        let mut sc = Self::new();
        for _ in 0..=200 {
            sc.fresh(req);
        }
        assert_eq!(sc.s.state(), SafetyState::Active);
        sc
    }
}

fn close(a: V3, b: V3) -> bool {
    (0..3).all(|i| (a[i] - b[i]).abs() < 1e-9)
}

#[test]
fn pure_helpers() {
    assert_eq!(fault_of(UP, Some(50 * MS), true, 50 * MS), None);
    assert_eq!(
        fault_of(UP, Some(50 * MS + 1), true, 50 * MS),
        Some(StopReason::StaleSample)
    );
    assert_eq!(
        fault_of(UP, None, true, 50 * MS),
        Some(StopReason::StaleSample)
    );
    assert_eq!(
        fault_of([f64::NAN; 3], None, false, 50 * MS),
        Some(StopReason::PeerDead)
    );
    assert_eq!(
        fault_of([f64::NAN; 3], None, true, 50 * MS),
        Some(StopReason::StaleSample)
    );
    assert_eq!(
        fault_of([0.0, f64::INFINITY, 0.0], Some(0), true, 50 * MS),
        Some(StopReason::NonFinite)
    );
    assert_eq!(
        ramp_down_value([0.0, 0.0, 4.0], 10, 100, 35),
        Some([0.0, 0.0, 3.0])
    );
    assert_eq!(
        ramp_down_value([0.0, 0.0, 4.0], 10, 100, 5),
        Some([0.0, 0.0, 4.0])
    );
    assert_eq!(ramp_down_value([0.0, 0.0, 4.0], 10, 100, 110), None);
    assert_eq!(ramp_down_value([0.0, 0.0, 4.0], 10, 0, 10), None);
    assert_eq!(ramp_in_gain(10, 100, 60), 0.5);
    assert_eq!(ramp_in_gain(10, 100, 0), 0.0);
    assert_eq!(ramp_in_gain(10, 100, u64::MAX), 1.0);
    assert_eq!(ramp_in_gain(10, 0, 10), 1.0);
}

#[test]
fn waiting_gives_zero_until_the_first_sample() {
    let mut sc = Script::new();
    for _ in 0..100 {
        assert_eq!(sc.tick(UP, None, true), ZERO);
        assert_eq!(sc.tick([f64::NAN; 3], None, false), ZERO);
        assert_eq!(sc.s.state(), SafetyState::Waiting);
    }
}

#[test]
fn start_ramps_in_over_200_ms() {
    let mut sc = Script::new();
    // First call: the ramp starts, gain 0 (and dt 0).
    assert_eq!(sc.fresh(UP), ZERO);
    assert_eq!(sc.s.state(), SafetyState::RampingIn);
    for k in 1..200u64 {
        let f = sc.fresh(UP);
        assert!(close(f, [0.0, 0.0, k as f64 / 200.0]), "tick {k}: {f:?}");
        assert_eq!(sc.s.state(), SafetyState::RampingIn);
    }
    assert!(close(sc.fresh(UP), UP));
    assert_eq!(sc.s.state(), SafetyState::Active);
}

#[test]
fn first_sample_stale_or_dead_is_stopped_not_ramped() {
    let mut sc = Script::new();
    assert_eq!(sc.tick(UP, Some(60 * MS), true), ZERO);
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::StaleSample));
    assert_eq!(sc.tick(UP, Some(MS), false), ZERO);
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::PeerDead));
    assert_eq!(sc.tick([f64::NAN; 3], Some(MS), true), ZERO);
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::NonFinite));
    sc.fresh(UP);
    assert_eq!(sc.s.state(), SafetyState::RampingIn);
}

#[test]
fn clamp_keeps_direction() {
    let mut sc = Script::active([30.0, 40.0, 0.0]);
    // |(30, 40, 0)| = 50 -> 8 N along (0.6, 0.8, 0).
    assert!(close(sc.fresh([30.0, 40.0, 0.0]), [4.8, 6.4, 0.0]));
    let mut sc = Script::active([0.0, 0.0, -1e300]);
    assert!(close(sc.fresh([0.0, 0.0, -1e300]), [0.0, 0.0, -8.0]));
    let f = sc.fresh([f64::MAX, f64::MAX, f64::MAX]);
    assert!(f.iter().all(|x| x.is_finite()) && norm(f) <= 8.0 + 1e-12);
}

#[test]
fn slew_limits_a_step() {
    let mut sc = Script::active(ZERO);
    // 0 -> 8 N at 1.6 N per 1 ms tick.
    for k in 1..=5 {
        let f = sc.fresh([0.0, 0.0, 8.0]);
        assert!(close(f, [0.0, 0.0, 1.6 * k as f64]), "tick {k}: {f:?}");
    }
    assert!(close(sc.fresh([0.0, 0.0, 8.0]), [0.0, 0.0, 8.0]));
    // And back down, crossing the full range in 10 ticks.
    assert!(close(sc.fresh([0.0, 0.0, -8.0]), [0.0, 0.0, 6.4]));
}

#[test]
fn backward_or_repeated_clock_moves_nothing() {
    let mut sc = Script::active(UP);
    // The time of the last tick.
    let t = sc.t_ns - MS;
    assert!(close(
        sc.s.filter(t - 5 * MS, [0.0, 0.0, 8.0], Some(MS), true),
        UP
    ));
    assert!(close(
        sc.s.filter(t - 5 * MS, [0.0, 0.0, 8.0], Some(MS), true),
        UP
    ));
    // The clock resumes from the largest time seen: 1 ms later, 1.6 N more.
    assert!(close(
        sc.s.filter(t + MS, [0.0, 0.0, 8.0], Some(MS), true),
        [0.0, 0.0, 2.6]
    ));
    // A NaN on a stalled clock: the fault is seen, the last safe force held.
    assert!(close(
        sc.s.filter(t, [f64::NAN; 3], Some(MS), true),
        [0.0, 0.0, 2.6]
    ));
    assert_eq!(
        sc.s.state(),
        SafetyState::RampingDown(StopReason::NonFinite)
    );
}

#[test]
fn non_finite_request_decays_then_ramps_in() {
    let mut sc = Script::active([0.0, 0.0, 4.0]);
    // The tick that sees the NaN holds the last safe force.
    assert!(close(sc.fresh([f64::NAN, 0.0, 0.0]), [0.0, 0.0, 4.0]));
    assert_eq!(
        sc.s.state(),
        SafetyState::RampingDown(StopReason::NonFinite)
    );
    // 4 N * (1 - k / 10) while the NaN lasts or not (the ramp completes).
    for k in 1..10 {
        let req = if k < 5 {
            [f64::INFINITY; 3]
        } else {
            [0.0, 0.0, 4.0]
        };
        let f = sc.fresh(req);
        assert!(
            close(f, [0.0, 0.0, 4.0 * (1.0 - k as f64 / 10.0)]),
            "tick {k}: {f:?}"
        );
    }
    assert_eq!(sc.fresh([0.0, 0.0, 4.0]), ZERO);
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::NonFinite));
    // Finite again: ramp-in, 4 N * k / 200.
    assert_eq!(sc.fresh([0.0, 0.0, 4.0]), ZERO);
    assert_eq!(sc.s.state(), SafetyState::RampingIn);
    assert!(close(sc.fresh([0.0, 0.0, 4.0]), [0.0, 0.0, 0.02]));
}

#[test]
fn stale_sample_ramps_down_and_stays_zero() {
    let mut sc = Script::active([0.0, 5.0, 0.0]);
    // Exactly 50 ms is still fresh.
    assert!(close(
        sc.tick([0.0, 5.0, 0.0], Some(50 * MS), true),
        [0.0, 5.0, 0.0]
    ));
    let f = sc.tick([0.0, 5.0, 0.0], Some(51 * MS), true);
    assert!(close(f, [0.0, 5.0, 0.0]));
    assert_eq!(
        sc.s.state(),
        SafetyState::RampingDown(StopReason::StaleSample)
    );
    for k in 1..10u64 {
        let f = sc.tick([0.0, 5.0, 0.0], Some((51 + k) * MS), true);
        assert!(
            close(f, [0.0, 5.0 * (1.0 - k as f64 / 10.0), 0.0]),
            "tick {k}: {f:?}"
        );
    }
    for k in 10..500u64 {
        assert_eq!(sc.tick([0.0, 5.0, 0.0], Some((51 + k) * MS), true), ZERO);
        assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::StaleSample));
    }
    // Samples come back: ramp-in from zero.
    assert_eq!(sc.fresh([0.0, 5.0, 0.0]), ZERO);
    assert_eq!(sc.s.state(), SafetyState::RampingIn);
    assert!(close(sc.fresh([0.0, 5.0, 0.0]), [0.0, 0.025, 0.0]));
}

#[test]
fn missing_sample_after_samples_counts_as_stale() {
    let mut sc = Script::active(UP);
    sc.tick(UP, None, true);
    assert_eq!(
        sc.s.state(),
        SafetyState::RampingDown(StopReason::StaleSample)
    );
}

#[test]
fn dead_peer_ramps_down_and_recovers() {
    let mut sc = Script::active(UP);
    sc.tick(UP, Some(MS), false);
    assert_eq!(sc.s.state(), SafetyState::RampingDown(StopReason::PeerDead));
    for _ in 0..10 {
        sc.tick(UP, Some(MS), false);
    }
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::PeerDead));
    assert_eq!(sc.tick(UP, Some(MS), false), ZERO);
    // Dead and stale: the dead peer wins; stale alone after it revives.
    sc.tick(UP, Some(90 * MS), false);
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::PeerDead));
    sc.tick(UP, Some(90 * MS), true);
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::StaleSample));
    sc.fresh(UP);
    assert_eq!(sc.s.state(), SafetyState::RampingIn);
}

#[test]
fn a_glitch_costs_a_full_ramp_down_then_a_ramp_in() {
    let mut sc = Script::active([0.0, 0.0, 2.0]);
    sc.tick([0.0, 0.0, 2.0], Some(MS), false);
    // The peer is back at once, but the ramp-down completes.
    for k in 1..10 {
        let f = sc.fresh([0.0, 0.0, 2.0]);
        assert!(
            close(f, [0.0, 0.0, 2.0 * (1.0 - k as f64 / 10.0)]),
            "tick {k}: {f:?}"
        );
    }
    assert_eq!(sc.fresh([0.0, 0.0, 2.0]), ZERO);
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::PeerDead));
    sc.fresh([0.0, 0.0, 2.0]);
    assert_eq!(sc.s.state(), SafetyState::RampingIn);
}

#[test]
fn fault_during_ramp_in_ramps_down_from_the_partial_force() {
    let mut sc = Script::new();
    for _ in 0..=100 {
        sc.fresh([0.0, 0.0, 2.0]);
    }
    assert!(close(sc.s.output_n(), [0.0, 0.0, 1.0]));
    assert!(close(
        sc.tick([0.0, 0.0, 2.0], Some(MS), false),
        [0.0, 0.0, 1.0]
    ));
    assert!(close(
        sc.tick([0.0, 0.0, 2.0], Some(MS), false),
        [0.0, 0.0, 0.9]
    ));
}

#[test]
fn shutdown_ramps_to_zero_then_stops_forever() {
    let mut sc = Script::active([0.0, 0.0, 6.0]);
    sc.s.shutdown(sc.t_ns);
    assert_eq!(sc.s.state(), SafetyState::RampingDown(StopReason::Shutdown));
    for k in 0..10 {
        let f = sc.fresh([0.0, 0.0, 6.0]);
        assert!(
            close(f, [0.0, 0.0, 6.0 * (1.0 - k as f64 / 10.0)]),
            "tick {k}: {f:?}"
        );
    }
    for _ in 0..1000 {
        assert_eq!(sc.fresh([0.0, 0.0, 6.0]), ZERO);
        assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::Shutdown));
    }
    sc.s.shutdown(sc.t_ns);
    assert_eq!(sc.fresh(UP), ZERO);
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::Shutdown));
}

#[test]
fn shutdown_while_waiting_or_stopped_is_immediate() {
    let mut sc = Script::new();
    sc.s.shutdown(0);
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::Shutdown));
    assert_eq!(sc.fresh(UP), ZERO);
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::Shutdown));
    let mut sc = Script::new();
    sc.tick(UP, Some(90 * MS), true);
    sc.s.shutdown(sc.t_ns);
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::Shutdown));
}

#[test]
fn shutdown_during_a_ramp_down_keeps_its_end() {
    let mut sc = Script::active([0.0, 0.0, 5.0]);
    sc.tick(UP, Some(MS), false);
    for _ in 0..4 {
        sc.fresh(UP);
    }
    sc.s.shutdown(sc.t_ns);
    assert_eq!(sc.s.state(), SafetyState::RampingDown(StopReason::Shutdown));
    // Ramp started 5 ticks ago: 5 N * (1 - 5/10), then down to zero at 10.
    assert!(close(sc.fresh(UP), [0.0, 0.0, 2.5]));
    for _ in 0..4 {
        sc.fresh(UP);
    }
    assert_eq!(sc.fresh(UP), ZERO);
    assert_eq!(sc.s.state(), SafetyState::Stopped(StopReason::Shutdown));
}

#[test]
fn shutdown_with_a_late_or_early_time() {
    // Shutdown stamped 3 ms after the last tick: the ramp starts then.
    let mut sc = Script::active([0.0, 0.0, 5.0]);
    let t = sc.t_ns - MS;
    sc.s.shutdown(t + 3 * MS);
    assert!(close(sc.s.filter(t, UP, Some(MS), true), [0.0, 0.0, 5.0]));
    assert!(close(
        sc.s.filter(t + 8 * MS, UP, Some(MS), true),
        [0.0, 0.0, 2.5]
    ));
    assert_eq!(sc.s.filter(t + 13 * MS, UP, Some(MS), true), ZERO);
    // Stamped before the last tick: the ramp starts at the filter's clock.
    let mut sc = Script::active([0.0, 0.0, 5.0]);
    let t = sc.t_ns - MS;
    sc.s.shutdown(0);
    assert!(close(
        sc.s.filter(t + 5 * MS, UP, Some(MS), true),
        [0.0, 0.0, 2.5]
    ));
}

#[test]
fn invalid_config_outputs_zero_forever() {
    let cfg = SafetyConfig {
        max_force_n: f64::NAN,
        max_slew_n_per_s: -1.0,
        max_sample_age_ns: 0,
        ramp_down_ns: 0,
        ramp_in_ns: 0,
    };
    let mut s = Safety::new(cfg);
    for k in 0..1000u64 {
        let f = s.filter(k * MS, [0.0, 0.0, 1.0 + k as f64], Some(0), true);
        assert_eq!(f, ZERO);
    }
    assert_eq!(s.config().ramp_in_ns, 0);
}
