//! Small fixed-size vector helpers (no allocation, plain arrays as in the protocol).
//!
//! Everything here is a pure function on `[f64; 3]` so that the real-time
//! modules (`extrapolate`, `safety`) stay allocation-free and testable. The
//! norm is computed with scaling so that huge but finite vectors (1e200 N
//! from a diverging simulation) do not overflow to infinity on the way: the
//! callers rely on "finite in, finite out" wherever the true result is
//! representable.

/// A 3-vector.
pub type V3 = [f64; 3];

/// A 3x3 matrix, row-major (as in the protocol).
pub type M3 = [[f64; 3]; 3];

/// The zero vector.
pub const ZERO: V3 = [0.0; 3];

/// `a + b`.
#[inline]
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `a - b`.
#[inline]
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `k a`.
#[inline]
pub fn scale(a: V3, k: f64) -> V3 {
    [a[0] * k, a[1] * k, a[2] * k]
}

/// `a . b`.
#[inline]
pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `m a` for a row-major matrix.
#[inline]
pub fn mat_vec(m: &M3, a: V3) -> V3 {
    [dot(m[0], a), dot(m[1], a), dot(m[2], a)]
}

/// All three components are finite.
#[inline]
pub fn is_finite(a: V3) -> bool {
    a.iter().all(|x| x.is_finite())
}

/// All nine entries are finite.
#[inline]
pub fn is_finite_m3(m: &M3) -> bool {
    m.iter().all(|r| is_finite(*r))
}

/// Euclidean norm, scaled so that it does not overflow for finite vectors
/// whose norm is representable (`|[1e200; 3]|` is 1.7e200, not inf).
/// NaN if a component is NaN, inf if one is infinite.
pub fn norm(a: V3) -> f64 {
    let m = a[0].abs().max(a[1].abs()).max(a[2].abs());
    if a.iter().any(|x| x.is_nan()) {
        return f64::NAN;
    }
    if m == 0.0 || !m.is_finite() {
        return m;
    }
    // Divide rather than multiply by 1/m: exact for the largest component,
    // so the norm of an axis-aligned vector is exactly its component.
    let s = [a[0] / m, a[1] / m, a[2] / m];
    m * dot(s, s).sqrt()
}

/// `a` shortened, direction kept, so that `|a| <= limit`; `a` itself when
/// already inside. Returns zero for a non-finite `a` or a limit that is not
/// a positive finite number: a caller that asks for a clamp wants a safe
/// vector, and zero is the only one that is safe without more information.
pub fn clamp_norm(a: V3, limit: f64) -> V3 {
    if !is_finite(a) || !limit.is_finite() || limit <= 0.0 {
        return ZERO;
    }
    let n = norm(a);
    if n <= limit {
        return a;
    }
    // n > limit > 0, so the ratio lies in (0, 1) and the result is finite.
    scale(a, limit / n)
}

/// Moves from `from` toward `to` by at most `max_step` (Euclidean). Both
/// vectors must be finite; a non-finite or negative `max_step` counts as 0
/// (no move), an infinite one as "no limit".
pub fn step_toward(from: V3, to: V3, max_step: f64) -> V3 {
    let max_step = if max_step.is_nan() || max_step < 0.0 {
        0.0
    } else {
        max_step
    };
    let d = sub(to, from);
    let n = norm(d);
    if !n.is_finite() {
        // The difference overflowed (opposite huge vectors): no finite
        // straight-line step is computable, so stay put.
        return from;
    }
    if n <= max_step {
        return to;
    }
    // n > max_step >= 0, so n > 0 and the ratio lies in [0, 1).
    add(from, scale(d, max_step / n))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basic_algebra() {
        assert_eq!(add([1.0, 2.0, 3.0], [1.0, 1.0, 1.0]), [2.0, 3.0, 4.0]);
        assert_eq!(sub([1.0, 2.0, 3.0], [1.0, 1.0, 1.0]), [0.0, 1.0, 2.0]);
        assert_eq!(scale([1.0, 2.0, 3.0], 2.0), [2.0, 4.0, 6.0]);
        assert_eq!(dot([1.0, 2.0, 3.0], [4.0, 5.0, 6.0]), 32.0);
        let m = [[1.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 3.0]];
        assert_eq!(mat_vec(&m, [1.0, 1.0, 1.0]), [3.0, 1.0, 3.0]);
    }

    #[test]
    fn norm_does_not_overflow() {
        assert_eq!(norm([3.0, 4.0, 0.0]), 5.0);
        assert_eq!(norm(ZERO), 0.0);
        let n = norm([1e200, 1e200, 1e200]);
        assert!((n / 1e200 - 3f64.sqrt()).abs() < 1e-12);
        assert!(norm([f64::NAN, 0.0, 0.0]).is_nan());
        assert_eq!(norm([f64::NEG_INFINITY, 0.0, 0.0]), f64::INFINITY);
    }

    #[test]
    fn clamp_keeps_direction() {
        assert_eq!(clamp_norm([3.0, 4.0, 0.0], 10.0), [3.0, 4.0, 0.0]);
        let c = clamp_norm([3.0, 4.0, 0.0], 1.0);
        assert!((c[0] - 0.6).abs() < 1e-15 && (c[1] - 0.8).abs() < 1e-15 && c[2] == 0.0);
        assert_eq!(clamp_norm([f64::NAN, 0.0, 0.0], 1.0), ZERO);
        assert_eq!(clamp_norm([1.0, 0.0, 0.0], f64::NAN), ZERO);
        assert_eq!(clamp_norm([1.0, 0.0, 0.0], 0.0), ZERO);
        assert!(norm(clamp_norm([f64::MAX, f64::MAX, 0.0], 2.0)) <= 2.0 + 1e-15);
    }

    #[test]
    fn step_is_limited() {
        assert_eq!(step_toward(ZERO, [0.0, 0.0, 2.0], 0.5), [0.0, 0.0, 0.5]);
        assert_eq!(step_toward(ZERO, [0.0, 0.0, 2.0], 5.0), [0.0, 0.0, 2.0]);
        assert_eq!(step_toward(ZERO, [0.0, 0.0, 2.0], 0.0), ZERO);
        assert_eq!(step_toward(ZERO, [0.0, 0.0, 2.0], f64::NAN), ZERO);
        assert_eq!(step_toward(ZERO, ZERO, 0.0), ZERO);
        assert_eq!(
            step_toward(ZERO, [0.0, 0.0, 2.0], f64::INFINITY),
            [0.0, 0.0, 2.0]
        );
        let big = [f64::MAX, 0.0, 0.0];
        assert_eq!(step_toward(big, scale(big, -1.0), 1.0), big);
    }
}
