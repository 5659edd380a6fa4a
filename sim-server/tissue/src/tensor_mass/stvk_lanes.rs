//! StVK elements a block of lanes at a time: the same force correction and tangent
//! bound as `large_strain::stvk`, written lane by lane ([`super::lanes`]).
//! The scalar path computed one element at a time in ~75 ns; the lanes
//! share every instruction between four (f64) or eight (f32). Tested
//! against the scalar path to round-off (f64) and to f32's precision.

// Tensor indices (r, c, k) written as in the formulas read better than
// iterator chains over rows of lanes.
#![allow(clippy::needless_range_loop)]

use super::kernel::V3;
use super::lanes::{
    L, LaneBlock, M, Scalar, add, fma, gershgorin, gradient, identity_plus, lanes, mat, matmul,
    max, mul, raise_live, row_abs, scatter, splat, stress, sub, zero,
};
use super::nonlinear::{STVK_BARRIER_J, STVK_BARRIER_SCALE};

/// A block's force corrections (whole forces when `whole`) into `out` (`alive` masks removed
/// ones), `bound` raised to the live lanes' tangent bounds: returns the
/// number of elements in the barrier.
#[inline(always)]
pub fn stvk_block<S: Scalar, const N: usize>(
    b: &LaneBlock<S, N>,
    alive: [bool; N],
    u: &[V3],
    whole: bool,
    out: &mut [[L<S, N>; 3]; 4],
    bound: &mut L<S, N>,
) -> usize {
    let h = gradient(b, alive, u);
    let mut lin = zero();
    let mut quad = zero();
    for r in 0..3 {
        for c in 0..3 {
            lin[r][c] = mul(splat(0.5), add(h[r][c], h[c][r]));
            let hh = fma(
                h[0][r],
                h[0][c],
                fma(h[1][r], h[1][c], mul(h[2][r], h[2][c])),
            );
            quad[r][c] = mul(splat(0.5), hh);
        }
    }
    // The stress is linear in the strain: whole forces need only
    // S = sigma(E); a correction P - sigma_lin keeps sigma(quad) apart (a
    // small-strain correction is small: not a difference of two large
    // stresses in f32).
    let e: M<S, N> = mat(|r, c| add(lin[r][c], quad[r][c]));
    let (s, sq) = if whole {
        (stress(b, &e), zero())
    } else {
        let sq = stress(b, &quad);
        let sl = stress(b, &lin);
        (mat(|r, c| add(sl[r][c], sq[r][c])), sq)
    };
    let hs = matmul(&h, &s);
    // F = I + H, its determinant and cofactor (columns f2 x f3, f3 x f1, f1 x f2).
    let f = identity_plus(&h);
    let col = |c: usize| [f[0][c], f[1][c], f[2][c]];
    let cross = |a: [L<S, N>; 3], b: [L<S, N>; 3]| -> [L<S, N>; 3] {
        [
            sub(mul(a[1], b[2]), mul(a[2], b[1])),
            sub(mul(a[2], b[0]), mul(a[0], b[2])),
            sub(mul(a[0], b[1]), mul(a[1], b[0])),
        ]
    };
    let cof_cols = [
        cross(col(1), col(2)),
        cross(col(2), col(0)),
        cross(col(0), col(1)),
    ];
    let det = fma(
        f[0][0],
        cof_cols[0][0],
        fma(f[1][0], cof_cols[0][1], mul(f[2][0], cof_cols[0][2])),
    );
    let k = mul(splat(STVK_BARRIER_SCALE), add(b.lambda, add(b.mu, b.mu)));
    let gap = max(sub(splat(STVK_BARRIER_J), det), splat(0.0));
    let barrier_coef = mul(mul(splat(-3.0), k), mul(gap, gap));
    // P = F S + b, d = H S + sigma(quad) + b.
    // F S = S + H S (for the bound only).
    let fs: M<S, N> = mat(|r, c| add(s[r][c], hs[r][c]));
    let mut d = zero();
    let mut p = zero();
    for r in 0..3 {
        for c in 0..3 {
            let bar = mul(barrier_coef, cof_cols[c][r]);
            p[r][c] = add(fs[r][c], bar);
            // P = F S + b; its correction P - sigma_lin = H S + sigma(quad) + b.
            d[r][c] = if whole {
                p[r][c]
            } else {
                add(add(hs[r][c], sq[r][c]), bar)
            };
        }
    }
    // Bound: sigma_max(F)^2 <= gershgorin(I + 2E) times the rest bound,
    // plus the geometric term (the whole P in the barrier).
    let mut c2 = zero();
    for r in 0..3 {
        for c in 0..3 {
            let x = mul(splat(2.0), e[r][c]);
            c2[r][c] = if r == c { add(x, splat(1.0)) } else { x };
        }
    }
    let stretch = gershgorin(&c2);
    let outside = fma(
        stretch,
        b.rest_lambda,
        mul(max(gershgorin(&s), splat(0.0)), b.geometric),
    );
    let inside = fma(
        max(stretch, splat(1.0)),
        b.rest_lambda,
        mul(mul(splat(4.0), row_abs(&p)), b.geometric),
    );
    scatter(b, &d, alive, out);
    let zero = S::default();
    let tangent = lanes(|l| if gap[l] > zero { inside[l] } else { outside[l] });
    raise_live(bound, tangent, alive);
    (0..N).filter(|l| alive[*l] && gap[*l] > zero).count()
}
