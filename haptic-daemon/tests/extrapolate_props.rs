//! Property tests of the extrapolators: any input (NaN, inf, huge, zero,
//! non-monotone times) gives a finite force, and bounded inputs give a force
//! bounded in terms of the input magnitudes.

use haptic_daemon::extrapolate::{Extrapolator, ForceSample, MAX_POSITION_FACTOR, Method};
use haptic_daemon::math::{V3, norm, sub};
use proptest::prelude::*;

fn any_v3() -> impl Strategy<Value = V3> {
    [
        proptest::num::f64::ANY,
        proptest::num::f64::ANY,
        proptest::num::f64::ANY,
    ]
}

fn bounded_v3(r: f64) -> impl Strategy<Value = V3> {
    [-r..r, -r..r, -r..r]
}

fn sample(
    t: impl Strategy<Value = u64>,
    seq: impl Strategy<Value = u64>,
    v: impl Fn() -> BoxedStrategy<V3>,
    contact: impl Strategy<Value = bool>,
) -> impl Strategy<Value = ForceSample> {
    (t, seq, v(), v(), [v(), v(), v()], contact).prop_map(
        |(t_ns, seq, position_m, force_n, k, in_contact)| ForceSample {
            t_ns,
            seq,
            position_m,
            force_n,
            stiffness_n_per_m: k,
            in_contact,
            catching_up: false,
        },
    )
}

fn method() -> impl Strategy<Value = Method> {
    proptest::sample::select(Method::ALL.to_vec())
}

fn frobenius(k: &[[f64; 3]; 3]) -> f64 {
    norm([norm(k[0]), norm(k[1]), norm(k[2])])
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn any_input_gives_a_finite_force(
        m in method(),
        samples in proptest::collection::vec(
            sample(any::<u64>(), 0u64..8, || any_v3().boxed(), any::<bool>()), 0..5),
        queries in proptest::collection::vec((any::<u64>(), any_v3()), 1..5),
    ) {
        let mut e = Extrapolator::new(m);
        for s in &samples {
            e.push(s);
            for (t, p) in &queries {
                let f = e.force(*t, *p);
                prop_assert!(f.iter().all(|x| x.is_finite()), "{m:?} {f:?}");
            }
        }
        if let Some(l) = e.latest() {
            prop_assert!(l.is_finite());
        }
    }

    #[test]
    fn bounded_inputs_give_bounded_forces(
        m in method(),
        samples in proptest::collection::vec(
            sample(0u64..100_000_000, 0u64..8, || bounded_v3(1e3).boxed(), any::<bool>()), 0..5),
        t in 0u64..200_000_000,
        p in bounded_v3(1e3),
    ) {
        let mut e = Extrapolator::new(m);
        let mut accepted: Vec<ForceSample> = Vec::new();
        for s in &samples {
            e.push(s);
            if e.latest() == Some(s) && accepted.last() != Some(s) {
                accepted.push(*s);
            }
        }
        let f = e.force(t, p);
        let bound = match accepted.as_slice() {
            [] => 0.0,
            [.., last] if matches!(m, Method::LocalModel | Method::LocalNormal | Method::LocalProblem) => {
                norm(last.force_n) + frobenius(&last.stiffness_n_per_m) * norm(sub(last.position_m, p))
            }
            [last] => norm(last.force_n),
            [.., prev, last] => {
                (1.0 + MAX_POSITION_FACTOR) * norm(last.force_n) + MAX_POSITION_FACTOR * norm(prev.force_n)
            }
        };
        prop_assert!(norm(f) <= bound * (1.0 + 1e-12) + 1e-12, "{m:?}: |{f:?}| > {bound}");
    }

    #[test]
    fn constant_is_the_latest_force(
        samples in proptest::collection::vec(
            sample(any::<u64>(), any::<u64>(), || bounded_v3(1e6).boxed(), any::<bool>()), 1..5),
        t in any::<u64>(),
        p in any_v3(),
    ) {
        let mut e = Extrapolator::new(Method::Constant);
        for s in &samples {
            e.push(s);
        }
        prop_assert_eq!(e.force(t, p), e.latest().unwrap().force_n);
    }

    #[test]
    fn paper_factor_is_the_absolute_signed_factor(
        p0 in bounded_v3(1.0), p1 in bounded_v3(1.0), p in bounded_v3(1.0),
    ) {
        use haptic_daemon::extrapolate::{paper_position_factor, signed_position_factor};
        match (paper_position_factor(p0, p1, p), signed_position_factor(p0, p1, p)) {
            (Some(a), Some(s)) => prop_assert!((a - s.abs()).abs() < 1e-6, "{a} vs {s}"),
            (a, s) => prop_assert!(a.is_none() && s.is_none(), "{a:?} vs {s:?}"),
        }
    }
}
