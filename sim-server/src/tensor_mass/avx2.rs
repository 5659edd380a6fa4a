//! The fused step pass written with AVX2 intrinsics (4-wide f64).
//!
//! It performs exactly the floating-point operations of the portable pass
//! ([`Kernel::run_part_body`]) in the same order (separate multiplies and
//! adds, no FMA), so both give bit-identical results; it only packs them
//! into vectors. Per edge, with K row-major (k0..k8):
//! - K u_j: m[q] += k[q] * [u_j0 u_j1 u_j2 u_j0 | u_j1 u_j2 u_j0 u_j1 | u_j2]
//!   (reduced to the row's K U once per row);
//! - K^T u_i: t = k (o) [u_i0 u_i0 u_i0 u_i1 | u_i1 u_i1 u_i2 u_i2 | u_i2],
//!   then (t0 + t3 + t6, t1 + t4 + t7, t2 + t5 + t8) into the ring slot of row j.

use super::kernel::{Kernel, Part, StepInputs, Storage, V3};
use std::arch::x86_64::*;

/// [x0 x1 x2 x2] from a 3-vector, without reading past it.
#[inline]
#[target_feature(enable = "avx2")]
fn load3(v: &V3) -> __m256d {
    // SAFETY: reads v[0], v[1] and v[2], all inside the array.
    unsafe {
        let lo = _mm_loadu_pd(v.as_ptr());
        let hi = _mm_load1_pd(v.as_ptr().add(2));
        _mm256_set_m128d(hi, lo)
    }
}

/// The pass over one part's rows.
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn run_part<S: Storage>(
    kernel: &Kernel<S>,
    inp: &StepInputs<'_>,
    part: Part<'_>,
) {
    let Part {
        start,
        end,
        deferred_end,
        ring,
        deferred,
        next,
        spill,
    } = part;
    let (diag, row_start, edges) = kernel.parts();
    let mask = ring.len() - 1;
    assert!(
        ring.len().is_power_of_two() && ring.len() > kernel.span() && spill.len() <= kernel.span()
    );
    let ring = &mut ring[..=mask];
    let u = inp.u;
    let ahead = edges.as_ptr().wrapping_add(32);
    for i in start..end {
        let ui = &u[i];
        let uiv = load3(ui);
        // Tiles for K^T u_i: [ui0 ui0 ui0 ui1] and [ui1 ui1 ui2 ui2].
        let tia = _mm256_permute4x64_pd::<0b01_00_00_00>(uiv);
        let tib = _mm256_permute4x64_pd::<0b10_10_01_01>(uiv);
        // Tiles for K u: [x0 x1 x2 x0] and [x1 x2 x0 x1].
        // SAFETY: AVX2 is enabled for this function.
        let (da, db) = unsafe { S::load8(&diag[i]) };
        let mut ma = _mm256_mul_pd(da, _mm256_permute4x64_pd::<0b00_10_01_00>(uiv));
        let mut mb = _mm256_mul_pd(db, _mm256_permute4x64_pd::<0b01_00_10_01>(uiv));
        let mut m8 = diag[i][8].to_real() * ui[2];
        let (r0, r1) = (row_start[i] as usize, row_start[i + 1] as usize);
        for (s, e) in edges[r0..r1].iter().enumerate() {
            // An address past the end is only a useless hint: prefetch never faults.
            _mm_prefetch::<_MM_HINT_T0>(ahead.wrapping_add(r0 + s).cast::<i8>());
            let j = e.col as usize;
            let ujv = load3(&u[j]);
            // SAFETY: AVX2 is enabled for this function.
            let (ka, kb) = unsafe { S::load8(&e.k) };
            let k8 = e.k[8].to_real();
            ma = _mm256_add_pd(
                ma,
                _mm256_mul_pd(ka, _mm256_permute4x64_pd::<0b00_10_01_00>(ujv)),
            );
            mb = _mm256_add_pd(
                mb,
                _mm256_mul_pd(kb, _mm256_permute4x64_pd::<0b01_00_10_01>(ujv)),
            );
            m8 += k8 * u[j][2];
            let ta = _mm256_mul_pd(ka, tia); // t0 t1 t2 t3
            let tb = _mm256_mul_pd(kb, tib); // t4 t5 t6 t7
            let t8 = k8 * ui[2];
            // v2 = [t3 t4 t5 .], v3 = [t6 t7 t8 .]
            let cross = _mm256_permute2f128_pd::<0x21>(ta, tb); // t2 t3 t4 t5
            let v2 = _mm256_permute4x64_pd::<0b11_11_10_01>(cross); // t3 t4 t5 t5
            let v3 = _mm256_permute4x64_pd::<0b11_11_11_10>(tb); // t6 t7 t7 t7
            let v3 = _mm256_blend_pd::<0b0100>(v3, _mm256_set1_pd(t8)); // t6 t7 t8 t7
            let kt = _mm256_add_pd(_mm256_add_pd(ta, v2), v3);
            let slot = &mut ring[j & mask];
            // SAFETY: `slot` is 4 f64 and AVX2 is enabled.
            unsafe {
                let cur = _mm256_loadu_pd(slot.as_ptr());
                _mm256_storeu_pd(slot.as_mut_ptr(), _mm256_add_pd(cur, kt));
            }
        }
        let mut m = [0.0; 8];
        // SAFETY: `m` holds 8 f64.
        unsafe {
            _mm256_storeu_pd(m.as_mut_ptr(), ma);
            _mm256_storeu_pd(m.as_mut_ptr().add(4), mb);
        }
        let slot = &mut ring[i & mask];
        let acc = [
            slot[0] + (m[0] + m[1] + m[2]),
            slot[1] + (m[3] + m[4] + m[5]),
            slot[2] + (m[6] + m[7] + m8),
        ];
        *slot = [0.0; 4];
        if i < deferred_end {
            deferred[i - start] = acc;
        } else {
            inp.integrate(i, acc, &mut next[i - start]);
        }
    }
    for (r, sp) in spill.iter_mut().enumerate() {
        let slot = &mut ring[(end + r) & mask];
        *sp = [slot[0], slot[1], slot[2]];
        *slot = [0.0; 4];
    }
}
