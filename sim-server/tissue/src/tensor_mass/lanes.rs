//! Four elements at a time: the lane type, lane arithmetic and the pieces
//! the StVK and corotational lanes share (the displacement gradient, the
//! paper's stress, the nodal forces), over structure-of-arrays rest data so
//! that the compiler turns each line into one vector operation (AVX2 and FMA
//! where the CPU has them, checked at run time as for the linear kernel).
//! Isotropic and anisotropic elements share the lanes: an isotropic lane
//! has zero fibre coefficients. Removed elements are masked (zero force, no
//! bound).

// Tensor indices (r, c, k) written as in the formulas read better than
// iterator chains over rows of lanes.
#![allow(clippy::needless_range_loop)]

use super::kernel::V3;
use crate::math::Real;

/// Four lanes.
pub type L = [Real; 4];
/// A 3x3 tensor of lanes, row-major.
pub type M = [[L; 3]; 3];

/// The rest data of four elements of one model.
#[derive(Clone, Debug, Default)]
pub struct LaneBlock {
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

/// Four lanes from `f(lane)`. Written out rather than by
/// `std::array::from_fn`, whose adapters LLVM does not always inline into
/// the AVX2 pass (measured: the corotational pass ran 1.7x slower when they
/// were left out of line after the core moved to its own crate).
#[inline(always)]
pub fn lanes(f: impl Fn(usize) -> Real) -> L {
    [f(0), f(1), f(2), f(3)]
}

/// A per-lane mask from `f(lane)`.
#[inline(always)]
pub fn mask(f: impl Fn(usize) -> bool) -> [bool; 4] {
    [f(0), f(1), f(2), f(3)]
}

/// Three lane vectors from `f(row)`.
#[inline(always)]
pub fn vec3(f: impl Fn(usize) -> L) -> [L; 3] {
    [f(0), f(1), f(2)]
}

/// A lane matrix from `f(row, column)`.
#[inline(always)]
pub fn mat(f: impl Fn(usize, usize) -> L) -> M {
    [
        [f(0, 0), f(0, 1), f(0, 2)],
        [f(1, 0), f(1, 1), f(1, 2)],
        [f(2, 0), f(2, 1), f(2, 2)],
    ]
}

#[inline(always)]
pub fn splat(x: Real) -> L {
    [x; 4]
}

#[inline(always)]
pub fn add(a: L, b: L) -> L {
    lanes(|i| a[i] + b[i])
}

#[inline(always)]
pub fn sub(a: L, b: L) -> L {
    lanes(|i| a[i] - b[i])
}

#[inline(always)]
pub fn mul(a: L, b: L) -> L {
    lanes(|i| a[i] * b[i])
}

#[inline(always)]
pub fn fma(a: L, b: L, c: L) -> L {
    lanes(|i| a[i] * b[i] + c[i])
}

#[inline(always)]
pub fn max(a: L, b: L) -> L {
    lanes(|i| a[i].max(b[i]))
}

#[inline(always)]
pub fn abs(a: L) -> L {
    lanes(|i| a[i].abs())
}

#[inline(always)]
pub fn zero() -> M {
    [[splat(0.0); 3]; 3]
}

/// a b for lane matrices.
#[inline(always)]
pub fn matmul(a: &M, b: &M) -> M {
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
pub fn stress(b: &LaneBlock, e: &M) -> M {
    let i1 = add(add(e[0][0], e[1][1]), e[2][2]);
    let a = b.dir;
    let ea: [L; 3] = vec3(|r| fma(e[r][0], a[0], fma(e[r][1], a[1], mul(e[r][2], a[2]))));
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
pub fn gershgorin(m: &M) -> L {
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
pub fn row_abs(m: &M) -> L {
    let row = |r: usize| add(add(abs(m[r][0]), abs(m[r][1])), abs(m[r][2]));
    max(max(row(0), row(1)), row(2))
}

/// I + h: the deformation gradient F of a displacement gradient.
#[inline(always)]
pub fn identity_plus(h: &M) -> M {
    mat(|r, c| {
        if r == c {
            add(h[r][c], splat(1.0))
        } else {
            h[r][c]
        }
    })
}

/// H = sum_{k=1..3} (u_k - u_0) (x) m_k, the displacement gradient.
#[inline(always)]
pub fn gradient(b: &LaneBlock, u: &[V3]) -> M {
    let corner = |k: usize| vec3(|c| lanes(|lane| u[b.vertices[lane][k] as usize][c]));
    let du: [[L; 3]; 4] = [corner(0), corner(1), corner(2), corner(3)];
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
    h
}

/// The nodal forces f_k = -V d m_k (k = 1..3), f_0 = -(f_1 + f_2 + f_3) of
/// each live lane into `out` (zero for a removed one).
#[inline(always)]
pub fn scatter(b: &LaneBlock, d: &M, alive: [bool; 4], out: &mut [[V3; 4]]) {
    let minus_v = mul(splat(-1.0), b.volume);
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
    }
}
