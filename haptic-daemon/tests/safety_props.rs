//! Property tests of the safety filter: for random sequences of requests
//! (NaN and inf included), sample ages, liveness, clock steps (backward
//! included) and shutdowns, the output is always finite, within the clamp
//! and within the slew limit; a fault that lasts `ramp_down_ns` means zero
//! output; after a shutdown plus `ramp_down_ns`, exactly zero forever.

use haptic_daemon::math::{V3, norm, sub};
use haptic_daemon::safety::{Safety, SafetyConfig, SafetyState, StopReason};
use proptest::prelude::*;

const MS: u64 = 1_000_000;

#[derive(Clone, Debug)]
struct Step {
    /// Clock advance; negative values step the clock back.
    dt_ns: i64,
    requested_n: V3,
    age_ns: Option<u64>,
    alive: bool,
    shutdown: bool,
}

fn component() -> impl Strategy<Value = f64> {
    prop_oneof![
        6 => -20.0..20.0f64,
        1 => proptest::num::f64::ANY,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(1e300),
    ]
}

fn step() -> impl Strategy<Value = Step> {
    (
        prop_oneof![8 => 0i64..3 * MS as i64, 1 => -5 * MS as i64..0, 1 => 0i64..100 * MS as i64],
        [component(), component(), component()],
        prop_oneof![1 => Just(None), 8 => (0u64..40 * MS).prop_map(Some), 2 => (0u64..200 * MS).prop_map(Some)],
        prop_oneof![9 => Just(true), 1 => Just(false)],
        prop_oneof![200 => Just(false), 1 => Just(true)],
    )
        .prop_map(|(dt_ns, requested_n, age_ns, alive, shutdown)| Step {
            dt_ns,
            requested_n,
            age_ns,
            alive,
            shutdown,
        })
}

fn config() -> impl Strategy<Value = SafetyConfig> {
    (
        0.1f64..50.0,
        1.0f64..4.0,
        1u64..100 * MS,
        1u64..30 * MS,
        1u64..300 * MS,
    )
        .prop_map(
            |(max_force_n, slew_margin, max_sample_age_ns, ramp_down_ns, ramp_in_ns)| {
                SafetyConfig {
                    max_force_n,
                    max_slew_n_per_s: slew_margin * max_force_n / (ramp_down_ns as f64 / 1e9),
                    max_sample_age_ns,
                    ramp_down_ns,
                    ramp_in_ns,
                }
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    #[test]
    fn output_is_finite_clamped_and_slew_limited(
        cfg in config(),
        steps in proptest::collection::vec(step(), 1..400),
    ) {
        prop_assert!(cfg.validate().is_ok());
        let mut s = Safety::new(cfg);
        let mut now: u64 = 1_000 * MS;
        let mut clock: Option<u64> = None;
        let mut prev: V3 = [0.0; 3];
        // Since when (filter clock) a fault has lasted without interruption.
        let mut fault_since: Option<u64> = None;
        let mut shutdown_at: Option<u64> = None;
        for st in &steps {
            now = now.saturating_add_signed(st.dt_ns);
            if st.shutdown && shutdown_at.is_none() {
                s.shutdown(now);
                shutdown_at = Some(clock.map_or(now, |c| c.max(now)));
            }
            let f = s.filter(now, st.requested_n, st.age_ns, st.alive);
            let t = clock.map_or(now, |c| c.max(now));
            let dt_s = clock.map_or(0, |c| t - c) as f64 / 1e9;
            clock = Some(t);

            prop_assert!(f.iter().all(|x| x.is_finite()), "{f:?}");
            prop_assert!(norm(f) <= cfg.max_force_n * (1.0 + 1e-12), "|{f:?}| > {}", cfg.max_force_n);
            let slew = norm(sub(f, prev));
            prop_assert!(
                slew <= cfg.max_slew_n_per_s * dt_s * (1.0 + 1e-9) + 1e-12,
                "step {slew} N in {dt_s} s (limit {} N/s)", cfg.max_slew_n_per_s
            );
            prev = f;

            // A fault the safety filter sees (stale/missing sample counts
            // only once a sample had been seen; before that it is Waiting,
            // which outputs zero anyway).
            let faulty = !st.alive
                || st.age_ns.is_none_or(|a| a > cfg.max_sample_age_ns)
                || !st.requested_n.iter().all(|x| x.is_finite());
            fault_since = if faulty { Some(fault_since.unwrap_or(t)) } else { None };
            if let Some(since) = fault_since
                && t - since >= cfg.ramp_down_ns
            {
                prop_assert_eq!(f, [0.0; 3], "fault for {} ns", t - since);
            }
            if let Some(at) = shutdown_at {
                prop_assert!(matches!(
                    s.state(),
                    SafetyState::RampingDown(StopReason::Shutdown) | SafetyState::Stopped(StopReason::Shutdown)
                ));
                if t.saturating_sub(at) >= cfg.ramp_down_ns {
                    prop_assert_eq!(f, [0.0; 3]);
                    prop_assert_eq!(s.state(), SafetyState::Stopped(StopReason::Shutdown));
                }
            }
        }
    }

    #[test]
    fn no_sample_means_zero(
        cfg in config(),
        steps in proptest::collection::vec(step(), 1..100),
    ) {
        let mut s = Safety::new(cfg);
        let mut now = 0u64;
        for st in &steps {
            now = now.saturating_add_signed(st.dt_ns);
            prop_assert_eq!(s.filter(now, st.requested_n, None, st.alive), [0.0; 3]);
        }
    }
}
