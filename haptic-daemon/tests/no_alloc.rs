//! `Extrapolator::push`/`force` (with a stiffness cap),
//! `Safety::filter_at`/`shutdown`/`ramp_in_from_output` (with the passivity
//! controller), `Plausible::check` and `LiveGuard::observe` allocate
//! nothing: a counting global allocator counts allocations made on this
//! thread during 10,000 ticks per method (samples every 3rd tick, NaN
//! samples and requests, stale and dead-peer spells, backward clock steps,
//! device glitches and a re-home, a fast-forward burst, and a shutdown at
//! the end).

use haptic_daemon::extrapolate::{Extrapolator, ForceSample, Method};
use haptic_daemon::live::{Live, LiveConfig, LiveGuard};
use haptic_daemon::plausible::{Plausible, PlausibleConfig, Verdict};
use haptic_daemon::safety::{PassivityConfig, Safety, SafetyConfig, SafetyState, StopReason};
use shared::alloc_count::{Counting, count};

#[global_allocator]
static ALLOCATOR: Counting = Counting;

const MS: u64 = 1_000_000;

/// The sample of tick `k`; every 97th one has a NaN force.
fn sample(k: u64, now: u64) -> ForceSample {
    let x = k as f64 * 1e-3;
    let z = if k.is_multiple_of(97) {
        f64::NAN
    } else {
        x.sin()
    };
    ForceSample {
        t_ns: now,
        seq: k,
        position_m: [0.0, 0.0, 0.05 - x.sin() * 0.01],
        force_n: [0.0, 0.0, z],
        stiffness_n_per_m: [[100.0, 0.0, 0.0], [0.0, 100.0, 0.0], [0.0, 0.0, 100.0]],
        in_contact: k % 500 < 400,
        catching_up: false,
    }
}

#[test]
fn ten_thousand_ticks_allocate_nothing() {
    for method in Method::ALL {
        let mut e = Extrapolator::new(method).with_max_stiffness(400.0);
        let mut safety =
            Safety::new(SafetyConfig::new(5.0).unwrap()).with_passivity(PassivityConfig::default());
        let mut plausible = Plausible::new(PlausibleConfig::default());
        let mut live = LiveGuard::new(LiveConfig::default());
        let mut held = [0.0; 3];
        let mut sim_ns = 0u64;
        let t0 = 1_000 * MS;
        let mut last_sample_t: Option<u64> = None;
        let mut max_out = 0.0f64;

        let ((), allocations) = count(|| {
            for k in 0..10_000u64 {
                // A backward step of the clock now and then.
                let now = if k % 1000 == 999 {
                    t0 + (k - 5) * MS
                } else {
                    t0 + k * MS
                };
                // Samples every 3rd tick, except for a 100 ms gap (stale),
                // and a fast-forward burst (20 ms of simulated time each).
                if k.is_multiple_of(3) && !(3000..3100).contains(&k) {
                    sim_ns += if (7000..7300).contains(&k) {
                        20 * MS
                    } else {
                        3 * MS
                    };
                    match live.observe(now, sim_ns) {
                        Live::NotLive => {}
                        v => {
                            if v == Live::Resumed {
                                safety.ramp_in_from_output(now);
                            }
                            e.push(&sample(k, now));
                            last_sample_t = Some(now);
                        }
                    }
                }
                let x = k as f64 * 1e-3;
                let position = [
                    0.0,
                    0.0,
                    if k.is_multiple_of(211) {
                        f64::INFINITY
                    } else {
                        0.05 - x.sin() * 0.012
                    },
                ];
                // Device glitches (1 m away for 5 ticks), NaN, and a re-home.
                let mut device = position;
                if k % 1000 < 5 {
                    device[0] += 1.0;
                }
                if k % 777 == 3 {
                    device[1] = f64::NAN;
                }
                if k >= 8000 {
                    device[0] += 0.2;
                }
                match plausible.check(now, device) {
                    Verdict::Accept => held = device,
                    Verdict::Rereference => {
                        held = device;
                        safety.rebase_motion();
                        safety.ramp_in_from_output(now);
                    }
                    Verdict::Reject | Verdict::Lost => {}
                }
                let mut requested = e.force(now, held);
                if k.is_multiple_of(1234) {
                    requested[1] = f64::NAN;
                }
                let age = last_sample_t.map(|t| now.saturating_sub(t));
                let alive = !(6000..6050).contains(&k);
                if k == 9_900 {
                    safety.shutdown(now);
                }
                let out = safety.filter_at(now, requested, held, age, alive);
                max_out = max_out.max(out.iter().fold(0.0, |m, v| m.max(v.abs())));
                std::hint::black_box(out);
            }
        });

        assert_eq!(
            allocations,
            0,
            "{}: {allocations} allocations in 10,000 ticks",
            method.name()
        );
        assert!(
            max_out > 0.1,
            "{}: the loop never produced a force",
            method.name()
        );
        assert_eq!(safety.state(), SafetyState::Stopped(StopReason::Shutdown));
        assert!(plausible.rejected() > 0 && plausible.rereferences() > 0);
        assert!(live.not_live() > 0);
    }
}
