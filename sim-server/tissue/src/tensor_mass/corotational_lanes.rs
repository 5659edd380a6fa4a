//! Corotational elements a block of lanes at a time: the same rotation, force
//! correction and tangent bound as the scalar path of `large_strain`
//! (`nonlinear::extract_rotation`, then P = R sigma(sym(R^T F) - I) minus
//! the linear stress), written lane by lane ([`super::lanes`]).
//!
//! The rotation iterations run on all lanes together, each lane
//! masked once it has converged (or met a NaN), so every lane takes exactly
//! the iterations the scalar path would: the block costs the slowest lane's
//! count (warm-started, one or two). The Newton step needs (tr S I - S)^-1,
//! here by its adjugate; where that matrix is not safely positive definite
//! the lane takes Mueller et al.'s step instead, as the scalar path does.
//! Tested against the scalar path: to round-off in f64 lanes, to 1e-6 of
//! the element forces in f32 lanes.

// Tensor indices (r, c, k) written as in the formulas read better than
// iterator chains over rows of lanes.
#![allow(clippy::needless_range_loop)]

use super::kernel::V3;
use super::lanes::{
    L, LaneBlock, M, Scalar, abs, add, fma, gradient, lanes, mat, matmul, mul, raise_live, row_abs,
    scatter, splat, stress, sub, vec3, zero,
};
use super::nonlinear::ROTATION_MAX_ITER;

/// A quaternion per lane: x, y, z, w.
pub type Q<S, const N: usize> = [L<S, N>; 4];

/// R - I for the rotation matrix R of unit quaternions (glam's
/// `Mat3::from_quat` without its ones), row-major. Everything downstream is
/// written in differences from the identity (R - I, R^T F - I): for small
/// strains and rotations these are small numbers computed without
/// cancelling against 1, which is what lets the f32 lanes keep the
/// strain's digits (with R and F themselves, f32's 6e-8 near 1 was a
/// 1e-5 error in the force of a 1% strain).
#[inline(always)]
fn rotation_minus_identity<S: Scalar, const N: usize>(q: &Q<S, N>) -> M<S, N> {
    let [x, y, z, w] = *q;
    let (x2, y2, z2) = (add(x, x), add(y, y), add(z, z));
    let (xx, yy, zz) = (mul(x, x2), mul(y, y2), mul(z, z2));
    let (xy, xz, yz) = (mul(x, y2), mul(x, z2), mul(y, z2));
    let (wx, wy, wz) = (mul(w, x2), mul(w, y2), mul(w, z2));
    let zero = splat(0.0);
    [
        [sub(zero, add(yy, zz)), sub(xy, wz), add(xz, wy)],
        [add(xy, wz), sub(zero, add(xx, zz)), sub(yz, wx)],
        [sub(xz, wy), add(yz, wx), sub(zero, add(xx, yy))],
    ]
}

/// G = R^T (I + H) - I - H = (R - I)^T + (R - I)^T H, from `rmi` = R - I.
#[inline(always)]
fn turned_part<S: Scalar, const N: usize>(rmi: &M<S, N>, h: &M<S, N>) -> M<S, N> {
    let t = transpose_mul(rmi, h);
    mat(|r, c| add(rmi[c][r], t[r][c]))
}

/// a^T b for lane matrices.
#[inline(always)]
fn transpose_mul<S: Scalar, const N: usize>(a: &M<S, N>, b: &M<S, N>) -> M<S, N> {
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

// Lane masks are lanes of 1 (set) and 0, not `[bool; N]`: compares,
// `and`s and selects then stay single vector instructions, where packing
// bools into bytes and back cost most of a rotation step (measured: the
// iteration took half the corotational pass).

/// 1 where `a > b`, else 0.
#[inline(always)]
fn gt<S: Scalar, const N: usize>(a: L<S, N>, b: L<S, N>) -> L<S, N> {
    lanes(|i| {
        if a[i] > b[i] {
            S::of(1.0)
        } else {
            S::default()
        }
    })
}

/// 1 where `a` is not NaN, else 0.
#[inline(always)]
fn not_nan<S: Scalar, const N: usize>(a: L<S, N>) -> L<S, N> {
    lanes(|i| {
        if !a[i].is_nan() {
            S::of(1.0)
        } else {
            S::default()
        }
    })
}

/// Per lane: `if mask { a } else { b }`.
#[inline(always)]
fn select<S: Scalar, const N: usize>(mask: L<S, N>, a: L<S, N>, b: L<S, N>) -> L<S, N> {
    lanes(|i| if mask[i] != S::default() { a[i] } else { b[i] })
}

/// Whether every lane of a mask is set.
#[inline(always)]
fn all<S: Scalar, const N: usize>(mask: L<S, N>) -> bool {
    mask.iter().all(|m| *m != S::default())
}

/// Whether any lane of a mask is set.
#[inline(always)]
fn any<S: Scalar, const N: usize>(mask: L<S, N>) -> bool {
    mask.iter().any(|m| *m != S::default())
}

/// One rotation step of every active lane (`nonlinear::extract_rotation`'s
/// loop body): updates `q` where `active` (a lane mask), and returns the
/// mask of the lanes that go on.
#[inline(always)]
fn rotation_step<S: Scalar, const N: usize>(
    h: &M<S, N>,
    q: &mut Q<S, N>,
    active: L<S, N>,
) -> L<S, N> {
    // A - I with A = R^T F: its skew part is the residual, its symmetric
    // part B = S - I.
    let g = turned_part(&rotation_minus_identity(q), h);
    let a: M<S, N> = mat(|r, c| add(g[r][c], h[r][c]));
    let axial = [
        sub(a[2][1], a[1][2]),
        sub(a[0][2], a[2][0]),
        sub(a[1][0], a[0][1]),
    ];
    let half = splat(0.5);
    let b: M<S, N> = mat(|r, c| mul(half, add(a[r][c], a[c][r])));
    let tr_b = add(add(b[0][0], b[1][1]), b[2][2]);
    // tr S = 3 + tr B; m = tr S I - S = (2 + tr B) I - B, symmetric.
    let tr = add(tr_b, splat(3.0));
    let diag = add(tr_b, splat(2.0));
    let m: M<S, N> = mat(|r, c| {
        let neg = mul(splat(-1.0), b[r][c]);
        if r == c { add(diag, neg) } else { neg }
    });
    // Adjugate (cofactors of a symmetric matrix) and determinant.
    let cof = |r0: usize, r1: usize, c0: usize, c1: usize| {
        sub(mul(m[r0][c0], m[r1][c1]), mul(m[r0][c1], m[r1][c0]))
    };
    let adj: M<S, N> = [
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
    // The scalar path's 1e-300, or f32's smallest normal.
    let scale = add(abs(tr_m), [S::of(1e-300).max(S::MIN_POSITIVE); N]);
    let minor = sub(mul(m[0][0], m[1][1]), mul(m[0][1], m[1][0]));
    // Grouped as the scalar path's `1e-6 * sc * sc`, so f64 lanes take
    // the same branch to the bit.
    let pd = mul(
        mul(
            gt(m[0][0], mul(splat(1e-3), scale)),
            gt(minor, mul(mul(splat(1e-6), scale), scale)),
        ),
        gt(det, mul(mul(mul(splat(1e-9), scale), scale), scale)),
    );
    let one = S::of(1.0);
    let inv_det = select(pd, lanes(|i| one / det[i]), splat(0.0));
    let mut omega = vec3(|r| {
        mul(
            inv_det,
            fma(
                adj[r][0],
                axial[0],
                fma(adj[r][1], axial[1], mul(adj[r][2], axial[2])),
            ),
        )
    });
    // Mueller et al.'s step where Newton's matrix is not safely positive
    // definite: rare (large rotations from a cold start), so its division
    // only when a lane needs it.
    if !all(pd) {
        let mueller = lanes(|i| one / (tr[i].abs() + S::of(1e-12)));
        omega = vec3(|r| select(pd, omega[r], mul(axial[r], mueller)));
    }
    let w2 = fma(
        omega[0],
        omega[0],
        fma(omega[1], omega[1], mul(omega[2], omega[2])),
    );
    // q * (omega / 2, 1), normalised.
    let [hx, hy, hz] = omega.map(|o| mul(half, o));
    let [x, y, z, qw] = *q;
    let nw = sub(qw, fma(x, hx, fma(y, hy, mul(z, hz))));
    let nx = add(fma(qw, hx, x), sub(mul(y, hz), mul(z, hy)));
    let ny = add(fma(qw, hy, y), sub(mul(z, hx), mul(x, hz)));
    let nz = add(fma(qw, hz, z), sub(mul(x, hy), mul(y, hx)));
    let n2 = fma(nx, nx, fma(ny, ny, fma(nz, nz, mul(nw, nw))));
    let inv = lanes(|i| one / n2[i].sqrt());
    // A NaN stops a lane before its update, as in the scalar loop.
    let update = mul(active, not_nan(w2));
    *q = [
        select(update, mul(nx, inv), q[0]),
        select(update, mul(ny, inv), q[1]),
        select(update, mul(nz, inv), q[2]),
        select(update, mul(nw, inv), q[3]),
    ];
    // |omega| > tol, compared squared (no square root).
    mul(
        update,
        gt(w2, splat(S::ROTATION_TOL_RAD * S::ROTATION_TOL_RAD)),
    )
}

/// A block of corotational elements' force corrections (whole forces when
/// `whole`) into `out` (`alive`
/// masks removed ones), their rotations (lane quaternions) refined in place in `rotation`,
/// `bound` raised to the live lanes' tangent bounds.
#[inline(always)]
pub fn corotational_block<S: Scalar, const N: usize>(
    b: &LaneBlock<S, N>,
    alive: [bool; N],
    rotation: &mut Q<S, N>,
    u: &[V3],
    whole: bool,
    out: &mut [[L<S, N>; 3]; 4],
    bound: &mut L<S, N>,
) {
    let h = gradient(b, alive, u);
    // A local copy the iterations keep in registers, stored back once.
    let mut q = *rotation;
    let mut active: L<S, N> = lanes(|l| if alive[l] { S::of(1.0) } else { S::default() });
    for _ in 0..ROTATION_MAX_ITER {
        if !any(active) {
            break;
        }
        active = rotation_step(&h, &mut q, active);
    }
    *rotation = q;
    // The rotated strain sym(R^T F) - I = sym H + sym G, its stress
    // sigma_lin + sigma(sym G), and P - sigma_lin = sigma(sym G) + (R - I)
    // sigma_rot, each a small quantity computed as such.
    let rmi = rotation_minus_identity(&q);
    let g = turned_part(&rmi, &h);
    let half = splat(0.5);
    let lin: M<S, N> = mat(|i, j| mul(half, add(h[i][j], h[j][i])));
    let turned: M<S, N> = mat(|i, j| mul(half, add(g[i][j], g[j][i])));
    // The stress is linear in the strain: whole forces need only
    // sigma_rot = sigma(sym H + sym G); a correction keeps sigma(sym G)
    // apart (small, not a difference of two larger stresses in f32).
    let (rot, st) = if whole {
        let strain: M<S, N> = mat(|i, j| add(lin[i][j], turned[i][j]));
        (stress(b, &strain), zero())
    } else {
        let sl = stress(b, &lin);
        let st = stress(b, &turned);
        (mat(|i, j| add(sl[i][j], st[i][j])), st)
    };
    let rmi_rot = matmul(&rmi, &rot);
    let p: M<S, N> = mat(|i, j| add(rot[i][j], rmi_rot[i][j]));
    let d: M<S, N> = if whole {
        p
    } else {
        mat(|i, j| add(st[i][j], rmi_rot[i][j]))
    };
    scatter(b, &d, alive, out);
    // The rotated rest tangent plus the rotation's terms (see
    // `large_strain::element`).
    let tangent = fma(mul(splat(2.0), row_abs(&p)), b.geometric, b.rest_lambda);
    raise_live(bound, tangent, alive);
}
