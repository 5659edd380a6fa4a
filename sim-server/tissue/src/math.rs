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
}
