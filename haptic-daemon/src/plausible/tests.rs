//! The plausibility filter on scripted 1 kHz (and 10 kHz) device streams.

use super::*;

const MS: u64 = 1_000_000;
const T0: u64 = 1_000 * MS;

fn filter() -> Plausible {
    Plausible::new(PlausibleConfig::default())
}

/// A hand probing at rest 15 mm deep (z = -0.015), 1 kHz, with a glitch to
/// `glitch` from tick 100 to 104 (5 ms); returns the verdicts.
fn glitch_run(glitch: V3) -> (Plausible, Vec<Verdict>) {
    let mut f = filter();
    let rest = [0.01, 0.02, -0.015];
    let v = (0..200u64)
        .map(|k| {
            let p = if (100..105).contains(&k) {
                glitch
            } else {
                rest
            };
            f.check(T0 + k * MS, p)
        })
        .collect();
    (f, v)
}

#[test]
fn a_5_ms_glitch_is_rejected_entirely() {
    for glitch in [
        [1.01, 0.02, -0.015],  // 1 m away
        [0.01, 0.02, -0.035],  // 20 mm deeper
        [0.01, 0.02, -0.0235], // 8.5 mm deeper
    ] {
        let (f, v) = glitch_run(glitch);
        for (k, verdict) in v.iter().enumerate() {
            let want = if (100..105).contains(&k) {
                Verdict::Reject
            } else {
                Verdict::Accept
            };
            assert_eq!(*verdict, want, "{glitch:?} tick {k}");
        }
        assert_eq!(f.rejected(), 5);
        assert_eq!(f.rereferences(), 0);
        assert_eq!(f.last_good_m(), Some([0.01, 0.02, -0.015]));
    }
}

#[test]
fn smooth_motion_at_1_5_m_s_is_accepted() {
    for period_ns in [MS, MS / 10] {
        // Straight at 1.5 m/s from rest in one tick would be a 1.5 mm jump
        // (within the tolerance); then steady.
        let mut f = filter();
        for k in 0..2_000u64 {
            let t = k * period_ns;
            let x = 1.5 * t as f64 * 1e-9;
            assert_eq!(f.check(T0 + t, [x, 0.0, 0.0]), Verdict::Accept, "tick {k}");
        }
        // A 2 Hz stroke peaking at 1.5 m/s (and 19 m/s^2), 3D.
        let mut f = filter();
        let w = std::f64::consts::TAU * 2.0;
        let a = 1.5 / w;
        for k in 0..20_000u64 {
            let t_s = (k * period_ns) as f64 * 1e-9;
            let p = [a * (w * t_s).sin(), 0.5 * a * (w * t_s).cos(), 0.01 * t_s];
            assert_eq!(f.check(T0 + k * period_ns, p), Verdict::Accept, "tick {k}");
        }
        assert_eq!(f.rejected(), 0);
    }
}

#[test]
fn a_jittery_device_at_1_m_s_is_accepted() {
    // A device delivering on its own thread: every 3rd tick repeats the
    // previous pose and the next one catches up (1 ms timing error).
    let mut f = filter();
    let mut x = 0.0;
    for k in 0..3_000u64 {
        let fresh = 1.0 * k as f64 * 1e-3;
        if k % 3 != 1 {
            x = fresh;
        }
        assert_eq!(
            f.check(T0 + k * MS, [x, 0.0, 0.0]),
            Verdict::Accept,
            "tick {k}"
        );
    }
}

#[test]
fn a_sudden_start_beyond_a_hand_is_rejected() {
    // From rest to 2.9 m/s in one tick: under the speed limit, but the
    // acceleration (2900 m/s^2) is not a hand's.
    let mut f = filter();
    for k in 0..10u64 {
        assert_eq!(f.check(T0 + k * MS, [0.0; 3]), Verdict::Accept);
    }
    assert_eq!(f.check(T0 + 10 * MS, [0.0029, 0.0, 0.0]), Verdict::Reject);
}

#[test]
fn a_long_displacement_is_accepted_after_the_bound() {
    let mut f = filter();
    for k in 0..50u64 {
        assert_eq!(f.check(T0 + k * MS, [0.0; 3]), Verdict::Accept);
    }
    // Re-homed 10 cm away for good.
    let there = [0.1, 0.0, 0.0];
    let mut verdicts = Vec::new();
    for k in 50..100u64 {
        verdicts.push(f.check(T0 + k * MS, there));
    }
    // Ticks 50..69 (19 ms after the first rejection) are rejected, tick 70
    // (20 ms) becomes the new reference, then everything is accepted.
    for (i, v) in verdicts.iter().enumerate() {
        let want = match i {
            0..20 => Verdict::Reject,
            20 => Verdict::Rereference,
            _ => Verdict::Accept,
        };
        assert_eq!(*v, want, "tick {}", 50 + i);
    }
    assert_eq!(f.rereferences(), 1);
    assert_eq!(f.rejected(), 20);
    assert_eq!(f.last_good_m(), Some(there));
}

#[test]
fn non_finite_samples_are_rejected_then_lost() {
    let mut f = filter();
    assert_eq!(f.check(T0, [0.0; 3]), Verdict::Accept);
    for (k, p) in [
        [f64::NAN, 0.0, 0.0],
        [0.0, f64::INFINITY, 0.0],
        [0.0, 0.0, f64::NEG_INFINITY],
    ]
    .into_iter()
    .enumerate()
    {
        assert_eq!(f.check(T0 + (1 + k as u64) * MS, p), Verdict::Reject);
    }
    assert_eq!(f.last_good_m(), Some([0.0; 3]));
    // A good sample ends the run.
    assert_eq!(f.check(T0 + 4 * MS, [0.0; 3]), Verdict::Accept);
    // 20 ms of NaN: lost; the next finite sample is a new reference.
    for k in 5..25u64 {
        assert_eq!(f.check(T0 + k * MS, [f64::NAN; 3]), Verdict::Reject, "{k}");
    }
    assert_eq!(f.check(T0 + 25 * MS, [f64::NAN; 3]), Verdict::Lost);
    assert_eq!(f.check(T0 + 26 * MS, [0.5; 3]), Verdict::Rereference);
    // Before any reference, NaN is rejected too.
    let mut f = filter();
    assert_eq!(f.check(T0, [f64::NAN; 3]), Verdict::Reject);
    assert_eq!(f.last_good_m(), None);
    assert_eq!(f.check(T0 + MS, [0.0; 3]), Verdict::Accept);
}

#[test]
fn the_clock_standing_still_allows_only_the_tolerance() {
    let mut f = filter();
    assert_eq!(f.check(T0, [0.0; 3]), Verdict::Accept);
    assert_eq!(f.check(T0, [0.001, 0.0, 0.0]), Verdict::Accept);
    assert_eq!(f.check(T0, [0.01, 0.0, 0.0]), Verdict::Reject);
    // A backward clock counts as no time.
    assert_eq!(f.check(T0 - MS, [0.01, 0.0, 0.0]), Verdict::Reject);
}

#[test]
fn configuration_errors() {
    let good = PlausibleConfig::default();
    assert_eq!(good.validate(), Ok(()));
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let c = PlausibleConfig {
            max_speed_m_s: bad,
            ..good
        };
        assert!(matches!(
            c.validate(),
            Err(PlausibleError::Limit {
                name: "max_speed_m_s",
                ..
            })
        ));
        let c = PlausibleConfig {
            max_accel_m_s2: bad,
            ..good
        };
        assert!(matches!(
            c.validate(),
            Err(PlausibleError::Limit {
                name: "max_accel_m_s2",
                ..
            })
        ));
    }
    let c = PlausibleConfig {
        tolerance_m: -1e-3,
        ..good
    };
    assert_eq!(c.validate(), Err(PlausibleError::Tolerance(-1e-3)));
    let c = PlausibleConfig {
        max_reject_run_ns: 0,
        ..good
    };
    assert_eq!(c.validate(), Err(PlausibleError::ZeroRun));
    // An invalid configuration falls back to the defaults.
    assert_eq!(Plausible::new(c).config(), &good);
}
