//! The live-sample guard on scripted streams.

use super::*;

const MS: u64 = 1_000_000;
const T0: u64 = 1_000 * MS;

fn guard() -> LiveGuard {
    LiveGuard::new(LiveConfig::default())
}

/// Arrival at the next 1 ms tick at or after `t_ns` (the daemon's drain).
fn tick_of(t_ns: u64) -> u64 {
    t_ns.div_ceil(MS) * MS
}

#[test]
fn normal_streams_are_live() {
    // Paced at 30, 60, 100, 250 and 1000 Hz, published with up to 3 ms of
    // jitter, received at the next 1 ms tick: never judged not live.
    for rate_hz in [30u64, 60, 100, 250, 1000] {
        let step = 1_000_000_000 / rate_hz;
        let mut g = guard();
        for k in 0..2_000u64 {
            let jitter = (k * 7919 % 3001) * 1_000;
            let arrival = tick_of(T0 + k * step + jitter);
            assert_ne!(
                g.observe(arrival, k * step),
                Live::NotLive,
                "{rate_hz} Hz k {k}"
            );
        }
        assert_eq!(g.not_live(), 0, "{rate_hz} Hz");
    }
}

#[test]
fn a_late_step_and_its_catch_up_are_live() {
    // 30 Hz: step 10 takes 60 ms, step 11 follows at once (catch-up); two
    // samples in one tick.
    let step = 33_333_333u64;
    let mut g = guard();
    for k in 0..40u64 {
        let mut t = T0 + k * step;
        if k == 10 {
            t += 27 * MS;
        }
        if k > 10 {
            t = t.max(T0 + 10 * step + 27 * MS + MS);
        }
        let arrival = tick_of(t);
        assert_eq!(g.observe(arrival, k * step), Live::Live, "k {k}");
    }
    // 1 kHz: a 6 ms step, then quick steps, four per tick, until caught up.
    let mut g = guard();
    let mut arrival = T0;
    let mut sim = 0u64;
    for _ in 0..100 {
        arrival += MS;
        sim += MS;
        assert_eq!(g.observe(arrival, sim), Live::Live);
    }
    arrival += 6 * MS;
    while sim + T0 < arrival {
        for _ in 0..4 {
            sim += MS;
            assert_eq!(g.observe(arrival, sim), Live::Live, "sim {sim}");
        }
        arrival += MS;
    }
    assert_eq!(g.not_live(), 0);
}

/// A 30 Hz stream, a 10 s stall, then 1.9 s of simulated time in 0.3 s,
/// then real rate again. Returns the verdicts of the burst and after it.
fn stall_and_burst(step: u64) -> (LiveGuard, Vec<(u64, u64, Live)>) {
    let mut g = guard();
    let mut sim = 0u64;
    let mut wall = T0;
    for _ in 0..(1_000 * MS / step) {
        wall += step;
        sim += step;
        assert_eq!(g.observe(tick_of(wall), sim), Live::Live);
    }
    wall += 10_000 * MS;
    let burst_steps = 1_900 * MS / step;
    let mut out = Vec::new();
    for k in 0..burst_steps {
        sim += step;
        let arrival = tick_of(wall + k * 300 * MS / burst_steps);
        out.push((arrival, sim, g.observe(arrival, sim)));
    }
    wall += 300 * MS;
    for _ in 0..(1_000 * MS / step) {
        wall += step;
        sim += step;
        let arrival = tick_of(wall);
        out.push((arrival, sim, g.observe(arrival, sim)));
    }
    (g, out)
}

#[test]
fn a_fast_forward_burst_is_not_live() {
    for step in [33_333_333u64, 10 * MS, MS] {
        let (g, out) = stall_and_burst(step);
        let burst_end = out[0].0 + 300 * MS;
        // Simulated time of the burst rendered as live: at most twice the
        // allowance (10 ms slack + one step), against 1.9 s.
        let live_sim_ns: u64 = out
            .iter()
            .filter(|(a, _, v)| *a < burst_end && *v != Live::NotLive)
            .count() as u64
            * step;
        let bound = 2 * (10 * MS + step);
        assert!(live_sim_ns <= bound, "step {step}: {live_sim_ns} ns live");
        // Real rate again: live within 150 ms of wall time after the burst,
        // the first one marked Resumed, and all live from there on.
        let first = out
            .iter()
            .position(|(a, _, v)| *a >= burst_end && *v != Live::NotLive)
            .expect("live again");
        assert!(out[first].0 - burst_end <= 150 * MS, "step {step}");
        assert_eq!(out[first].2, Live::Resumed, "step {step}");
        assert!(out[first + 1..].iter().all(|(_, _, v)| *v == Live::Live));
        assert!(g.not_live() as f64 >= 0.9 * (1_900 * MS / step) as f64);
    }
}

#[test]
fn a_long_catch_up_is_cut_at_the_allowance() {
    // 1 kHz: a 42 ms step (an implicit factor rebuild), then catch-up at
    // four steps per tick: the lead rendered as live stays within the
    // allowance (10 ms slack + 1 ms step), then it resumes.
    let mut g = guard();
    let mut arrival = T0;
    let mut sim = 0u64;
    for _ in 0..100 {
        arrival += MS;
        sim += MS;
        g.observe(arrival, sim);
    }
    arrival += 42 * MS;
    let (mut live_ms, mut ticks, mut resumed) = (0u64, 0u64, 0);
    while sim + T0 < arrival {
        for _ in 0..4 {
            sim += MS;
            match g.observe(arrival, sim) {
                Live::NotLive => {}
                Live::Resumed => resumed += 1,
                Live::Live => live_ms += 1,
            }
        }
        arrival += MS;
        ticks += 1;
    }
    assert!(g.not_live() > 0);
    // Live simulated time beyond 1.5 x the wall time: at most 2 x 11 ms.
    assert!(
        live_ms <= ticks * 3 / 2 + 22,
        "{live_ms} ms live in {ticks} ms"
    );
    for _ in 0..100 {
        arrival += MS;
        sim += MS;
        if g.observe(arrival, sim) == Live::Resumed {
            resumed += 1;
        }
    }
    assert_eq!(resumed, 1);
    assert_eq!(g.observe(arrival + MS, sim + MS), Live::Live);
}

#[test]
fn a_restarted_simulation_starts_over() {
    let mut g = guard();
    for k in 1..100u64 {
        assert_eq!(g.observe(T0 + k * MS, k * MS), Live::Live);
    }
    // sim_time_ns back to 0: judged afresh, live.
    assert_eq!(g.observe(T0 + 100 * MS, 0), Live::Live);
    assert_eq!(g.observe(T0 + 101 * MS, MS), Live::Live);
    // A simulation that does not fill sim_time_ns (always 0) is live.
    let mut g = guard();
    for k in 0..100u64 {
        assert_eq!(g.observe(T0 + k * MS / 10, 0), Live::Live);
    }
}

#[test]
fn configuration_errors() {
    let good = LiveConfig::default();
    assert_eq!(good.validate(), Ok(()));
    for r in [1.0, 0.5, f64::NAN, f64::INFINITY] {
        let c = LiveConfig {
            max_rate: r,
            ..good
        };
        assert!(matches!(c.validate(), Err(LiveError::MaxRate(_))), "{r}");
    }
    let c = LiveConfig {
        slack_ns: 0,
        ..good
    };
    assert_eq!(c.validate(), Err(LiveError::ZeroDuration("slack_ns")));
    let c = LiveConfig { gap_ns: 0, ..good };
    assert_eq!(c.validate(), Err(LiveError::ZeroDuration("gap_ns")));
    assert_eq!(LiveGuard::new(c).config(), &good);
}
