//! The fused step pass written with AVX2 intrinsics (4-wide f64).
//!
//! It performs exactly the floating-point operations of the portable pass
//! ([`Kernel::run_part_body`]) in the same order (separate multiplies and
//! adds, no FMA), so both give bit-identical results; it only packs them
//! into vectors. Each block is read as three overlapping windows
//! [k0 k1 k2 k3], [k3 k4 k5 k6], [k6 k7 k8 0] ([`Storage::rows`]) and each
//! displacement as w = [u0 u1 u2 0] (a masked load), so that per edge
//! - K u_j: three row accumulators m_r += window_r (o) w_j (lane 3 stays
//!   zero), reduced to the row's K U once per row;
//! - K^T u_i = window_0 u_i0 + window_1 u_i1 + window_2 u_i2 in lanes 0..2
//!   (the columns of K), with the broadcasts of u_i made once per row.
//!
//! No shuffles in the edge loop.

use super::{Kernel, Part, StepInputs, Storage, V3};
use std::arch::x86_64::*;

/// [x0 x1 x2 0] from a 3-vector, without reading past it (also the
/// nonlinear pass's corner loads, `lanes::avx2`).
#[inline]
#[target_feature(enable = "avx2")]
pub(in crate::tensor_mass) fn load3(v: &V3) -> __m256d {
    // SAFETY: the mask reads v[0], v[1] and v[2] only; a masked-off lane
    // never faults.
    unsafe { _mm256_maskload_pd(v.as_ptr(), _mm256_set_epi64x(0, -1, -1, -1)) }
}

/// The three lanes of `v` in an array.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn lanes(v: __m256d) -> [f64; 4] {
    let mut out = [0.0; 4];
    // SAFETY: `out` holds 4 f64.
    unsafe { _mm256_storeu_pd(out.as_mut_ptr(), v) };
    out
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
        ring.len().is_power_of_two()
            && ring.len() > kernel.span() + 1
            && spill.len() <= kernel.span()
    );
    let ring = &mut ring[..=mask];
    let u = inp.u;
    // Prefetch distances (edges ahead in the block stream, vertices past a
    // row's highest column), chosen by A/B runs at 1M tetrahedra.
    let ahead = edges.as_ptr().wrapping_add(96);
    macro_rules! finish {
        ($p:expr, $m:expr) => {{
            let (p, [m0, m1, m2]) = ($p, $m);
            let (a, b, c) = (lanes(m0), lanes(m1), lanes(m2));
            let slot = &mut ring[p & mask];
            let acc = [
                slot[0] + (a[0] + a[1] + a[2]),
                slot[1] + (b[0] + b[1] + b[2]),
                slot[2] + (c[0] + c[1] + c[2]),
            ];
            *slot = [0.0; 4];
            if p < deferred_end {
                deferred[p - start] = acc;
            } else {
                inp.integrate(p, acc, &mut next[p - start]);
            }
        }};
    }
    let mut pending: Option<(usize, [__m256d; 3])> = None;
    for i in start..end {
        inp.prefetch_ahead(i);
        let ui = &u[i];
        let wi = load3(ui);
        let (bi0, bi1, bi2) = (
            _mm256_set1_pd(ui[0]),
            _mm256_set1_pd(ui[1]),
            _mm256_set1_pd(ui[2]),
        );
        // SAFETY: AVX2 is enabled for this function.
        let (d0, d1, d2) = unsafe { S::rows(&diag[i]) };
        let mut m0 = _mm256_mul_pd(d0, wi);
        let mut m1 = _mm256_mul_pd(d1, wi);
        let mut m2 = _mm256_mul_pd(d2, wi);
        let (r0, r1) = (row_start[i] as usize, row_start[i + 1] as usize);
        if let Some(last) = edges[r0..r1].last() {
            // The displacements a row reaches first are those at the front
            // of the band (its highest column): fetch them a few rows early.
            _mm_prefetch::<_MM_HINT_T0>(
                u.as_ptr().wrapping_add(last.col as usize + 16).cast::<i8>(),
            );
        }
        for (s, e) in edges[r0..r1].iter().enumerate() {
            // An address past the end is only a useless hint: prefetch never faults.
            _mm_prefetch::<_MM_HINT_T0>(ahead.wrapping_add(r0 + s).cast::<i8>());
            let j = e.col as usize;
            let wj = load3(&u[j]);
            // SAFETY: AVX2 is enabled for this function.
            let (k0, k1, k2) = unsafe { S::rows(&e.k) };
            m0 = _mm256_add_pd(m0, _mm256_mul_pd(k0, wj));
            m1 = _mm256_add_pd(m1, _mm256_mul_pd(k1, wj));
            m2 = _mm256_add_pd(m2, _mm256_mul_pd(k2, wj));
            // (t0 + t3) + t6 and so on: the portable pass's order.
            let kt = _mm256_add_pd(
                _mm256_add_pd(_mm256_mul_pd(k0, bi0), _mm256_mul_pd(k1, bi1)),
                _mm256_mul_pd(k2, bi2),
            );
            let slot = &mut ring[j & mask];
            // SAFETY: `slot` is 4 f64 and AVX2 is enabled.
            unsafe {
                let cur = _mm256_loadu_pd(slot.as_ptr());
                _mm256_storeu_pd(slot.as_mut_ptr(), _mm256_add_pd(cur, kt));
            }
        }
        // Row i is finished after row i + 1's edges: its reduction and
        // integration wait on the chain of adds through its edges, and
        // issued here they would hold the reorder window while the next
        // row's independent loads queue behind them. Row i + 1 scatters only
        // to columns above i + 1, and the ring is longer than span + 1, so
        // slot i is final and not aliased.
        if let Some((p, m)) = pending {
            finish!(p, m);
        }
        pending = Some((i, [m0, m1, m2]));
    }
    if let Some((p, m)) = pending {
        finish!(p, m);
    }
    for (r, sp) in spill.iter_mut().enumerate() {
        let slot = &mut ring[(end + r) & mask];
        *sp = [slot[0], slot[1], slot[2]];
        *slot = [0.0; 4];
    }
}
