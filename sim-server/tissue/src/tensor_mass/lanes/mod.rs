//! Elements a block at a time: the lane type, lane arithmetic and the
//! pieces the StVK and corotational lanes share (the displacement gradient,
//! the paper's stress, the nodal forces), over structure-of-arrays rest data
//! so that the compiler turns each line into one vector operation (AVX2 and
//! FMA where the CPU has them, checked at run time as for the linear kernel).
//! Generic over the scalar and the lane count: four f64 lanes (the static
//! solver, f64 storage; tested equal to the scalar path to round-off) or
//! eight f32 lanes (the explicit step with f32 storage, as the linear
//! kernel: the same 256-bit registers hold twice the elements and the rest
//! data is half the bytes). Isotropic and anisotropic elements share the
//! lanes: an isotropic lane has zero fibre coefficients. Removed elements
//! are masked (zero force, no bound).

// Tensor indices (r, c, k) written as in the formulas read better than
// iterator chains over rows of lanes.
#![allow(clippy::needless_range_loop)]

use super::kernel::V3;

#[cfg(target_arch = "x86_64")]
pub(in crate::tensor_mass) mod avx2;
use crate::math::Real;
use std::ops::{Add, Div, Mul, Sub};

/// The scalar of a lane: f64 or f32.
pub trait Scalar:
    Copy
    + Default
    + PartialOrd
    + Send
    + Sync
    + std::fmt::Debug
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
{
    /// Corner displacement differences (m) below this are taken as zero
    /// before rounding: f32 products of smaller ones (ahead of a wave the
    /// displacements are tiny, not zero) underflow to subnormals, and each
    /// subnormal operation took a microcode assist (the 1M-tetrahedron
    /// corotational cube ran 2x slower in f32 than in f64 until its first
    /// 60 steps had passed). A picometre across an element is far below
    /// what f32 resolves of its size; f64 lanes keep every digit.
    const FLUSH_BELOW_M: Real;
    /// A corotational element's rotation iterations stop after a step
    /// below this (rad). Newton converges quadratically, so the rotation is
    /// then accurate to about its square: f64 lanes take the scalar path's
    /// 1e-6 (1e-12), f32 lanes 1e-4 (1e-8, below what f32 resolves of a
    /// strain: a rotation error d changes the strain by about d times
    /// itself). With f64's tolerance the f32 lanes took a second iteration
    /// nearly every step only to confirm the first.
    const ROTATION_TOL_RAD: Real;
    /// The smallest positive normal number.
    const MIN_POSITIVE: Self;
    /// Rounds from f64.
    fn of(x: Real) -> Self;
    /// Widens to f64.
    fn real(self) -> Real;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// The larger (the other if one is NaN).
    fn max(self, other: Self) -> Self;
    /// Whether it is NaN.
    fn is_nan(self) -> bool;
}

macro_rules! scalar {
    ($t:ty, $flush:expr, $rotation_tol:expr) => {
        impl Scalar for $t {
            const FLUSH_BELOW_M: Real = $flush;
            const ROTATION_TOL_RAD: Real = $rotation_tol;
            const MIN_POSITIVE: Self = <$t>::MIN_POSITIVE;
            #[inline(always)]
            fn of(x: Real) -> Self {
                x as $t
            }
            #[inline(always)]
            fn real(self) -> Real {
                self as Real
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline(always)]
            fn max(self, other: Self) -> Self {
                <$t>::max(self, other)
            }
            #[inline(always)]
            fn is_nan(self) -> bool {
                <$t>::is_nan(self)
            }
        }
    };
}
scalar!(f64, 0.0, crate::tensor_mass::nonlinear::ROTATION_TOL_RAD);
scalar!(f32, 1e-12, 1e-4);

/// A vertex's force sum `[x, y, z, 0]` (the AVX2 sweep), aligned so that a
/// 256-bit access never splits a cache line.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
pub struct Acc(pub [f64; 4]);

/// N lanes.
pub type L<S, const N: usize> = [S; N];
/// A 3x3 tensor of lanes, row-major.
pub type M<S, const N: usize> = [[L<S, N>; 3]; 3];

/// The rest data of N elements of one model.
#[derive(Clone, Debug)]
pub struct LaneBlock<S: Scalar, const N: usize> {
    /// Vertices, per lane.
    pub vertices: [[u32; 4]; N],
    /// Shape vectors m_1..m_3 (m_0 = -(m_1 + m_2 + m_3)): `m[k][c]` lane-wise.
    pub m: [[L<S, N>; 3]; 3],
    /// Rest volume (m^3).
    pub volume: L<S, N>,
    /// lambda, mu (Pa).
    pub lambda: L<S, N>,
    /// mu (Pa).
    pub mu: L<S, N>,
    /// Fibre direction (zero for isotropic lanes).
    pub dir: [L<S, N>; 3],
    /// Stretch, cross and shear coefficients (Pa; zero when off).
    pub stretch: L<S, N>,
    /// Cross-stretch coefficient.
    pub cross: L<S, N>,
    /// Shear coefficient.
    pub shear: L<S, N>,
    /// Irons' rest bound (1/s^2).
    pub rest_lambda: L<S, N>,
    /// Geometric term per Pa (1/(s^2 Pa)).
    pub geometric: L<S, N>,
}

/// N lanes from `f(lane)`. A plain loop rather than
/// `std::array::from_fn`, whose adapters LLVM does not always inline into
/// the AVX2 pass (measured: the corotational pass ran 1.7x slower when they
/// were left out of line after the core moved to its own crate).
#[inline(always)]
pub fn lanes<S: Scalar, const N: usize>(f: impl Fn(usize) -> S) -> L<S, N> {
    let mut out = [S::default(); N];
    for (i, o) in out.iter_mut().enumerate() {
        *o = f(i);
    }
    out
}

/// Three lane vectors from `f(row)`.
#[inline(always)]
pub fn vec3<S: Scalar, const N: usize>(f: impl Fn(usize) -> L<S, N>) -> [L<S, N>; 3] {
    [f(0), f(1), f(2)]
}

/// A lane matrix from `f(row, column)`.
#[inline(always)]
pub fn mat<S: Scalar, const N: usize>(f: impl Fn(usize, usize) -> L<S, N>) -> M<S, N> {
    [
        [f(0, 0), f(0, 1), f(0, 2)],
        [f(1, 0), f(1, 1), f(1, 2)],
        [f(2, 0), f(2, 1), f(2, 2)],
    ]
}

#[inline(always)]
pub fn splat<S: Scalar, const N: usize>(x: Real) -> L<S, N> {
    [S::of(x); N]
}

#[inline(always)]
pub fn add<S: Scalar, const N: usize>(a: L<S, N>, b: L<S, N>) -> L<S, N> {
    lanes(|i| a[i] + b[i])
}

#[inline(always)]
pub fn sub<S: Scalar, const N: usize>(a: L<S, N>, b: L<S, N>) -> L<S, N> {
    lanes(|i| a[i] - b[i])
}

#[inline(always)]
pub fn mul<S: Scalar, const N: usize>(a: L<S, N>, b: L<S, N>) -> L<S, N> {
    lanes(|i| a[i] * b[i])
}

#[inline(always)]
pub fn fma<S: Scalar, const N: usize>(a: L<S, N>, b: L<S, N>, c: L<S, N>) -> L<S, N> {
    lanes(|i| a[i] * b[i] + c[i])
}

#[inline(always)]
pub fn max<S: Scalar, const N: usize>(a: L<S, N>, b: L<S, N>) -> L<S, N> {
    lanes(|i| a[i].max(b[i]))
}

#[inline(always)]
pub fn abs<S: Scalar, const N: usize>(a: L<S, N>) -> L<S, N> {
    lanes(|i| a[i].abs())
}

#[inline(always)]
pub fn zero<S: Scalar, const N: usize>() -> M<S, N> {
    [[splat(0.0); 3]; 3]
}

/// a b for lane matrices.
#[inline(always)]
pub fn matmul<S: Scalar, const N: usize>(a: &M<S, N>, b: &M<S, N>) -> M<S, N> {
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
pub fn stress<S: Scalar, const N: usize>(b: &LaneBlock<S, N>, e: &M<S, N>) -> M<S, N> {
    let i1 = add(add(e[0][0], e[1][1]), e[2][2]);
    let a = b.dir;
    let ea: [L<S, N>; 3] = vec3(|r| fma(e[r][0], a[0], fma(e[r][1], a[1], mul(e[r][2], a[2]))));
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
    // Each entry of the upper triangle computed once and mirrored: symmetric
    // by construction, and for a symmetric strain equal to the bit to the
    // nine-entry form (the products commute, and `fma` here is the unfused
    // a * b + c, so the two products of the fibre term add the same way).
    let mut s = zero();
    for r in 0..3 {
        for c in r..3 {
            let mut x = mul(two_mu, e[r][c]);
            x = fma(coef_aa, mul(a[r], a[c]), x);
            x = fma(two_shear, fma(a[r], ea[c], mul(ea[r], a[c])), x);
            if r == c {
                x = add(x, diag);
            }
            s[r][c] = x;
            s[c][r] = x;
        }
    }
    s
}

/// `running` raised to `bound` in the live lanes (the pass keeps a lane
/// vector of the largest bounds and reduces it once, not lane by lane per
/// block; a NaN bound is dropped, as `Real::max` drops it).
#[inline(always)]
pub fn raise_live<S: Scalar, const N: usize>(
    running: &mut L<S, N>,
    bound: L<S, N>,
    alive: [bool; N],
) {
    *running = lanes(|i| {
        if alive[i] {
            running[i].max(bound[i])
        } else {
            running[i]
        }
    });
}

/// Gershgorin's upper bound on the largest eigenvalue (symmetric), lane-wise.
#[inline(always)]
pub fn gershgorin<S: Scalar, const N: usize>(m: &M<S, N>) -> L<S, N> {
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
pub fn row_abs<S: Scalar, const N: usize>(m: &M<S, N>) -> L<S, N> {
    let row = |r: usize| add(add(abs(m[r][0]), abs(m[r][1])), abs(m[r][2]));
    max(max(row(0), row(1)), row(2))
}

/// I + h: the deformation gradient F of a displacement gradient.
#[inline(always)]
pub fn identity_plus<S: Scalar, const N: usize>(h: &M<S, N>) -> M<S, N> {
    mat(|r, c| {
        if r == c {
            add(h[r][c], splat(1.0))
        } else {
            h[r][c]
        }
    })
}

/// H = sum_{k=1..3} (u_k - u_0) (x) m_k, the displacement gradient. The
/// corners' displacements relative to corner 0 are taken in f64 before
/// they are rounded to the lane's scalar (a body far from rest keeps its
/// strain's digits), and in f32 flushed to zero below
/// [`Scalar::FLUSH_BELOW_M`]. A removed lane gets H = 0 (so zero stress
/// and zero force, whatever its vertices do).
#[inline(always)]
pub fn gradient<S: Scalar, const N: usize>(
    b: &LaneBlock<S, N>,
    alive: [bool; N],
    u: &[V3],
) -> M<S, N> {
    let du = corner_differences(b, alive, u);
    let mut h = zero();
    for r in 0..3 {
        for c in 0..3 {
            let mut x = splat(0.0);
            for k in 0..3 {
                x = fma(du[k][r], b.m[k][c], x);
            }
            h[r][c] = x;
        }
    }
    h
}

/// The eight-f32-lane form of a generic lane type, when it is that
/// (`S` = f32, `N` = 8): `x` as `U` when `T` is `U` (the generic spelling
/// of the concrete type), else `None`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub fn as_f32x8<S: Scalar, const N: usize, T: 'static, U: 'static>(x: &T) -> Option<&U> {
    use std::any::TypeId;
    let eight_f32 = N == 8 && TypeId::of::<S>() == TypeId::of::<f32>();
    (eight_f32 && TypeId::of::<T>() == TypeId::of::<U>()).then(|| {
        // SAFETY: T and U are the same type (their TypeIds are equal).
        unsafe { &*(x as *const T as *const U) }
    })
}

/// du[k][c] = u_{k+1}[c] - u_0[c] per live lane (see [`gradient`]): with
/// AVX2 for eight f32 lanes ([`avx2::corner_differences`],
/// equal to the bit), else lane by lane.
#[inline(always)]
pub(super) fn corner_differences<S: Scalar, const N: usize>(
    b: &LaneBlock<S, N>,
    alive: [bool; N],
    u: &[V3],
) -> [[L<S, N>; 3]; 3] {
    #[cfg(target_arch = "x86_64")]
    if let (Some(vertices), Some(alive8)) = (
        as_f32x8::<S, N, _, [[u32; 4]; 8]>(&b.vertices),
        as_f32x8::<S, N, _, [bool; 8]>(&alive),
    ) && std::arch::is_x86_feature_detected!("avx2")
    {
        // SAFETY: AVX2 is present (checked just above).
        let du = unsafe { avx2::corner_differences(vertices, *alive8, u) };
        // SAFETY: S = f32 and N = 8 (`as_f32x8` returned them): the same type.
        return unsafe { std::mem::transmute_copy(&du) };
    }
    portable_corner_differences(b, alive, u)
}

/// [`corner_differences`] lane by lane (every CPU; what the AVX2 form is
/// tested equal to).
#[inline(always)]
pub fn portable_corner_differences<S: Scalar, const N: usize>(
    b: &LaneBlock<S, N>,
    alive: [bool; N],
    u: &[V3],
) -> [[L<S, N>; 3]; 3] {
    // Written as loops: the closures of a `lanes(|lane| ...)` form were
    // left out of line here (9% of the StVK pass in `perf`).
    let mut du: [[L<S, N>; 3]; 3] = [[[S::default(); N]; 3]; 3];
    for lane in (0..N).filter(|l| alive[*l]) {
        let v = &b.vertices[lane];
        let u0 = u[v[0] as usize];
        for k in 0..3 {
            let uk = u[v[k + 1] as usize];
            for c in 0..3 {
                du[k][c][lane] = S::of(uk[c] - u0[c]);
            }
        }
    }
    if S::FLUSH_BELOW_M > 0.0 {
        // Lane-wise compare and blend, not a branch per value.
        let floor = S::of(S::FLUSH_BELOW_M);
        for row in du.iter_mut().flatten() {
            *row = lanes(|l| {
                if row[l].abs() < floor {
                    S::default()
                } else {
                    row[l]
                }
            });
        }
    }
    du
}

/// The nodal forces f_k = -V d m_k (k = 1..3), f_0 = -(f_1 + f_2 + f_3) of
/// each live lane into `out[corner][coordinate]` (zero for a removed one).
#[inline(always)]
pub fn scatter<S: Scalar, const N: usize>(
    b: &LaneBlock<S, N>,
    d: &M<S, N>,
    alive: [bool; N],
    out: &mut [[L<S, N>; 3]; 4],
) {
    let minus_v = mul(splat(-1.0), b.volume);
    // Removed lanes: `gradient` gave them H = 0, so d = 0 and their
    // forces are exactly zero without a select here.
    debug_assert!((0..N).all(|l| alive[l] || d.iter().flatten().all(|x| x[l] == S::default())));
    let mut f0: [L<S, N>; 3] = [splat(0.0); 3];
    for kk in 0..3 {
        for r in 0..3 {
            let dot = add(
                add(mul(d[r][0], b.m[kk][0]), mul(d[r][1], b.m[kk][1])),
                mul(d[r][2], b.m[kk][2]),
            );
            let x = mul(minus_v, dot);
            out[kk + 1][r] = x;
            f0[r] = sub(f0[r], x);
        }
    }
    out[0] = f0;
}
