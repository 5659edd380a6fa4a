//! The penalty contact on the precomputed backend: the static equilibrium
//! of the tissue and the contact springs, solved every step on the
//! precomputed responses (where the paper's projection law used to be the
//! only one here, and missed a tool between vertices).
//!
//! The backend is a linear static map S from the surface forces to the
//! displacements (its responses T, with the tools' holds). With the penalty
//! springs' forces f(u) on the contact vertices C, a step finds u with
//! u = S(f(u)): Newton on the contact vertices' displacements,
//!
//! ```text
//! (I + T_CC H) delta = -(u_C - S(f(u))_C),
//! ```
//!
//! H the springs' Hessian (each point's k n n^T spread over its triangle),
//! T_CC the responses of the contact vertices to each other (read from the
//! precomputed responses, no solve): the contact problem on the compliance
//! W = T_CC that SOFA's constraint solvers and LCPForceFeedback pose
//! (Duriez et al. 2006, Saupin et al. 2008), here with the penalty law's
//! springs instead of complementarity. Each iteration evaluates the springs
//! and applies S at the points' vertices only (the holds included,
//! exactly), the whole body once at the end of the step; the Jacobian leaves
//! out the holds' coupling and the turning of the normal round the tool,
//! which slows convergence where they matter but not the fixed point it
//! converges to. The last S(f(u)) is the step's state and its springs the
//! tools' reactions. Experimental: a step that ends at the iteration
//! limit keeps its last iterate, which can be far from the solution (force
//! spikes in 2 of 9 real-time liver runs; README); no line search guards
//! it yet. Static: no damping (no velocity), and no friction (its
//! springs need the motion between sub-steps; a scene asking for it here is
//! refused).

use super::Backend;
use super::precomputed::Precomputed;
use crate::contact::ContactField;
use crate::math::{Real, Vec3};

/// Newton iterations at most per step.
const MAX_ITERATIONS: usize = 12;
/// Converged when no contact vertex moves more than this (m): 10 nm, a
/// force error of about 1e-5 N at the contact's stiffness. At 0.1 nm
/// most contact steps of a real-time run ended at the iteration limit
/// (the box poke: 2,330 of 4,022; now 7 of 4,021), the same forces.
const TOLERANCE_M: Real = 1e-8;
/// Contact vertices beyond which the Jacobian keeps only its diagonal
/// blocks (a dense solve of 3 x this many unknowns costs about a
/// millisecond).
const DENSE_LIMIT: usize = 150;

/// Scratch of the contact solve (buffers reused across steps).
#[derive(Default)]
pub(super) struct ContactSolve {
    /// Per vertex: the contact force of this iteration (N).
    force: Vec<[Real; 3]>,
    /// Per vertex: its slot among the contact vertices, `u32::MAX` if none.
    slot: Vec<u32>,
    /// The contact vertices.
    vertices: Vec<u32>,
    /// Their displacements at this iteration's evaluation.
    u_at: Vec<Vec3>,
    /// The Newton system (row-major, 3c x 3c) and its right side.
    jacobian: Vec<Real>,
    rhs: Vec<Real>,
    /// H per contact-vertex pair, summed over points (3c x 3c, row-major).
    hessian: Vec<Real>,
    /// The vertices of the step's contact points (each once).
    rows: Vec<u32>,
    /// Newton iterations of the last step.
    pub iterations: usize,
    /// Whether the last step stopped at [`MAX_ITERATIONS`] short of the
    /// tolerance.
    pub capped: bool,
}

/// The vertices of `field`'s points, each once, into `cs.rows` (the slots
/// left clean).
fn gather_rows(field: &ContactField, cs: &mut ContactSolve) {
    cs.rows.clear();
    for p in field.points() {
        for v in p.vertices {
            if cs.slot[v as usize] == u32::MAX {
                cs.slot[v as usize] = 0;
                cs.rows.push(v);
            }
        }
    }
    for &v in &cs.rows {
        cs.slot[v as usize] = u32::MAX;
    }
}

impl Precomputed {
    /// One step under the penalty contact `field` (see the module docs).
    pub(super) fn step_with_penalty(&mut self, field: &mut ContactField) {
        let n = self.vertex_len();
        let mut cs = std::mem::take(&mut self.contact);
        if cs.force.len() != n {
            cs.force = vec![[0.0; 3]; n];
            cs.slot = vec![u32::MAX; n];
        }
        cs.iterations = 0;
        cs.capped = false;
        if field.is_idle() {
            self.clear_contact_forces();
            self.step_static();
        } else {
            // Warm: from the last step's contact forces (its equilibrium,
            // with this step's loads, holds and tool pose), where the free
            // solution would start the press's whole depth away. The
            // iterations need the springs' vertices only; the whole body
            // once, at the end.
            self.prepare_rows();
            gather_rows(field, &mut cs);
            self.step_rows(&cs.rows);
            self.solve_contact(field, &mut cs);
            self.step_static();
        }
        self.contact = cs;
    }

    fn solve_contact(&mut self, field: &mut ContactField, cs: &mut ContactSolve) {
        for k in 0..MAX_ITERATIONS {
            cs.iterations = k + 1;
            field.restart_report();
            let (rest, u) = (self.model().mesh().positions_m(), self.displacements());
            field.static_forces(rest, u, &mut cs.force);
            self.gather_contact_vertices(field, cs);
            // S(f(u)): the forces on the loadable contact vertices.
            self.set_contact_forces(&cs.vertices, &cs.force);
            for (s, &v) in cs.vertices.iter().enumerate() {
                cs.u_at[s] = self.displacement_of(v);
            }
            self.step_rows(&cs.rows);
            let c = cs.vertices.len();
            if c == 0 {
                break;
            }
            // Residual r = u_C - S(f(u))_C.
            let mut worst: Real = 0.0;
            cs.rhs.clear();
            for (s, &v) in cs.vertices.iter().enumerate() {
                let r = cs.u_at[s] - self.displacement_of(v);
                worst = worst.max(r.abs().max_element());
                cs.rhs.extend_from_slice(&[-r.x, -r.y, -r.z]);
            }
            if worst <= TOLERANCE_M {
                break;
            }
            if k + 1 == MAX_ITERATIONS {
                cs.capped = true;
                break;
            }
            self.assemble_jacobian(field, cs);
            if !crate::math::solve_in_place(&mut cs.jacobian, &mut cs.rhs, 3 * c, 1) {
                // A singular Jacobian (round-off only: I + T H with T and H
                // positive): keep S(f(u)), the consistent state.
                break;
            }
            // A step longer than the residual itself overshoots where the
            // contact set changes within it: at most the residual's size.
            let step = cs.rhs.iter().fold(0.0 as Real, |m, x| m.max(x.abs()));
            if step > worst {
                let scale = worst / step;
                cs.rhs.iter_mut().for_each(|x| *x *= scale);
            }
            // The next iterate: u_C + delta, the rest at S(f(u)) (the
            // springs read only their triangles' vertices).
            for (s, &v) in cs.vertices.iter().enumerate() {
                let d = Vec3::new(cs.rhs[3 * s], cs.rhs[3 * s + 1], cs.rhs[3 * s + 2]);
                self.set_displacement(v, cs.u_at[s] + d);
            }
        }
        for &v in &cs.vertices {
            cs.slot[v as usize] = u32::MAX;
        }
    }

    /// The loadable (free surface, not held) vertices of the acting points.
    fn gather_contact_vertices(&self, field: &ContactField, cs: &mut ContactSolve) {
        for &v in &cs.vertices {
            cs.slot[v as usize] = u32::MAX;
        }
        cs.vertices.clear();
        for (i, p) in field.points().iter().enumerate() {
            if field.penetrations_m()[i] <= 0.0 {
                continue;
            }
            for v in p.vertices {
                let vi = v as usize;
                if cs.slot[vi] == u32::MAX && self.loadable(vi) {
                    cs.slot[vi] = cs.vertices.len() as u32;
                    cs.vertices.push(v);
                }
            }
        }
        cs.u_at.clear();
        cs.u_at.resize(cs.vertices.len(), Vec3::ZERO);
    }

    /// J = I + T_CC H over the contact vertices (only H's diagonal blocks
    /// beyond [`DENSE_LIMIT`] vertices).
    fn assemble_jacobian(&self, field: &ContactField, cs: &mut ContactSolve) {
        let c = cs.vertices.len();
        let m = 3 * c;
        let dense = c <= DENSE_LIMIT;
        cs.hessian.clear();
        cs.hessian.resize(m * m, 0.0);
        // The springs' slopes only (k n n^T, positive): with their whole
        // Hessian (less the turning of the normal round the tool, which
        // makes it indefinite) a press on the box took at most 6 iterations
        // where these take up to the 12, but the liver's poke felt 3.2-3.9 N
        // spikes (1.20 N with these, 1.21 N on tensor-mass): not kept.
        let hessians = field.spring_hessians();
        for (i, p) in field.points().iter().enumerate() {
            if field.penetrations_m()[i] <= 0.0 {
                continue;
            }
            let g = hessians[i];
            for a in 0..3 {
                let sa = cs.slot[p.vertices[a] as usize];
                if sa == u32::MAX {
                    continue;
                }
                for b in 0..3 {
                    let sb = cs.slot[p.vertices[b] as usize];
                    if sb == u32::MAX || (!dense && sa != sb) {
                        continue;
                    }
                    let w = p.weights[a] * p.weights[b];
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
            cs.jacobian[i * m + i] = 1.0;
        }
        // J[(s, r), :] += sum over (t, q) of T[(s, r), (t, q)] H[(t, q), :],
        // T[(s, r), (t, q)] the displacement along r of vertex s under a
        // unit force along q on vertex t.
        for t in 0..c {
            for q in 0..3 {
                let column = self.response_of(cs.vertices[t], q);
                let row_h = &cs.hessian[(3 * t + q) * m..(3 * t + q + 1) * m];
                if row_h.iter().all(|x| *x == 0.0) {
                    continue;
                }
                for s in 0..c {
                    let d = column[cs.vertices[s] as usize];
                    for r in 0..3 {
                        let coef = d[r];
                        if coef == 0.0 {
                            continue;
                        }
                        let row = &mut cs.jacobian[(3 * s + r) * m..(3 * s + r + 1) * m];
                        for (j, h) in row.iter_mut().zip(row_h) {
                            *j += coef * h;
                        }
                    }
                }
            }
        }
    }
}
