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
/// simulation's contact field, `tissue::contact::penalty::field::spring`).
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

/// The inverse of L L^T into `out` (row-major n x n, exactly symmetric)
/// from the factor of [`cholesky`], `scratch` n x n: L^-1 by rows, then
/// L^-T L^-1 as a sum of the rows' outer products, both in row slices
/// that vectorise (n^3 / 2 multiply-adds; the problem's set-up inverts up
/// to three 72 x 72 matrices a problem, which solving the unit columns
/// one by one made most of the set-up thread's time).
pub(super) fn cholesky_inverse(l: &[f64], scratch: &mut Vec<f64>, out: &mut Vec<f64>, n: usize) {
    scratch.clear();
    scratch.resize(n * n, 0.0);
    for i in 0..n {
        let (done, rest) = scratch.split_at_mut(i * n);
        let row = &mut rest[..n];
        row[i] = 1.0;
        for k in 0..i {
            let f = l[i * n + k];
            if f != 0.0 {
                for (r, x) in row[..=k].iter_mut().zip(&done[k * n..k * n + k + 1]) {
                    *r -= f * x;
                }
            }
        }
        let d = 1.0 / l[i * n + i];
        row[..=i].iter_mut().for_each(|r| *r *= d);
    }
    out.clear();
    out.resize(n * n, 0.0);
    for k in 0..n {
        let rk = &scratch[k * n..k * n + k + 1];
        for (i, &a) in rk.iter().enumerate() {
            if a != 0.0 {
                for (x, y) in out[i * n..i * n + k + 1].iter_mut().zip(rk) {
                    *x += a * y;
                }
            }
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cholesky_inverse_inverts_and_is_symmetric() {
        let n = 7;
        // A = B B^T + n I, B with entries of both signs.
        let b: Vec<f64> = (0..n * n).map(|i| ((i * 37) % 11) as f64 - 5.0).collect();
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                a[i * n + j] = (0..n).map(|k| b[i * n + k] * b[j * n + k]).sum::<f64>()
                    + if i == j { n as f64 } else { 0.0 };
            }
        }
        let mut l = a.clone();
        assert!(cholesky(&mut l, n));
        let (mut scratch, mut inv) = (Vec::new(), Vec::new());
        cholesky_inverse(&l, &mut scratch, &mut inv, n);
        for i in 0..n {
            for j in 0..n {
                let ai: f64 = (0..n).map(|k| a[i * n + k] * inv[k * n + j]).sum();
                let id = if i == j { 1.0 } else { 0.0 };
                assert!((ai - id).abs() < 1e-12, "({i}, {j}): {ai}");
                assert_eq!(inv[i * n + j], inv[j * n + i]);
            }
        }
    }
}
