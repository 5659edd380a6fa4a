//! StVK elements four at a time: the same force correction and tangent
//! bound as `large_strain::stvk`, written lane by lane over structure-of-
//! arrays rest data so that the compiler turns each line into one vector
//! operation (AVX2 and FMA where the CPU has them, checked at run time as
//! for the linear kernel). The scalar path computed one element at a time
//! in ~75 ns; the lanes share every instruction between four.
//!
//! Isotropic and anisotropic elements share the lanes: an isotropic lane
//! has zero fibre coefficients. Removed elements are masked (zero force, no
//! bound). Tested against the scalar path to round-off.

// Tensor indices (r, c, k) written as in the formulas read better than
// iterator chains over rows of lanes.
#![allow(clippy::needless_range_loop)]

use super::kernel::V3;
use super::nonlinear::{STVK_BARRIER_J, STVK_BARRIER_SCALE};
use crate::math::Real;

/// Four lanes.
pub type L = [Real; 4];
/// A 3x3 tensor of lanes, row-major.
type M = [[L; 3]; 3];

/// The rest data of four StVK elements.
#[derive(Clone, Debug, Default)]
pub struct StvkBlock {
    /// Vertices, per lane.
    pub vertices: [[u32; 4]; 4],
    /// Shape vectors m_1..m_3 (m_0 = -(m_1 + m_2 + m_3)): `m[k][c]` lane-wise.
    pub m: [[L; 3]; 3],
    /// Rest volume (m^3).
    pub volume: L,
    /// lambda, mu (Pa).
    pub lambda: L,
    /// mu (Pa).
    pub mu: L,
    /// Fibre direction (zero for isotropic lanes).
    pub dir: [L; 3],
    /// Stretch, cross and shear coefficients (Pa; zero when off).
    pub stretch: L,
    /// Cross-stretch coefficient.
    pub cross: L,
    /// Shear coefficient.
    pub shear: L,
    /// Irons' rest bound (1/s^2).
    pub rest_lambda: L,
    /// Geometric term per Pa (1/(s^2 Pa)).
    pub geometric: L,
}

#[inline(always)]
fn splat(x: Real) -> L {
    [x; 4]
}

#[inline(always)]
fn add(a: L, b: L) -> L {
    std::array::from_fn(|i| a[i] + b[i])
}

#[inline(always)]
fn sub(a: L, b: L) -> L {
    std::array::from_fn(|i| a[i] - b[i])
}

#[inline(always)]
fn mul(a: L, b: L) -> L {
    std::array::from_fn(|i| a[i] * b[i])
}

#[inline(always)]
fn fma(a: L, b: L, c: L) -> L {
    std::array::from_fn(|i| a[i] * b[i] + c[i])
}

#[inline(always)]
fn max(a: L, b: L) -> L {
    std::array::from_fn(|i| a[i].max(b[i]))
}

#[inline(always)]
fn abs(a: L) -> L {
    std::array::from_fn(|i| a[i].abs())
}

#[inline(always)]
fn zero() -> M {
    [[splat(0.0); 3]; 3]
}

/// a b for lane matrices.
#[inline(always)]
fn matmul(a: &M, b: &M) -> M {
    let mut c = zero();
    for r in 0..3 {
        for col in 0..3 {
            let mut s = mul(a[r][0], b[0][col]);
            s = fma(a[r][1], b[1][col], s);
            c[r][col] = fma(a[r][2], b[2][col], s);
        }
    }
    c
}

/// The paper's stress of a symmetric strain, lane-wise (see `TetElastic::stress`).
#[inline(always)]
fn stress(b: &StvkBlock, e: &M) -> M {
    let i1 = add(add(e[0][0], e[1][1]), e[2][2]);
    let a = b.dir;
    let ea: [L; 3] =
        std::array::from_fn(|r| fma(e[r][0], a[0], fma(e[r][1], a[1], mul(e[r][2], a[2]))));
    let i4 = fma(a[0], ea[0], fma(a[1], ea[1], mul(a[2], ea[2])));
    // coefficient of a(x)a: 2 stretch I4 + cross (I1 - 2 I4) - 4 shear I4
    let two_i4 = add(i4, i4);
    let coef_aa = sub(
        fma(
            mul(splat(2.0), b.stretch),
            i4,
            mul(b.cross, sub(i1, two_i4)),
        ),
        mul(mul(splat(4.0), b.shear), i4),
    );
    let diag = fma(b.lambda, i1, mul(b.cross, i4));
    let two_mu = add(b.mu, b.mu);
    let two_shear = add(b.shear, b.shear);
    let mut s = zero();
    for r in 0..3 {
        for c in 0..3 {
            let mut x = mul(two_mu, e[r][c]);
            x = fma(coef_aa, mul(a[r], a[c]), x);
            x = fma(two_shear, fma(a[r], ea[c], mul(ea[r], a[c])), x);
            if r == c {
                x = add(x, diag);
            }
            s[r][c] = x;
        }
    }
    s
}

/// Gershgorin's upper bound on the largest eigenvalue (symmetric), lane-wise.
#[inline(always)]
fn gershgorin(m: &M) -> L {
    let row = |r: usize| {
        let mut x = m[r][r];
        for c in (0..3).filter(|c| *c != r) {
            x = add(x, abs(m[r][c]));
        }
        x
    };
    max(max(row(0), row(1)), row(2))
}

/// The largest absolute row sum, lane-wise.
#[inline(always)]
fn row_abs(m: &M) -> L {
    let row = |r: usize| add(add(abs(m[r][0]), abs(m[r][1])), abs(m[r][2]));
    max(max(row(0), row(1)), row(2))
}

/// Four elements' force corrections into `out` (`alive` masks removed
/// ones): returns (largest tangent bound, elements in the barrier).
#[inline(always)]
pub fn stvk_block(b: &StvkBlock, alive: [bool; 4], u: &[V3], out: &mut [[V3; 4]]) -> (Real, usize) {
    // H = sum_{k=1..3} (u_k - u_0) (x) m_k.
    let du: [[L; 3]; 4] = std::array::from_fn(|k| {
        std::array::from_fn(|c| std::array::from_fn(|lane| u[b.vertices[lane][k] as usize][c]))
    });
    let mut h = zero();
    for r in 0..3 {
        for c in 0..3 {
            let mut x = splat(0.0);
            for k in 0..3 {
                x = fma(sub(du[k + 1][r], du[0][r]), b.m[k][c], x);
            }
            h[r][c] = x;
        }
    }
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
    let sq = stress(b, &quad);
    let sl = stress(b, &lin);
    let mut s = zero();
    for r in 0..3 {
        for c in 0..3 {
            s[r][c] = add(sl[r][c], sq[r][c]);
        }
    }
    let hs = matmul(&h, &s);
    // F = I + H, its determinant and cofactor (columns f2 x f3, f3 x f1, f1 x f2).
    let f: M = std::array::from_fn(|r| {
        std::array::from_fn(|c| {
            if r == c {
                add(h[r][c], splat(1.0))
            } else {
                h[r][c]
            }
        })
    });
    let col = |c: usize| [f[0][c], f[1][c], f[2][c]];
    let cross = |a: [L; 3], b: [L; 3]| -> [L; 3] {
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
    let fs = matmul(&f, &s);
    let mut d = zero();
    let mut p = zero();
    for r in 0..3 {
        for c in 0..3 {
            let bar = mul(barrier_coef, cof_cols[c][r]);
            d[r][c] = add(add(hs[r][c], sq[r][c]), bar);
            p[r][c] = add(fs[r][c], bar);
        }
    }
    // Bound: sigma_max(F)^2 <= gershgorin(I + 2E) times the rest bound,
    // plus the geometric term (the whole P in the barrier).
    let mut c2 = zero();
    for r in 0..3 {
        for c in 0..3 {
            let x = mul(splat(2.0), add(lin[r][c], quad[r][c]));
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
    // Forces f_k = -V d m_k for k = 1..3, f_0 = -(f_1 + f_2 + f_3).
    let minus_v = mul(splat(-1.0), b.volume);
    let mut lambda: Real = 0.0;
    let mut in_barrier = 0;
    for lane in 0..4 {
        let slot = &mut out[lane];
        if !alive[lane] {
            *slot = [[0.0; 3]; 4];
            continue;
        }
        let mut f0 = [0.0; 3];
        for kk in 0..3 {
            for r in 0..3 {
                let x = minus_v[lane]
                    * (d[r][0][lane] * b.m[kk][0][lane]
                        + d[r][1][lane] * b.m[kk][1][lane]
                        + d[r][2][lane] * b.m[kk][2][lane]);
                slot[kk + 1][r] = x;
                f0[r] -= x;
            }
        }
        slot[0] = f0;
        let barrier = gap[lane] > 0.0;
        in_barrier += barrier as usize;
        lambda = lambda.max(if barrier { inside[lane] } else { outside[lane] });
    }
    (lambda, in_barrier)
}
