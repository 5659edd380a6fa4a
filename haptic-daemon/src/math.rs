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

/// Frobenius norm of a matrix (an upper bound of its spectral norm, at most
/// `sqrt(3)` times it for a 3x3 matrix). NaN or inf for non-finite entries.
pub fn frobenius(m: &M3) -> f64 {
    let rows = [norm(m[0]), norm(m[1]), norm(m[2])];
    norm(rows)
}

/// Spectral norm (largest singular value) of a 3x3 matrix: the largest
/// gain `|m a| / |a|`, equal to the largest `|eigenvalue|` of a symmetric
/// matrix. Closed form (the largest eigenvalue of the symmetric `m^T m` by
/// the trigonometric method), clamped into `[|m|_F / sqrt(3), |m|_F]`, the
/// bounds any 3x3 matrix satisfies, so rounding can never make it exceed
/// the conservative Frobenius norm. NaN or inf for non-finite entries.
pub fn spectral_norm(m: &M3) -> f64 {
    let f = frobenius(m);
    if !f.is_finite() || f == 0.0 {
        return f;
    }
    // Work on m / |m|_F so that m^T m cannot overflow or underflow.
    let a: M3 = std::array::from_fn(|i| scale(m[i], 1.0 / f));
    // b = a^T a (symmetric, positive semi-definite, trace 1).
    let b: M3 =
        std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[k][i] * a[k][j]).sum()));
    let p1 = b[0][1].powi(2) + b[0][2].powi(2) + b[1][2].powi(2);
    let q = (b[0][0] + b[1][1] + b[2][2]) / 3.0;
    let p2 = (b[0][0] - q).powi(2) + (b[1][1] - q).powi(2) + (b[2][2] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    let lambda_max = if p <= 1e-300 {
        q
    } else {
        // c = (b - q I) / p; r = det(c) / 2 lies in [-1, 1] up to rounding.
        let c: M3 = std::array::from_fn(|i| {
            std::array::from_fn(|j| (b[i][j] - if i == j { q } else { 0.0 }) / p)
        });
        let det = c[0][0] * (c[1][1] * c[2][2] - c[1][2] * c[2][1])
            - c[0][1] * (c[1][0] * c[2][2] - c[1][2] * c[2][0])
            + c[0][2] * (c[1][0] * c[2][1] - c[1][1] * c[2][0]);
        let phi = (det / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
        q + 2.0 * p * phi.cos()
    };
    // lambda_max of a^T a is sigma_max^2 / |m|_F^2, in [1/3, 1].
    let ratio = lambda_max.clamp(1.0 / 3.0, 1.0).sqrt();
    f * ratio
}

/// The positive semi-definite part of a stiffness: the symmetric part of
/// `m` with its negative eigenvalues set to zero (the nearest PSD matrix
/// in the Frobenius norm). A contact's stiffness is indefinite where the
/// contact itself is unstable (a round tool on a curved surface turns the
/// forces away as it moves sideways): rendered, a negative stiffness
/// pushes the hand further along, injecting energy, and on the liver it
/// swung by +-80 N/m from one 30 Hz sample to the next. Cyclic Jacobi
/// rotations (a handful of sweeps for a 3x3; written here rather than
/// pulling a linear-algebra crate into the real-time daemon for one 3x3,
/// and it allocates nothing). A non-finite `m` is returned unchanged.
pub fn positive_part(m: &M3) -> M3 {
    if !is_finite_m3(m) {
        return *m;
    }
    let mut a: M3 = std::array::from_fn(|i| std::array::from_fn(|j| 0.5 * (m[i][j] + m[j][i])));
    let mut v: M3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..32 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        let diag = a[0][0].powi(2) + a[1][1].powi(2) + a[2][2].powi(2);
        if off <= 1e-30 * diag || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            // The rotation zeroing a[p][q] (Numerical Recipes' jacobi).
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = if theta == 0.0 {
                1.0
            } else {
                theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
            };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in &mut a {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
            let (rp, rq) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
            a[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
            for row in &mut v {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
        }
    }
    let lambda = [a[0][0].max(0.0), a[1][1].max(0.0), a[2][2].max(0.0)];
    std::array::from_fn(|i| {
        std::array::from_fn(|j| (0..3).map(|k| v[i][k] * lambda[k] * v[j][k]).sum())
    })
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
    fn matrix_norms() {
        let d = [[100.0, 0.0, 0.0], [0.0, -300.0, 0.0], [0.0, 0.0, 200.0]];
        assert!((spectral_norm(&d) - 300.0).abs() < 1e-9);
        assert!((frobenius(&d) - (14e4f64).sqrt()).abs() < 1e-9);
        // Rank one k n n^T: both norms are k.
        let n = [0.6, 0.0, 0.8];
        let r: M3 = std::array::from_fn(|i| scale(n, 500.0 * n[i]));
        assert!((spectral_norm(&r) - 500.0).abs() < 1e-9);
        assert!((frobenius(&r) - 500.0).abs() < 1e-9);
        // Isotropic: the Frobenius norm is sqrt(3) too large.
        let i3 = [[7.0, 0.0, 0.0], [0.0, 7.0, 0.0], [0.0, 0.0, 7.0]];
        assert!((spectral_norm(&i3) - 7.0).abs() < 1e-9);
        // Non-symmetric: [[0, 10, 0], 0, 0] maps y to 10 x.
        let s = [[0.0, 10.0, 0.0], [0.0; 3], [0.0; 3]];
        assert!((spectral_norm(&s) - 10.0).abs() < 1e-9);
        // A rotation-like shear: singular values of [[1, 1], [0, 1]] are
        // the golden ratio and its inverse.
        let sh = [[1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]];
        assert!((spectral_norm(&sh) - (1.0 + 5f64.sqrt()) / 2.0).abs() < 1e-9);
        assert_eq!(spectral_norm(&[[0.0; 3]; 3]), 0.0);
        assert!(spectral_norm(&[[f64::NAN; 3]; 3]).is_nan());
        let huge = [[1e300; 3]; 3];
        assert!(spectral_norm(&huge).is_finite());
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

    fn rotate(d: [f64; 3]) -> M3 {
        // R diag(d) R^T for a rotation about a skew axis.
        let (c, sn) = (0.6_f64, 0.8_f64);
        let rz: M3 = [[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]];
        let rx: M3 = [[1.0, 0.0, 0.0], [0.0, c, -sn], [0.0, sn, c]];
        let r: M3 = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..3).map(|k| rz[i][k] * rx[k][j]).sum())
        });
        std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..3).map(|k| r[i][k] * d[k] * r[j][k]).sum())
        })
    }

    fn max_diff(a: &M3, b: &M3) -> f64 {
        (0..9)
            .map(|k| (a[k / 3][k % 3] - b[k / 3][k % 3]).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn positive_part_keeps_a_psd_stiffness_and_drops_negative_directions() {
        let psd = rotate([300.0, 20.0, 0.0]);
        assert!(
            max_diff(&positive_part(&psd), &psd) < 1e-9,
            "{:?}",
            positive_part(&psd)
        );
        let indefinite = rotate([300.0, -80.0, 20.0]);
        let expected = rotate([300.0, 0.0, 20.0]);
        let got = positive_part(&indefinite);
        assert!(
            max_diff(&got, &expected) < 1e-9,
            "{got:?} against {expected:?}"
        );
        // Negative definite: nothing left.
        assert!(max_diff(&positive_part(&rotate([-5.0, -1.0, -2.0])), &[[0.0; 3]; 3]) < 1e-12);
        // The asymmetric part goes; a non-finite matrix comes back as is.
        let skew = [[1.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let sym = positive_part(&skew);
        assert!((sym[0][1] - sym[1][0]).abs() < 1e-12);
        let bad = [[f64::NAN, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(positive_part(&bad)[0][0].is_nan());
    }
}
