//! The extrapolation formulas as small pure functions (paper section 7,
//! eq 31 and 32, plus the signed and local-model variants).
//!
//! Each function returns `None` where its formula is degenerate (the caller
//! then falls back to the constant force); the bounds below are the
//! extrapolation horizon. Nothing here allocates, reads a clock or panics.

use crate::math::{M3, V3, add, dot, mat_vec, norm, scale, sub};

/// Below this distance between the two sample positions (m) the position
/// methods fall back to the constant force: the direction of motion is
/// undefined and the ratio `|P' - P_n| / |P_n - P_n-1|` divides by ~0.
/// 1 nm is far below any haptic device's resolution (~10 um), so a real
/// motion is never mistaken for a standstill.
pub const MIN_STEP_M: f64 = 1e-9;

/// Largest time factor `(t - t_n) / (t_n - t_n-1)`: the linear-in-time
/// extrapolation goes at most one sample period past the latest sample and
/// then holds. A late simulation thus never makes the force run away; the
/// safety filter's age watchdog handles samples that stay stale.
pub const MAX_TIME_FACTOR: f64 = 1.0;

/// Largest magnitude of the position factor: the force changes by at most
/// twice the last step's change. Twice, not once, because a hand
/// accelerating between samples legitimately moves further than during the
/// last step; beyond that the linearisation is not trustworthy (and a jump
/// of the tool, e.g. a tracking glitch, must not produce a force peak).
pub const MAX_POSITION_FACTOR: f64 = 2.0;

/// The time factor of eq 31, `(now - t_n) / (t_n - t_n-1)` clamped to
/// `[0, MAX_TIME_FACTOR]`: `now` before `t_n` (clock skew) gives 0.
/// `None` when the sample times are equal or decreasing.
pub fn time_factor(t_prev_ns: u64, t_last_ns: u64, now_ns: u64) -> Option<f64> {
    if t_last_ns <= t_prev_ns {
        return None;
    }
    let period = (t_last_ns - t_prev_ns) as f64;
    let elapsed = now_ns.saturating_sub(t_last_ns) as f64;
    // period >= 1 and both are finite, so the ratio is finite and >= 0.
    Some((elapsed / period).min(MAX_TIME_FACTOR))
}

/// The unit direction of the last step and its length, `None` when the
/// step is shorter than [`MIN_STEP_M`] or not computable.
fn step_direction(p_prev_m: V3, p_last_m: V3) -> Option<(V3, f64)> {
    let d = sub(p_last_m, p_prev_m);
    let n = norm(d);
    // `!(n >= MIN)` also catches NaN and the overflow of two huge positions.
    if !(n >= MIN_STEP_M && n.is_finite()) {
        return None;
    }
    Some((scale(d, 1.0 / n), n))
}

/// The signed position factor `s = (P - P_n).(P_n - P_n-1) / |P_n - P_n-1|^2`,
/// clamped to `[-MAX_POSITION_FACTOR, MAX_POSITION_FACTOR]`. Negative when
/// the tool went back toward `P_n-1`. `None` for a degenerate step or a
/// non-finite result (e.g. a NaN query position).
pub fn signed_position_factor(p_prev_m: V3, p_last_m: V3, p_m: V3) -> Option<f64> {
    let (u, n) = step_direction(p_prev_m, p_last_m)?;
    // Divide once by n after projecting on the unit vector, rather than by
    // n^2, so that n^2 cannot underflow or overflow.
    let s = dot(sub(p_m, p_last_m), u) / n;
    s.is_finite()
        .then(|| s.clamp(-MAX_POSITION_FACTOR, MAX_POSITION_FACTOR))
}

/// The paper's position factor (eq 32) as it is written: `P'` is the
/// projection of `P` on the line `(P_n-1, P_n)` and the factor is
/// `|P' - P_n| / |P_n - P_n-1|`, clamped to `[0, MAX_POSITION_FACTOR]`.
/// Equal to `|s|` of [`signed_position_factor`]: the ratio of norms loses
/// the sign, so a tool moving back still extrapolates forward (kept on
/// purpose, to measure it). `None` as for the signed factor.
pub fn paper_position_factor(p_prev_m: V3, p_last_m: V3, p_m: V3) -> Option<f64> {
    let (u, n) = step_direction(p_prev_m, p_last_m)?;
    let p_proj = add(p_prev_m, scale(u, dot(sub(p_m, p_prev_m), u)));
    let k = norm(sub(p_proj, p_last_m)) / n;
    k.is_finite().then(|| k.min(MAX_POSITION_FACTOR))
}

/// `F_n + k (F_n - F_n-1)`: the common form of eq 31 and 32.
pub fn linear(f_prev_n: V3, f_last_n: V3, k: f64) -> V3 {
    add(f_last_n, scale(sub(f_last_n, f_prev_n), k))
}

/// The local model `F = F_n + K (P_n - P)`: the contact stiffness `K`
/// (dF = -K dP) frozen at the latest sample.
pub fn local_model(f_last_n: V3, k_n_per_m: &M3, p_last_m: V3, p_m: V3) -> V3 {
    add(f_last_n, mat_vec(k_n_per_m, sub(p_last_m, p_m)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: V3, b: V3) -> bool {
        (0..3).all(|i| (a[i] - b[i]).abs() < 1e-12)
    }

    #[test]
    fn time_factor_by_hand() {
        // Samples at 0 and 10 ms.
        assert_eq!(time_factor(0, 10_000_000, 15_000_000), Some(0.5));
        assert_eq!(time_factor(0, 10_000_000, 10_000_000), Some(0.0));
        assert_eq!(time_factor(0, 10_000_000, 20_000_000), Some(1.0));
        // Capped at one period ahead.
        assert_eq!(time_factor(0, 10_000_000, 1_000_000_000), Some(1.0));
        assert_eq!(time_factor(0, 10_000_000, u64::MAX), Some(1.0));
        // Query before the latest sample (clock skew): no extrapolation.
        assert_eq!(time_factor(0, 10_000_000, 5_000_000), Some(0.0));
        // Equal and decreasing sample times are degenerate.
        assert_eq!(time_factor(10, 10, 20), None);
        assert_eq!(time_factor(20, 10, 30), None);
    }

    #[test]
    fn signed_factor_by_hand() {
        let (p0, p1) = ([0.0, 0.0, 0.0], [0.0, 0.0, 0.01]);
        // Half a step further, off the line by 3 mm (the offset is ignored).
        let s = signed_position_factor(p0, p1, [0.003, 0.0, 0.015]).unwrap();
        assert!((s - 0.5).abs() < 1e-12);
        // Half a step back.
        let s = signed_position_factor(p0, p1, [0.0, 0.0, 0.005]).unwrap();
        assert!((s + 0.5).abs() < 1e-12);
        // Clamped both ways.
        assert_eq!(signed_position_factor(p0, p1, [0.0, 0.0, 0.05]), Some(2.0));
        assert_eq!(
            signed_position_factor(p0, p1, [0.0, 0.0, -0.05]),
            Some(-2.0)
        );
    }

    #[test]
    fn paper_factor_by_hand_loses_the_sign() {
        let (p0, p1) = ([0.0, 0.0, 0.0], [0.0, 0.0, 0.01]);
        // P' = (0, 0, 0.015): |P' - P1| / |P1 - P0| = 0.005 / 0.01.
        let k = paper_position_factor(p0, p1, [0.003, 0.0, 0.015]).unwrap();
        assert!((k - 0.5).abs() < 1e-12);
        // Moving back gives the same positive factor.
        let k = paper_position_factor(p0, p1, [0.0, 0.004, 0.005]).unwrap();
        assert!((k - 0.5).abs() < 1e-12);
        assert_eq!(paper_position_factor(p0, p1, [0.0, 0.0, 0.05]), Some(2.0));
        // A diagonal step: P0 = 0, P1 = (1, 1, 0) mm, P = (2, 0, 0) mm
        // projects on (1, 1, 0) mm = P1, so the factor is 0.
        let k = paper_position_factor(p0, [1e-3, 1e-3, 0.0], [2e-3, 0.0, 0.0]).unwrap();
        assert!(k.abs() < 1e-12);
    }

    #[test]
    fn degenerate_steps() {
        let p = [0.1, 0.2, 0.3];
        let q = [0.1, 0.2, 0.3 + 0.5e-9];
        for f in [signed_position_factor, paper_position_factor] {
            assert_eq!(f(p, p, [1.0, 1.0, 1.0]), None, "equal positions");
            assert_eq!(f(p, q, [1.0, 1.0, 1.0]), None, "below MIN_STEP_M");
            assert_eq!(
                f(p, [0.1, 0.2, 0.4], [f64::NAN, 0.0, 0.0]),
                None,
                "NaN query"
            );
            assert_eq!(
                f(p, [0.1, 0.2, 0.4], [f64::INFINITY, 0.0, 0.0]),
                None,
                "inf query"
            );
            assert_eq!(
                f([-f64::MAX, 0.0, 0.0], [f64::MAX, 0.0, 0.0], p),
                None,
                "overflow"
            );
        }
        // Exactly MIN_STEP_M is a usable step.
        assert!(signed_position_factor([0.0; 3], [0.0, 0.0, MIN_STEP_M], [0.0; 3]).is_some());
    }

    #[test]
    fn linear_and_local_by_hand() {
        assert!(close(
            linear([0.0, 0.0, 1.0], [0.0, 0.0, 2.0], 0.5),
            [0.0, 0.0, 2.5]
        ));
        assert!(close(
            linear([0.0, 0.0, 1.0], [0.0, 0.0, 2.0], -0.5),
            [0.0, 0.0, 1.5]
        ));
        let k = [[100.0, 0.0, 0.0], [0.0, 200.0, 0.0], [0.0, 0.0, 300.0]];
        // K (P_n - P) = (100 * -0.001, 200 * 0.002, 300 * 0.005).
        let f = local_model(
            [0.0, 0.0, 1.0],
            &k,
            [0.0, 0.0, 0.01],
            [0.001, -0.002, 0.005],
        );
        assert!(close(f, [-0.1, 0.4, 2.5]));
        // Off-diagonal coupling: a y displacement pushes along x.
        let k = [[0.0, 10.0, 0.0], [0.0; 3], [0.0; 3]];
        let f = local_model([0.0; 3], &k, [0.0, 0.1, 0.0], [0.0; 3]);
        assert!(close(f, [1.0, 0.0, 0.0]));
    }
}
