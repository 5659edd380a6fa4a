//! Scalar and small fixed-size types used across the crate.
//!
//! Physics is set up and verified in `f64` (glam's `DVec3`/`DMat3`); only the
//! hot stiffness kernel may store its blocks in `f32` (see [`crate::tensor_mass::kernel`]).

/// The scalar of all set-up, verification and state arrays.
pub type Real = f64;
/// A 3-vector in metres, newtons, ... (units are in the field names).
pub type Vec3 = glam::DVec3;
/// A 3x3 tensor (column-major, glam convention).
pub type Mat3 = glam::DMat3;

/// The outer product `u v^T` (the paper's `u (x) v`).
#[inline]
pub fn outer(u: Vec3, v: Vec3) -> Mat3 {
    Mat3::from_cols(u * v.x, u * v.y, u * v.z)
}

/// Largest absolute entry of a 3x3 tensor.
#[inline]
pub fn max_abs(m: &Mat3) -> Real {
    m.to_cols_array().iter().fold(0.0, |a, x| a.max(x.abs()))
}

/// Signed volume of the tetrahedron (a, b, c, d): positive when (b-a, c-a, d-a) is right-handed.
#[inline]
pub fn tet_signed_volume(a: Vec3, b: Vec3, c: Vec3, d: Vec3) -> Real {
    (b - a).cross(c - a).dot(d - a) / 6.0
}

/// Solves M X = B in place (M n x n row-major, B n x k row-major, X
/// written into B) by Gaussian elimination with partial pivoting; false if
/// M is singular. Hand-written because it runs every step on buffers kept
/// across steps (a dense crate's LU would allocate its factors each time),
/// for n of a few tens.
pub(crate) fn solve_in_place(m: &mut [Real], b: &mut [Real], n: usize, k: usize) -> bool {
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&i, &j| m[i * n + col].abs().total_cmp(&m[j * n + col].abs()))
            .unwrap_or(col);
        if m[pivot * n + col].abs() < 1e-300 {
            return false;
        }
        if pivot != col {
            for j in 0..n {
                m.swap(col * n + j, pivot * n + j);
            }
            for j in 0..k {
                b.swap(col * k + j, pivot * k + j);
            }
        }
        let d = m[col * n + col];
        for i in col + 1..n {
            let f = m[i * n + col] / d;
            if f == 0.0 {
                continue;
            }
            for j in col..n {
                m[i * n + j] -= f * m[col * n + j];
            }
            for j in 0..k {
                b[i * k + j] -= f * b[col * k + j];
            }
        }
    }
    for col in (0..n).rev() {
        let d = m[col * n + col];
        for j in 0..k {
            let mut x = b[col * k + j];
            for i in col + 1..n {
                x -= m[col * n + i] * b[i * k + j];
            }
            b[col * k + j] = x / d;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outer_is_u_v_transposed() {
        let m = outer(Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0));
        // row 1, column 2 (0-based) = u.y * v.z
        assert_eq!(m.col(2).y, 12.0);
        assert_eq!(m.col(0).z, 12.0);
        assert_eq!(m * Vec3::X, Vec3::new(4.0, 8.0, 12.0));
    }

    #[test]
    fn unit_tet_volume() {
        let v = tet_signed_volume(Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z);
        assert!((v - 1.0 / 6.0).abs() < 1e-15);
    }

    #[test]
    fn gaussian_elimination_solves_a_pivoting_system() {
        // The first pivot is zero: partial pivoting must swap.
        let mut m = vec![0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 2.0, 0.0, 3.0];
        let x_true = [1.0, -2.0, 0.5];
        let a = m.clone();
        let mut b: Vec<Real> = (0..3)
            .map(|i| (0..3).map(|j| a[i * 3 + j] * x_true[j]).sum())
            .collect();
        assert!(solve_in_place(&mut m, &mut b, 3, 1));
        for (x, t) in b.iter().zip(x_true) {
            assert!((x - t).abs() < 1e-12, "{b:?}");
        }
        let mut singular = vec![1.0, 2.0, 2.0, 4.0];
        assert!(!solve_in_place(&mut singular, &mut [1.0, 1.0], 2, 1));
    }
}
