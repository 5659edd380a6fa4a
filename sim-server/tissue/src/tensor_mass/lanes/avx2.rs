//! The data movement of eight f32 lanes written with AVX2 intrinsics: the
//! corners' displacement differences into lanes, and the lanes' corner
//! forces added to their vertices.
//!
//! The portable forms ([`super::gradient`], `LaneSet::add_to_vertices`)
//! move one scalar at a time: nine differences per element inserted into
//! lanes and twelve force components read back out, each a scalar load,
//! convert and store, with the lane arrays assembled on the stack (a vector
//! read of eight scalar writes stalls on store forwarding). Measured on the
//! 8k cube this movement was more than half of the StVK pass. Here each
//! element's corner is one masked 256-bit load of its `[x, y, z]` (f64,
//! never read past it), the differences are taken and rounded four at a time,
//! and eight elements' `[dx, dy, dz, 0]` are transposed into three lane
//! vectors with in-register shuffles (the 4x4 transpose of `_MM_TRANSPOSE4_PS`
//! in both 128-bit halves); the forces go the other way into per-vertex
//! `[f64; 4]` accumulators (aligned, so that the next element's read of the
//! same vertex is forwarded from the store). The values and the order of
//! every floating-point operation are the portable forms' (subtract in f64,
//! round to f32, flush below [`Scalar::FLUSH_BELOW_M`]; widen, add in element
//! order), so the results are the same to the bit (tested).

use super::{Acc, Scalar};
use crate::tensor_mass::kernel::V3;
use crate::tensor_mass::kernel::avx2::load3;
use std::arch::x86_64::*;

/// Eight `[a, b, c, _]` (lane l in `rows[l]`) as three vectors of eight:
/// all the a's, all the b's, all the c's.
#[inline]
#[target_feature(enable = "avx2")]
fn transpose_8x3(rows: [__m128; 8]) -> [__m256; 3] {
    // r_l = [row l | row l + 4]: one in-lane 4x4 transpose per half.
    let r0 = _mm256_set_m128(rows[4], rows[0]);
    let r1 = _mm256_set_m128(rows[5], rows[1]);
    let r2 = _mm256_set_m128(rows[6], rows[2]);
    let r3 = _mm256_set_m128(rows[7], rows[3]);
    let t0 = _mm256_unpacklo_ps(r0, r1); // a0 a1 b0 b1 | a4 a5 b4 b5
    let t1 = _mm256_unpacklo_ps(r2, r3); // a2 a3 b2 b3 | a6 a7 b6 b7
    let t2 = _mm256_unpackhi_ps(r0, r1); // c0 c1 _ _ | c4 c5 _ _
    let t3 = _mm256_unpackhi_ps(r2, r3); // c2 c3 _ _ | c6 c7 _ _
    [
        _mm256_shuffle_ps::<0x44>(t0, t1),
        _mm256_shuffle_ps::<0xEE>(t0, t1),
        _mm256_shuffle_ps::<0x44>(t2, t3),
    ]
}

/// The inverse of [`transpose_8x3`] with a zero fourth column: lane l's
/// `[a, b, c, 0]`.
#[inline]
#[target_feature(enable = "avx2")]
fn untranspose_3x8(a: __m256, b: __m256, c: __m256) -> [__m128; 8] {
    let zero = _mm256_setzero_ps();
    let t0 = _mm256_unpacklo_ps(a, b); // a0 b0 a1 b1 | a4 b4 a5 b5
    let t1 = _mm256_unpackhi_ps(a, b); // a2 b2 a3 b3 | a6 b6 a7 b7
    let t2 = _mm256_unpacklo_ps(c, zero); // c0 0 c1 0 | c4 0 c5 0
    let t3 = _mm256_unpackhi_ps(c, zero); // c2 0 c3 0 | c6 0 c7 0
    let l04 = _mm256_shuffle_ps::<0x44>(t0, t2);
    let l15 = _mm256_shuffle_ps::<0xEE>(t0, t2);
    let l26 = _mm256_shuffle_ps::<0x44>(t1, t3);
    let l37 = _mm256_shuffle_ps::<0xEE>(t1, t3);
    [
        _mm256_castps256_ps128(l04),
        _mm256_castps256_ps128(l15),
        _mm256_castps256_ps128(l26),
        _mm256_castps256_ps128(l37),
        _mm256_extractf128_ps::<1>(l04),
        _mm256_extractf128_ps::<1>(l15),
        _mm256_extractf128_ps::<1>(l26),
        _mm256_extractf128_ps::<1>(l37),
    ]
}

/// As lanes.
#[inline]
#[target_feature(enable = "avx2")]
fn to_lanes(v: __m256) -> [f32; 8] {
    let mut out = [0.0; 8];
    // SAFETY: `out` holds 8 f32.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), v) };
    out
}

/// `du[k][c][lane]` = u[v_{k+1}][c] - u[v_0][c] of each live lane, taken in
/// f64, rounded to f32 and flushed to zero below
/// [`Scalar::FLUSH_BELOW_M`]; zero for a removed lane (as
/// [`super::gradient`]).
///
/// # Panics
/// When a vertex index is out of `u` (as the portable form).
#[inline]
#[target_feature(enable = "avx2")]
pub(in crate::tensor_mass) fn corner_differences(
    vertices: &[[u32; 4]; 8],
    alive: [bool; 8],
    u: &[V3],
) -> [[[f32; 8]; 3]; 3] {
    let mut rows = [[_mm_setzero_ps(); 8]; 3];
    for (lane, v) in vertices.iter().enumerate() {
        let u0 = load3(&u[v[0] as usize]);
        for (k, row) in rows.iter_mut().enumerate() {
            let d = _mm256_sub_pd(load3(&u[v[k + 1] as usize]), u0);
            row[lane] = _mm256_cvtpd_ps(d);
        }
    }
    let alive_mask = _mm256_castsi256_ps(_mm256_set_epi32(
        -(alive[7] as i32),
        -(alive[6] as i32),
        -(alive[5] as i32),
        -(alive[4] as i32),
        -(alive[3] as i32),
        -(alive[2] as i32),
        -(alive[1] as i32),
        -(alive[0] as i32),
    ));
    let floor = _mm256_set1_ps(f32::of(f32::FLUSH_BELOW_M));
    let sign = _mm256_set1_ps(-0.0);
    let mut du = [[[0.0; 8]; 3]; 3];
    for (k, row) in rows.into_iter().enumerate() {
        for (c, x) in transpose_8x3(row).into_iter().enumerate() {
            // Kept where |x| is not below the floor (a NaN is kept).
            let abs = _mm256_andnot_ps(sign, x);
            let keep = _mm256_cmp_ps::<_CMP_NLT_UQ>(abs, floor);
            du[k][c] = to_lanes(_mm256_and_ps(_mm256_and_ps(x, keep), alive_mask));
        }
    }
    du
}

/// Adds the first `count` lanes' corner forces (`forces[corner][c][lane]`)
/// to their vertices' accumulators, element by element and corner by
/// corner (widened to f64, as the portable sweep).
///
/// # Panics
/// When a vertex index is out of `acc`.
#[inline]
#[target_feature(enable = "avx2")]
pub(in crate::tensor_mass) fn add_block(
    vertices: &[[u32; 4]; 8],
    count: usize,
    forces: &[[[f32; 8]; 3]; 4],
    acc: &mut [Acc],
) {
    let load = |x: &[f32; 8]| {
        // SAFETY: `x` holds 8 f32.
        unsafe { _mm256_loadu_ps(x.as_ptr()) }
    };
    let corner = |k: usize| {
        let [a, b, c] = &forces[k];
        untranspose_3x8(load(a), load(b), load(c))
    };
    // Written out, not `array::from_fn` (see `lanes::lanes`).
    let corners = [corner(0), corner(1), corner(2), corner(3)];
    for (lane, v) in vertices.iter().enumerate().take(count) {
        for (k, corner) in corners.iter().enumerate() {
            let slot = &mut acc[v[k] as usize].0;
            // SAFETY: `slot` holds 4 f64 (32-byte aligned).
            unsafe {
                let f = _mm256_cvtps_pd(corner[lane]);
                let sum = _mm256_add_pd(_mm256_load_pd(slot.as_ptr()), f);
                _mm256_store_pd(slot.as_mut_ptr(), sum);
            }
        }
    }
}
