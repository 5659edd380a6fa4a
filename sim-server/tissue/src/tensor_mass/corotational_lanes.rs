//! Corotational elements four at a time: the same rotation, force
//! correction and tangent bound as the scalar path of `large_strain`
//! (`nonlinear::extract_rotation`, then P = R sigma(sym(R^T F) - I) minus
//! the linear stress), written lane by lane ([`super::lanes`]).
//!
//! The rotation iterations run on all four lanes together, each lane
//! masked once it has converged (or met a NaN), so every lane takes exactly
//! the iterations the scalar path would: the block costs the slowest lane's
//! count (warm-started, one or two). The Newton step needs (tr S I - S)^-1,
//! here by its adjugate; where that matrix is not safely positive definite
//! the lane takes Mueller et al.'s step instead, as the scalar path does.
//! Tested against the scalar path to round-off.

// Tensor indices (r, c, k) written as in the formulas read better than
// iterator chains over rows of lanes.
#![allow(clippy::needless_range_loop)]

use super::kernel::V3;
use super::lanes::{
    L, LaneBlock, M, abs, add, fma, gradient, identity_plus, lanes, mask, mat, matmul, mul,
    row_abs, scatter, splat, stress, sub, vec3, zero,
};
use super::nonlinear::{ROTATION_MAX_ITER, ROTATION_TOL_RAD};
use crate::math::Real;
use glam::DQuat;

/// A quaternion per lane: x, y, z, w.
type Q = [L; 4];

/// The rotation matrix of unit quaternions (glam's `Mat3::from_quat`),
/// row-major.
#[inline(always)]
fn rotation(q: &Q) -> M {
    let [x, y, z, w] = *q;
    let (x2, y2, z2) = (add(x, x), add(y, y), add(z, z));
    let (xx, yy, zz) = (mul(x, x2), mul(y, y2), mul(z, z2));
    let (xy, xz, yz) = (mul(x, y2), mul(x, z2), mul(y, z2));
    let (wx, wy, wz) = (mul(w, x2), mul(w, y2), mul(w, z2));
    let one = splat(1.0);
    [
        [sub(one, add(yy, zz)), sub(xy, wz), add(xz, wy)],
        [add(xy, wz), sub(one, add(xx, zz)), sub(yz, wx)],
        [sub(xz, wy), add(yz, wx), sub(one, add(xx, yy))],
    ]
}

/// a^T b for lane matrices.
#[inline(always)]
fn transpose_mul(a: &M, b: &M) -> M {
    let mut c = zero();
    for r in 0..3 {
        for col in 0..3 {
            let mut s = mul(a[0][r], b[0][col]);
            s = fma(a[1][r], b[1][col], s);
            c[r][col] = fma(a[2][r], b[2][col], s);
        }
    }
    c
}

/// Per lane: `if mask { a } else { b }`.
#[inline(always)]
fn select(mask: [bool; 4], a: L, b: L) -> L {
    lanes(|i| if mask[i] { a[i] } else { b[i] })
}

/// One rotation step of every active lane (`nonlinear::extract_rotation`'s
/// loop body): updates `q` where `active`, and returns which lanes go on.
#[inline(always)]
fn rotation_step(f: &M, q: &mut Q, active: [bool; 4]) -> [bool; 4] {
    let a = transpose_mul(&rotation(q), f);
    let axial = [
        sub(a[2][1], a[1][2]),
        sub(a[0][2], a[2][0]),
        sub(a[1][0], a[0][1]),
    ];
    let half = splat(0.5);
    let s: M = mat(|r, c| mul(half, add(a[r][c], a[c][r])));
    let tr = add(add(s[0][0], s[1][1]), s[2][2]);
    // m = tr S I - S, symmetric.
    let m: M = mat(|r, c| {
        let neg = mul(splat(-1.0), s[r][c]);
        if r == c { add(tr, neg) } else { neg }
    });
    // Adjugate (cofactors of a symmetric matrix) and determinant.
    let cof = |r0: usize, r1: usize, c0: usize, c1: usize| {
        sub(mul(m[r0][c0], m[r1][c1]), mul(m[r0][c1], m[r1][c0]))
    };
    let adj: M = [
        [cof(1, 2, 1, 2), cof(0, 2, 2, 1), cof(0, 1, 1, 2)],
        [cof(1, 2, 2, 0), cof(0, 2, 0, 2), cof(0, 1, 2, 0)],
        [cof(1, 2, 0, 1), cof(0, 2, 1, 0), cof(0, 1, 0, 1)],
    ];
    let det = fma(
        m[0][0],
        adj[0][0],
        fma(m[0][1], adj[1][0], mul(m[0][2], adj[2][0])),
    );
    // Sylvester's criterion with the scalar path's margins.
    let tr_m = add(add(m[0][0], m[1][1]), m[2][2]);
    let scale = add(abs(tr_m), splat(1e-300));
    let minor = sub(mul(m[0][0], m[1][1]), mul(m[0][1], m[1][0]));
    let pd = mask(|i| {
        let sc = scale[i];
        m[0][0][i] > 1e-3 * sc && minor[i] > 1e-6 * sc * sc && det[i] > 1e-9 * sc * sc * sc
    });
    let inv_det = lanes(|i| if pd[i] { 1.0 / det[i] } else { 0.0 });
    let mueller = lanes(|i| 1.0 / (tr[i].abs() + 1e-12));
    let omega = vec3(|r| {
        let newton = mul(
            inv_det,
            fma(
                adj[r][0],
                axial[0],
                fma(adj[r][1], axial[1], mul(adj[r][2], axial[2])),
            ),
        );
        select(pd, newton, mul(axial[r], mueller))
    });
    let w2 = fma(
        omega[0],
        omega[0],
        fma(omega[1], omega[1], mul(omega[2], omega[2])),
    );
    let w = lanes(|i| w2[i].sqrt());
    // q * (omega / 2, 1), normalised.
    let [hx, hy, hz] = omega.map(|o| mul(half, o));
    let [x, y, z, qw] = *q;
    let nw = sub(qw, fma(x, hx, fma(y, hy, mul(z, hz))));
    let nx = add(fma(qw, hx, x), sub(mul(y, hz), mul(z, hy)));
    let ny = add(fma(qw, hy, y), sub(mul(z, hx), mul(x, hz)));
    let nz = add(fma(qw, hz, z), sub(mul(x, hy), mul(y, hx)));
    let n2 = fma(nx, nx, fma(ny, ny, fma(nz, nz, mul(nw, nw))));
    let inv = lanes(|i| 1.0 / n2[i].sqrt());
    // A NaN stops a lane before its update, as in the scalar loop.
    let update = mask(|i| active[i] && !w[i].is_nan());
    *q = [
        select(update, mul(nx, inv), q[0]),
        select(update, mul(ny, inv), q[1]),
        select(update, mul(nz, inv), q[2]),
        select(update, mul(nw, inv), q[3]),
    ];
    mask(|i| update[i] && w[i] > ROTATION_TOL_RAD)
}

/// Four corotational elements' force corrections into `out` (`alive`
/// masks removed ones), their rotations refined in place in `rotations`:
/// returns the largest tangent bound.
#[inline(always)]
pub fn corotational_block(
    b: &LaneBlock,
    alive: [bool; 4],
    rotations: &mut [DQuat],
    u: &[V3],
    out: &mut [[V3; 4]],
) -> Real {
    let h = gradient(b, u);
    let f = identity_plus(&h);
    let quat = |k: usize| lanes(|lane| rotations[lane].to_array()[k]);
    let mut q: Q = [quat(0), quat(1), quat(2), quat(3)];
    let mut active = alive;
    for _ in 0..ROTATION_MAX_ITER {
        if !active.contains(&true) {
            break;
        }
        active = rotation_step(&f, &mut q, active);
    }
    for (lane, r) in rotations.iter_mut().enumerate().take(4) {
        if alive[lane] {
            *r = DQuat::from_xyzw(q[0][lane], q[1][lane], q[2][lane], q[3][lane]);
        }
    }
    let r = rotation(&q);
    let a = transpose_mul(&r, &f);
    let half = splat(0.5);
    let rotated: M = mat(|i, j| {
        let s = mul(half, add(a[i][j], a[j][i]));
        if i == j { sub(s, splat(1.0)) } else { s }
    });
    let lin: M = mat(|i, j| mul(half, add(h[i][j], h[j][i])));
    let p = matmul(&r, &stress(b, &rotated));
    let sl = stress(b, &lin);
    let mut d = zero();
    for i in 0..3 {
        for j in 0..3 {
            d[i][j] = sub(p[i][j], sl[i][j]);
        }
    }
    scatter(b, &d, alive, out);
    // The rotated rest tangent plus the rotation's terms (see
    // `large_strain::element`).
    let bound = fma(mul(splat(2.0), row_abs(&p)), b.geometric, b.rest_lambda);
    (0..4)
        .filter(|l| alive[*l])
        .map(|l| bound[l])
        .fold(0.0, Real::max)
}
