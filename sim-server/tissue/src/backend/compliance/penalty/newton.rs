//! The Newton system of the precomputed backend's penalty contact
//! ([`super`] solves it): the compliance T_CC among the contact vertices
//! (read from the precomputed responses, the holds' coupling included where
//! cheap), the Jacobian I + H T_CC from the springs' Hessian H, its
//! factorisation and the directions it gives (the whole system up to
//! [`DENSE_LIMIT`] contact vertices, each vertex's own block beyond), and
//! the chord test that confirms convergence with the last factors.

use super::{ContactSolve, TOLERANCE_M, largest_change, newton_rhs, step_at, try_direction};
use crate::backend::compliance::Compliance;
use crate::math::Mat3;
use crate::tensor_mass::{ForcePoint, ForceTerm};

/// Contact vertices beyond which the Newton direction takes each vertex's
/// own block of the system alone, (I + H_vv T_vv) dG_v = (f - G)_v: the
/// whole system costs O(c^2) memory and O(c^3) time (on this VM, with
/// the hand-written elimination before faer's LU, about 0.3 ms an
/// iteration at this many vertices, 3-5 ms at 140), which a broad
/// tool on a fine mesh would make unbounded; the line search keeps the
/// cheaper direction safe (where it does not descend, f - G).
pub(super) const DENSE_LIMIT: usize = 64;

/// The Jacobian includes the holds' coupling (each contact vertex's
/// response with the holding forces it calls for) when that costs at most
/// about this many operations a Newton iteration: always for a grip on a
/// few vertices, not for a grasp of fifty beside a deep press, where the
/// line search covers the slower convergence.
pub(super) const HOLD_COUPLING_FLOPS: usize = 2_000_000;

/// The acting points of the field's last evaluation, as their count and
/// the sum of their indices: equal when no point started or stopped
/// acting between two evaluations of a step (the points do not change
/// within it).
pub(super) fn field_signature<F: ForceTerm>(field: &F) -> (usize, usize) {
    (field.penetrations_m().iter().enumerate())
        .filter(|(_, d)| **d > 0.0)
        .fold((0, 0), |(n, sum), (i, _)| (n + 1, sum + i))
}

/// The acting points (penetrating) with their springs' whole Hessian
/// (`whole`) or their slopes k n n^T alone.
pub(super) fn acting_hessians<F: ForceTerm>(
    field: &F,
    whole: bool,
) -> impl Iterator<Item = (&F::Point, Mat3)> {
    let hessians = if whole {
        field.hessians()
    } else {
        field.spring_hessians()
    };
    (field
        .points()
        .iter()
        .zip(field.penetrations_m())
        .zip(hessians))
    .filter(|((_, d), _)| **d > 0.0)
    .map(|((p, _), h)| (p, *h))
}

/// The Newton direction dG into `cs.rhs` and its change of the rows'
/// state into `cs.du`: (I + H T) dG = f - G (the transpose of
/// J = I + T H), H the springs' whole Hessian or their slopes alone; the
/// direction f - G where that matrix is singular.
pub(super) fn newton_direction<C: Compliance, F: ForceTerm>(
    body: &mut C,
    field: &F,
    cs: &mut ContactSolve,
    whole: bool,
) {
    newton_rhs(cs);
    cs.chord = None;
    if cs.vertices.len() > DENSE_LIMIT {
        block_direction(body, field, cs, whole);
        try_direction(body, cs);
        return;
    }
    assemble_jacobian(body, field, cs, whole);
    let m = cs.rhs.len();
    if (cs.lu).solve_row_major(&mut cs.jacobian, &mut cs.rhs, m) {
        cs.chord = Some(field_signature(field));
        cs.chord_of.clear();
        cs.chord_of.extend_from_slice(&cs.vertices);
    } else {
        newton_rhs(cs);
    }
    try_direction(body, cs);
}

/// Whether the state is converged by the chord test: after a whole
/// Newton step, the last Newton matrix (still factored, the contact
/// vertices and acting points unchanged) applied to the new residual
/// moves no row more than the tolerance. That step of the simplified
/// Newton method stands for the Newton step the test used to take a
/// new Jacobian and factorisation for (the last iteration of nearly
/// every step, only to confirm the one before: docs/results/precomputed-contact.md); where the
/// matrix changed little it differs from it by a small factor, and the
/// convergence it confirms is quadratic.
pub(super) fn chord_converged<C: Compliance, F: ForceTerm>(
    body: &mut C,
    field: &F,
    cs: &mut ContactSolve,
) -> bool {
    let Some(signature) = cs.chord else {
        return false;
    };
    if signature != field_signature(field) || cs.chord_of != cs.vertices {
        return false;
    }
    newton_rhs(cs);
    let m = cs.rhs.len();
    if !cs.lu.resolve(&cs.jacobian, &mut cs.rhs, m) {
        return false;
    }
    try_direction(body, cs);
    largest_change(cs) <= TOLERANCE_M
}

/// Beyond [`DENSE_LIMIT`] contact vertices: `cs.rhs` (f - G) turned into
/// each vertex's own Newton step, (I + H_vv T_vv)^-1 (f - G)_v (left as
/// it is where that block is singular).
pub(super) fn block_direction<C: Compliance, F: ForceTerm>(
    body: &C,
    field: &F,
    cs: &mut ContactSolve,
    whole: bool,
) {
    let c = cs.vertices.len();
    cs.blocks.clear();
    cs.blocks.resize(c, Mat3::ZERO);
    for (p, g) in acting_hessians(field, whole) {
        for (v, w) in p.vertices().iter().zip(p.weights()) {
            let s = cs.slot[*v as usize];
            if s != u32::MAX {
                cs.blocks[s as usize] += g * (w * w);
            }
        }
    }
    for (s, &v) in cs.vertices.iter().enumerate() {
        let t = Mat3::from_cols_array_2d(
            &[0, 1, 2].map(|q| body.response_of(v, q)[v as usize].to_array()),
        );
        let m = Mat3::IDENTITY + cs.blocks[s] * t;
        if m.determinant().abs() > 1e-12 {
            let r = step_at(&cs.rhs, s);
            let d = m.inverse() * r;
            cs.rhs[3 * s..3 * s + 3].copy_from_slice(&d.to_array());
        }
    }
}

/// T_CC over the contact vertices (row-major, 3c x 3c) into
/// `cs.compliance`, unless it already holds them: the contact vertices
/// rarely change between the iterations of a step, and the holds never
/// do, so a step reads the responses once where each direction read
/// them (two directions an iteration where the whole Hessian's did not
/// descend). Entry ((t, q), (s, r)): the displacement along r of vertex
/// s under a unit force along q on vertex t, with the holding forces
/// that force calls for where that is cheap enough; T is symmetric, so
/// row (t, q) is that column.
pub(super) fn gather_compliance<C: Compliance>(body: &mut C, cs: &mut ContactSolve) {
    if cs.compliance_of == cs.vertices {
        return;
    }
    let c = cs.vertices.len();
    let m = 3 * c;
    cs.compliance.clear();
    cs.compliance.resize(m * m, 0.0);
    let h = body.hold_count();
    let holds = h > 0 && 3 * c * (9 * h * h + 9 * c * h) <= HOLD_COUPLING_FLOPS;
    for t in 0..c {
        for q in 0..3 {
            let row = &mut cs.compliance[(3 * t + q) * m..(3 * t + q + 1) * m];
            let response = body.response_of(cs.vertices[t], q);
            for (s, &v) in cs.vertices.iter().enumerate() {
                row[3 * s..3 * s + 3].copy_from_slice(&response[v as usize].to_array());
            }
            if holds {
                body.holding_response(cs.vertices[t], q, &mut cs.holding);
                let row = &mut cs.compliance[(3 * t + q) * m..(3 * t + q + 1) * m];
                for &(source, f) in &cs.holding {
                    for b in 0..3 {
                        let response = body.source_response(source, b);
                        for (s, &v) in cs.vertices.iter().enumerate() {
                            let d = f[b] * response[v as usize];
                            for r in 0..3 {
                                row[3 * s + r] += d[r];
                            }
                        }
                    }
                }
            }
        }
    }
    cs.compliance_of.clear();
    cs.compliance_of.extend_from_slice(&cs.vertices);
}

/// J = I + H T_CC over the contact vertices (at most [`DENSE_LIMIT`]),
/// row-major, H the springs' whole Hessian (`whole`) or their slopes
/// k n n^T alone. H couples only vertices that share a point's
/// triangle, so each row of J adds the few rows of T its non-zero
/// entries pick (O(c^2) per row of H's entries, not O(c^3)).
pub(super) fn assemble_jacobian<C: Compliance, F: ForceTerm>(
    body: &mut C,
    field: &F,
    cs: &mut ContactSolve,
    whole: bool,
) {
    gather_compliance(body, cs);
    let c = cs.vertices.len();
    let m = 3 * c;
    cs.hessian.clear();
    cs.hessian.resize(m * m, 0.0);
    for (p, g) in acting_hessians(field, whole) {
        for a in 0..3 {
            let sa = cs.slot[p.vertices()[a] as usize];
            if sa == u32::MAX {
                continue;
            }
            for b in 0..3 {
                let sb = cs.slot[p.vertices()[b] as usize];
                if sb == u32::MAX {
                    continue;
                }
                let w = p.weights()[a] * p.weights()[b];
                for r in 0..3 {
                    for q in 0..3 {
                        cs.hessian[(3 * sa as usize + r) * m + 3 * sb as usize + q] +=
                            w * g.col(q)[r];
                    }
                }
            }
        }
    }
    cs.jacobian.clear();
    cs.jacobian.resize(m * m, 0.0);
    for i in 0..m {
        let row = &mut cs.jacobian[i * m..(i + 1) * m];
        row[i] = 1.0;
        for (j, &h) in cs.hessian[i * m..(i + 1) * m].iter().enumerate() {
            if h == 0.0 {
                continue;
            }
            for (x, t) in row.iter_mut().zip(&cs.compliance[j * m..(j + 1) * m]) {
                *x += h * t;
            }
        }
    }
}
