//! Hand-computed tests of every method and every degenerate case.

use super::*;

const MS: u64 = 1_000_000;

/// A sample with no contact (also for `local_problem`'s tests).
pub(super) fn sample(seq: u64, t_ns: u64, position_m: V3, force_n: V3) -> ForceSample {
    ForceSample {
        t_ns,
        seq,
        position_m,
        force_n,
        stiffness_n_per_m: [[0.0; 3]; 3],
        in_contact: false,
        catching_up: false,
    }
}

/// Samples at t = 0 and 10 ms, positions (0,0,0) and (0,0,1 cm), forces
/// (0,0,1) and (0,0,2) N.
fn two(method: Method) -> Extrapolator {
    let mut e = Extrapolator::new(method);
    e.push(&sample(1, 0, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]));
    e.push(&sample(2, 10 * MS, [0.0, 0.0, 0.01], [0.0, 0.0, 2.0]));
    e
}

fn close(a: V3, b: V3) -> bool {
    (0..3).all(|i| (a[i] - b[i]).abs() < 1e-12)
}

#[test]
fn names_round_trip() {
    let names: Vec<_> = Method::ALL.iter().map(|m| m.name()).collect();
    assert_eq!(
        names,
        [
            "constant",
            "linear-time",
            "linear-position",
            "linear-position-signed",
            "local-model",
            "local-normal",
            "local-problem"
        ]
    );
    for m in Method::ALL {
        assert_eq!(Method::parse(m.name()), Some(m));
        assert_eq!(Extrapolator::new(m).method(), m);
    }
    assert_eq!(Method::parse("Constant"), None);
    assert_eq!(Method::parse(""), None);
}

#[test]
fn no_sample_gives_zero() {
    for m in Method::ALL {
        let e = Extrapolator::new(m);
        assert_eq!(e.force(123, [1.0, 2.0, 3.0]), ZERO, "{}", m.name());
        assert!(e.latest().is_none());
    }
}

#[test]
fn one_sample_gives_constant() {
    for m in Method::ALL {
        let mut e = Extrapolator::new(m);
        e.push(&sample(1, 10 * MS, [0.0, 0.0, 0.01], [0.0, 0.0, 2.0]));
        // Stiffness is zero in `sample`, so the local model is constant too.
        assert_eq!(
            e.force(15 * MS, [0.0, 0.0, 0.02]),
            [0.0, 0.0, 2.0],
            "{}",
            m.name()
        );
    }
}

#[test]
fn constant_holds() {
    let e = two(Method::Constant);
    assert_eq!(e.force(15 * MS, [0.0, 0.0, 0.5]), [0.0, 0.0, 2.0]);
    assert_eq!(e.force(u64::MAX, [f64::NAN; 3]), [0.0, 0.0, 2.0]);
}

#[test]
fn linear_time_by_hand() {
    let e = two(Method::LinearTime);
    let p = [9.0, 9.0, 9.0]; // ignored by this method
    // 2 + (15 - 10) / (10 - 0) * (2 - 1) = 2.5
    assert!(close(e.force(15 * MS, p), [0.0, 0.0, 2.5]));
    assert!(close(e.force(10 * MS, p), [0.0, 0.0, 2.0]));
    assert!(close(e.force(12 * MS, p), [0.0, 0.0, 2.2]));
    // One period ahead, then held (horizon).
    assert!(close(e.force(20 * MS, p), [0.0, 0.0, 3.0]));
    assert!(close(e.force(1_000 * MS, p), [0.0, 0.0, 3.0]));
    assert!(close(e.force(u64::MAX, p), [0.0, 0.0, 3.0]));
    // Before the latest sample: no extrapolation backwards.
    assert!(close(e.force(5 * MS, p), [0.0, 0.0, 2.0]));
    assert!(close(e.force(0, p), [0.0, 0.0, 2.0]));
}

#[test]
fn linear_time_degenerate_times() {
    // Equal times.
    let mut e = Extrapolator::new(Method::LinearTime);
    e.push(&sample(1, 10 * MS, ZERO, [0.0, 0.0, 1.0]));
    e.push(&sample(2, 10 * MS, ZERO, [0.0, 0.0, 2.0]));
    assert_eq!(e.force(15 * MS, ZERO), [0.0, 0.0, 2.0]);
    // A newer seq with an older time is accepted but not extrapolated.
    e.push(&sample(3, 5 * MS, ZERO, [0.0, 0.0, 4.0]));
    assert_eq!(e.latest().unwrap().seq, 3);
    assert_eq!(e.force(15 * MS, ZERO), [0.0, 0.0, 4.0]);
}

#[test]
fn linear_position_by_hand() {
    let e = two(Method::LinearPosition);
    // Half a step further, 3 mm off the line: P' = (0,0,1.5 cm), factor 0.5.
    assert!(close(e.force(0, [0.003, 0.0, 0.015]), [0.0, 0.0, 2.5]));
    // Half a step back: the paper's ratio of norms still gives +0.5.
    assert!(close(e.force(0, [0.0, 0.0, 0.005]), [0.0, 0.0, 2.5]));
    // At P_n: F_n.
    assert!(close(e.force(0, [0.0, 0.0, 0.01]), [0.0, 0.0, 2.0]));
    // Five steps further: factor capped at 2, 2 + 2 * 1 = 4.
    assert!(close(e.force(0, [0.0, 0.0, 0.06]), [0.0, 0.0, 4.0]));
}

#[test]
fn linear_position_signed_by_hand() {
    let e = two(Method::LinearPositionSigned);
    assert!(close(e.force(0, [0.003, 0.0, 0.015]), [0.0, 0.0, 2.5]));
    // Half a step back: 2 - 0.5 = 1.5 (interpolates toward F_n-1).
    assert!(close(e.force(0, [0.0, 0.0, 0.005]), [0.0, 0.0, 1.5]));
    // At P_n-1: F_n-1.
    assert!(close(e.force(0, [0.0, 0.0, 0.0]), [0.0, 0.0, 1.0]));
    // Far either way: factor capped at +-2.
    assert!(close(e.force(0, [0.0, 0.0, 0.06]), [0.0, 0.0, 4.0]));
    assert!(close(e.force(0, [0.0, 0.0, -0.05]), [0.0, 0.0, 0.0]));
}

#[test]
fn position_methods_with_equal_positions_are_constant() {
    for m in [Method::LinearPosition, Method::LinearPositionSigned] {
        let mut e = Extrapolator::new(m);
        e.push(&sample(1, 0, [0.1, 0.0, 0.0], [0.0, 0.0, 1.0]));
        e.push(&sample(2, MS, [0.1, 0.0, 0.0], [0.0, 0.0, 2.0]));
        assert_eq!(
            e.force(2 * MS, [0.2, 0.0, 0.0]),
            [0.0, 0.0, 2.0],
            "{}",
            m.name()
        );
        // A step below MIN_STEP_M (0.5 nm) is still a standstill.
        e.push(&sample(3, 2 * MS, [0.1, 0.0, 0.5e-9], [0.0, 0.0, 3.0]));
        assert_eq!(
            e.force(3 * MS, [0.2, 0.0, 0.0]),
            [0.0, 0.0, 3.0],
            "{}",
            m.name()
        );
    }
}

#[test]
fn a_sample_catching_up_is_rendered_as_it_is_by_every_method() {
    // The simulated tool 5 mm above the hand, in contact: no method may
    // extrapolate from where the tool is to where the hand is.
    for m in Method::ALL {
        let mut e = Extrapolator::new(m);
        let mut s = sample(1, 0, [0.0, 0.0, 0.01], [0.0, 0.0, 0.5]);
        s.stiffness_n_per_m = [[300.0, 0.0, 0.0], [0.0, 300.0, 0.0], [0.0, 0.0, 300.0]];
        s.in_contact = true;
        e.push(&s);
        s.seq = 2;
        s.t_ns = MS;
        s.position_m = [0.0, 0.0, 0.009];
        s.force_n = [0.0, 0.0, 0.6];
        s.catching_up = true;
        e.push(&s);
        assert_eq!(
            e.force(2 * MS, [0.0, 0.0, 0.004]),
            [0.0, 0.0, 0.6],
            "{}",
            m.name()
        );
        // The same sample not flagged is extrapolated by the stiffness
        // methods (what the flag prevents).
        if matches!(m, Method::LocalModel | Method::LocalNormal) {
            s.seq = 3;
            s.catching_up = false;
            e.push(&s);
            assert!(e.force(2 * MS, [0.0, 0.0, 0.004])[2] > 2.0, "{}", m.name());
        }
    }
}

#[test]
fn local_model_by_hand() {
    let mut e = Extrapolator::new(Method::LocalModel);
    let mut s = sample(1, 0, [0.0, 0.0, 0.01], [0.0, 0.0, 1.0]);
    s.stiffness_n_per_m = [[100.0, 0.0, 0.0], [0.0, 200.0, 0.0], [0.0, 0.0, 300.0]];
    s.in_contact = true;
    e.push(&s);
    // One sample suffices: F_n + K (P_n - P)
    // = (0,0,1) + (100 * -0.001, 200 * 0.002, 300 * 0.005) = (-0.1, 0.4, 2.5).
    assert!(close(e.force(0, [0.001, -0.002, 0.005]), [-0.1, 0.4, 2.5]));
    // At P_n: F_n.
    assert!(close(e.force(0, [0.0, 0.0, 0.01]), [0.0, 0.0, 1.0]));
    // Not in contact: zero stiffness, F_n whatever K says.
    s.seq = 2;
    s.in_contact = false;
    e.push(&s);
    assert_eq!(e.force(0, [0.001, -0.002, 0.005]), [0.0, 0.0, 1.0]);
}

#[test]
fn push_ignores_non_finite_samples() {
    let mut e = two(Method::LinearTime);
    let mut bad = sample(3, 20 * MS, [0.0, 0.0, 0.02], [0.0, 0.0, f64::NAN]);
    e.push(&bad);
    bad.force_n = [0.0, 0.0, 3.0];
    bad.position_m = [f64::INFINITY, 0.0, 0.0];
    e.push(&bad);
    bad.position_m = [0.0; 3];
    bad.stiffness_n_per_m[1][2] = f64::NEG_INFINITY;
    e.push(&bad);
    assert_eq!(e.latest().unwrap().seq, 2);
    assert!(
        close(e.force(15 * MS, ZERO), [0.0, 0.0, 2.5]),
        "both old samples kept"
    );
}

#[test]
fn push_ignores_old_and_duplicate_seq() {
    let mut e = two(Method::LinearTime);
    e.push(&sample(2, 30 * MS, ZERO, [0.0, 0.0, 9.0]));
    e.push(&sample(1, 30 * MS, ZERO, [0.0, 0.0, 9.0]));
    assert_eq!(e.latest().unwrap().force_n, [0.0, 0.0, 2.0]);
    assert!(close(e.force(15 * MS, ZERO), [0.0, 0.0, 2.5]));
    // A gap in seq is fine (dropped messages).
    e.push(&sample(7, 20 * MS, ZERO, [0.0, 0.0, 3.0]));
    assert!(close(e.force(25 * MS, ZERO), [0.0, 0.0, 3.5]));
}

#[test]
fn reset_forgets_samples() {
    let mut e = two(Method::LinearTime);
    e.reset();
    assert_eq!(e.force(15 * MS, ZERO), ZERO);
    // A restarted simulation's seq 0 is accepted after the reset.
    e.push(&sample(0, 20 * MS, ZERO, [0.0, 0.0, 5.0]));
    assert_eq!(e.force(25 * MS, ZERO), [0.0, 0.0, 5.0]);
}

#[test]
fn non_finite_query_position_gives_latest_force() {
    for m in Method::ALL {
        let mut e = two(m);
        let mut s = sample(3, 20 * MS, [0.0, 0.0, 0.02], [0.0, 0.0, 3.0]);
        s.in_contact = true;
        s.stiffness_n_per_m = [[100.0; 3]; 3];
        e.push(&s);
        for p in [
            [f64::NAN, 0.0, 0.0],
            [0.0, f64::INFINITY, 0.0],
            [0.0, 0.0, f64::NEG_INFINITY],
        ] {
            let f = e.force(25 * MS, p);
            if m == Method::LinearTime {
                assert!(close(f, [0.0, 0.0, 3.5]), "position is irrelevant in time");
            } else {
                assert_eq!(f, [0.0, 0.0, 3.0], "{}", m.name());
            }
        }
    }
}

#[test]
fn overflow_falls_back_to_latest_force() {
    // Finite but huge, opposite forces: F_n - F_n-1 overflows.
    for m in [
        Method::LinearTime,
        Method::LinearPosition,
        Method::LinearPositionSigned,
    ] {
        let mut e = Extrapolator::new(m);
        e.push(&sample(1, 0, [0.0; 3], [0.0, 0.0, -f64::MAX]));
        e.push(&sample(2, 10 * MS, [0.0, 0.0, 0.01], [0.0, 0.0, f64::MAX]));
        assert_eq!(
            e.force(15 * MS, [0.0, 0.0, 0.015]),
            [0.0, 0.0, f64::MAX],
            "{}",
            m.name()
        );
    }
    let mut e = Extrapolator::new(Method::LocalModel);
    let mut s = sample(1, 0, [0.0; 3], [1.0, 0.0, 0.0]);
    s.in_contact = true;
    s.stiffness_n_per_m = [[f64::MAX; 3]; 3];
    e.push(&s);
    assert_eq!(e.force(0, [-f64::MAX, 0.0, 0.0]), [1.0, 0.0, 0.0]);
}
