//! Small dense helpers of [`super::LocalProblem`]: the capsule distance,
//! the spring law, Cholesky and LU on fixed buffers (hand-written: they run
//! on the RT thread on buffers allocated once, for n of a few tens, where a
//! dense crate's factorisations allocate their results).

use crate::math::{V3, add, dot, scale, sub};

/// The point of segment a-b closest to `y`, and whether it lies strictly
/// inside.
pub(super) fn closest_on_segment(a: V3, b: V3, y: V3) -> (V3, bool) {
    let d = sub(b, a);
    let l2 = dot(d, d);
    if l2 <= 0.0 {
        return (a, false);
    }
    let t = dot(sub(y, a), d) / l2;
    if t <= 0.0 {
        (a, false)
    } else if t >= 1.0 {
        (b, false)
    } else {
        (add(a, scale(d, t)), true)
    }
}

/// A point's spring at penetration `d` (m): energy (J), force (N) and
/// slope (N/m), with the quadratic onset over `d0` (the law of the
/// simulation's contact field, `tissue::contact::field::spring`).
pub(super) fn spring(k: f64, d: f64, d0: f64) -> (f64, f64, f64) {
    if d < d0 {
        (
            k * d * d * d / (6.0 * d0),
            k * d * d / (2.0 * d0),
            k * d / d0,
        )
    } else {
        (
            k * (d0 * d0 / 6.0 + 0.5 * (d * d - d0 * d0) - 0.5 * d0 * (d - d0)),
            k * (d - 0.5 * d0),
            k,
        )
    }
}

/// Cholesky factor L (lower, in place, row-major n x n) of a symmetric
/// matrix; false if it is not positive definite. Hand-written: it runs on
/// the RT thread on fixed buffers, for n of a few tens.
pub(super) fn cholesky(a: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if d.is_nan() || d <= 0.0 || !d.is_finite() {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / d;
        }
    }
    true
}

/// Solves A x = b in place (A n x n row-major, destroyed) by Gaussian
/// elimination with partial pivoting; false if A is singular.
pub(super) fn lu_solve(a: &mut [f64], b: &mut [f64], n: usize) -> bool {
    for col in 0..n {
        let mut pivot = col;
        for r in col + 1..n {
            if a[r * n + col].abs() > a[pivot * n + col].abs() {
                pivot = r;
            }
        }
        let d = a[pivot * n + col];
        if d.abs() <= 1e-300 || d.is_nan() {
            return false;
        }
        if pivot != col {
            for j in 0..n {
                a.swap(col * n + j, pivot * n + j);
            }
            b.swap(col, pivot);
        }
        for r in col + 1..n {
            let f = a[r * n + col] / d;
            if f != 0.0 {
                for j in col..n {
                    a[r * n + j] -= f * a[col * n + j];
                }
                b[r] -= f * b[col];
            }
        }
    }
    for r in (0..n).rev() {
        let x = (r + 1..n).fold(b[r], |x, j| x - a[r * n + j] * b[j]);
        b[r] = x / a[r * n + r];
    }
    b.iter().all(|x| x.is_finite())
}

/// Solves L L^T x = b in place with the factor of [`cholesky`].
pub(super) fn cholesky_solve(l: &[f64], b: &mut [f64], n: usize) {
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * n + k] * b[k];
        }
        b[i] = s / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= l[k * n + i] * b[k];
        }
        b[i] = s / l[i * n + i];
    }
}
