//! The kernel's tensor storage: f32 or f64 blocks of 3x3, packed from the
//! model's tensors and read back as f64 (the state is always f64), and as
//! the three AVX2 row windows the fused pass multiplies. A part of
//! [`super`], the kernel.

use crate::math::{Mat3, Real};

/// A block as its three row windows, in f64x4 (see [`Storage::rows`]).
#[cfg(target_arch = "x86_64")]
pub type Windows = (
    std::arch::x86_64::__m256d,
    std::arch::x86_64::__m256d,
    std::arch::x86_64::__m256d,
);

/// The scalar of the nonlinear elements' lanes (`large_strain`), which
/// follows the storage's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LanePrecision {
    /// Four f64 lanes (equal to the scalar path to round-off).
    F64,
    /// Eight f32 lanes.
    F32,
}

/// Storage precision of the kernel's tensors. State (displacements, forces)
/// is always `f64`.
pub trait Storage: Copy + Default + Send + Sync + std::fmt::Debug + 'static {
    /// `"f32"` or `"f64"`.
    const NAME: &'static str;
    /// The nonlinear elements' lanes that go with this storage.
    const LANES: LanePrecision;
    /// Rounds from f64.
    fn from_real(x: Real) -> Self;
    /// Widens to f64.
    fn to_real(self) -> Real;
    /// The block as three overlapping f64x4 windows, [k0 k1 k2 k3],
    /// [k3 k4 k5 k6] and [k6 k7 k8 0]: lanes 0..2 of each are a row, and
    /// also, scaled by u0, u1 and u2, the three terms of K^T u.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    unsafe fn rows(k: &Block<Self>) -> Windows;
}

impl Storage for f32 {
    const NAME: &'static str = "f32";
    const LANES: LanePrecision = LanePrecision::F32;
    #[inline(always)]
    fn from_real(x: Real) -> Self {
        x as f32
    }
    #[inline(always)]
    fn to_real(self) -> Real {
        self as Real
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn rows(k: &Block<Self>) -> Windows {
        use std::arch::x86_64::*;
        // SAFETY: entries 0..4 and 3..7 are inside the 9; the last window
        // reads 6..9 only (the mask skips the fourth lane, and a masked lane
        // never faults); the caller guarantees AVX2.
        unsafe {
            let p = k.as_ptr();
            (
                _mm256_cvtps_pd(_mm_loadu_ps(p)),
                _mm256_cvtps_pd(_mm_loadu_ps(p.add(3))),
                _mm256_cvtps_pd(_mm_maskload_ps(p.add(6), _mm_set_epi32(0, -1, -1, -1))),
            )
        }
    }
}

impl Storage for f64 {
    const NAME: &'static str = "f64";
    const LANES: LanePrecision = LanePrecision::F64;
    #[inline(always)]
    fn from_real(x: Real) -> Self {
        x
    }
    #[inline(always)]
    fn to_real(self) -> Real {
        self
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn rows(k: &Block<Self>) -> Windows {
        use std::arch::x86_64::*;
        // SAFETY: as for f32: every unmasked lane is one of the 9 entries.
        unsafe {
            let p = k.as_ptr();
            (
                _mm256_loadu_pd(p),
                _mm256_loadu_pd(p.add(3)),
                _mm256_maskload_pd(p.add(6), _mm256_set_epi64x(0, -1, -1, -1)),
            )
        }
    }
}

/// A 3x3 block, row-major.
pub type Block<S> = [S; 9];

pub(super) fn pack<S: Storage>(m: &Mat3) -> Block<S> {
    let r = m.transpose().to_cols_array();
    r.map(S::from_real)
}

/// The block's entries in f64 (written out: `array::map` does not always
/// unroll in the hot loop).
#[inline(always)]
pub(in crate::tensor_mass) fn widen<S: Storage>(k: &Block<S>) -> [Real; 9] {
    [
        k[0].to_real(),
        k[1].to_real(),
        k[2].to_real(),
        k[3].to_real(),
        k[4].to_real(),
        k[5].to_real(),
        k[6].to_real(),
        k[7].to_real(),
        k[8].to_real(),
    ]
}
