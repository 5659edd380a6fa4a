//! The penalty contact on the precomputed backend: the static equilibrium
//! of the tissue and the contact springs, solved every step on the
//! precomputed responses (where the paper's projection law used to be the
//! only one here, and missed a tool between vertices).
//!
//! The backend is a linear static map S from the surface forces to the
//! displacements (its responses T, with the tools' holds): u = a + T G for
//! contact forces G. With the penalty springs' forces f(u), a step finds
//! the forces G = f(S(G)), which is where the potential
//!
//! ```text
//! E(G) = 1/2 G^T T G + Phi(S(G))      (Phi: the springs' energy)
//! ```
//!
//! is stationary: the tissue's elastic energy plus the springs'. Newton
//! on the contact vertices,
//!
//! ```text
//! (I + H T_CC) dG = f(u) - G,
//! ```
//!
//! H the springs' Hessian (each point's spread over its triangle: k n n^T
//! and the turning of the normal round the tool), T_CC the responses of
//! the contact vertices to each other (read from the precomputed responses,
//! no solve; with the holding forces each response calls for when that is
//! cheap, [`newton::HOLD_COUPLING_FLOPS`]): the contact problem on the compliance
//! W = T_CC that SOFA's constraint solvers and LCPForceFeedback pose
//! (Duriez et al. 2006, Saupin et al. 2008), here with the penalty law's
//! springs instead of complementarity. Each iterate is a consistent state
//! u = S(G) (S applied exactly at the points' vertices, the holds
//! included; the whole body once at the end of the step), and a step along
//! dG is taken only as far as E decreases enough (Armijo backtracking;
//! S is affine, so a shorter step needs no new application of S, only the
//! springs again). Without that line search (until 2026-11-27) the
//! iterates could cycle between contact sets from one step to the next
//! and, after a stall of the simulation, settled in 1 of 9 real-time liver
//! runs on a second equilibrium with surface caught on the far side of the
//! tip (forces of 4-16 N against 1.2 N, the tissue hanging on the tool
//! after it withdrew): the springs' energy is not convex round a tip, and
//! a method that only descends stays with the equilibrium it starts next
//! to. The turning of the normal makes H indefinite: where the Newton
//! direction with it does not descend, the step takes H's slopes k n n^T
//! alone (positive) for the rest of the step, and where that does not
//! either (holds left out) dG = f - G, which always does (T is positive).
//! Measured on the liver demo's grasp and poke (docs/results/precomputed-contact.md): with the slopes
//! alone and no holds' coupling, 3,089 of 7,533 contact steps ended at the
//! iteration limit, converging linearly; with both, 13-24. The springs'
//! forces at the last state are the tools' reactions. Static: no damping
//! (no velocity), and no friction (its springs need the motion between
//! sub-steps; a scene asking for it here is refused).

use super::Compliance;
use crate::dense_lu::DenseLu;
use crate::math::{Mat3, Real, Vec3};
use crate::tensor_mass::{ForcePoint, ForceTerm};

mod newton;

use newton::{chord_converged, newton_direction};

/// Newton iterations at most per step.
const MAX_ITERATIONS: usize = 12;
/// Converged when the Newton step moves no contact vertex more than this
/// (m): 10 nm, a force error of about 1e-5 N at the contact's stiffness.
const TOLERANCE_M: Real = 1e-8;
/// Armijo's sufficient decrease: a step must lower E by at least this
/// fraction of what its slope promises.
const ARMIJO: Real = 1e-4;
/// Halvings of a step before the iterations stop where they are.
const MAX_HALVINGS: usize = 8;

/// Scratch of the contact solve (buffers reused across steps).
#[derive(Default)]
pub(crate) struct ContactSolve {
    /// Per vertex: the springs' force at the current state (N).
    force: Vec<[Real; 3]>,
    /// Per vertex: the contact force applied to the tissue, G (N).
    applied: Vec<[Real; 3]>,
    /// Per vertex: the trial G + alpha dG (N).
    trial: Vec<[Real; 3]>,
    /// Per vertex: the contact force of the step before the last, G_n-1
    /// (for the predictor of [`warm_start`]), and the vertices
    /// where it is set.
    previous: Vec<Option<Vec3>>,
    previous_vertices: Vec<u32>,
    /// The vertices where `applied` may be non-zero.
    applied_vertices: Vec<u32>,
    /// Per vertex: its slot among the contact vertices, `u32::MAX` if none.
    slot: Vec<u32>,
    /// The contact vertices: the loadable vertices of the acting points
    /// and those of `applied_vertices`.
    vertices: Vec<u32>,
    /// Per vertex (written at `rows`): the current state's displacement
    /// and the full Newton step's change of it.
    u_at: Vec<Vec3>,
    du: Vec<Vec3>,
    /// The Newton system (row-major, 3c x 3c) and its right side.
    jacobian: Vec<Real>,
    rhs: Vec<Real>,
    /// The Newton system's factorisation buffers.
    lu: DenseLu,
    /// Whether `jacobian` holds the factors of the last Newton matrix and
    /// `rhs` nothing else since a whole step along its direction: then the
    /// acting points' signature ([`newton::field_signature`]) it was built at, and
    /// its contact vertices.
    chord: Option<(usize, usize)>,
    chord_of: Vec<u32>,
    /// H per contact-vertex pair, summed over points (3c x 3c, row-major).
    hessian: Vec<Real>,
    /// Beyond [`newton::DENSE_LIMIT`]: H's diagonal blocks, per contact vertex.
    blocks: Vec<Mat3>,
    /// T_CC (3c x 3c, row-major, `newton::gather_compliance`) and
    /// the contact vertices it is of (cleared at each step's start: the
    /// holds may have changed).
    compliance: Vec<Real>,
    compliance_of: Vec<u32>,
    /// The holding forces of one unit force.
    holding: Vec<(u32, Vec3)>,
    /// The vertices of the step's contact points and of the applied
    /// forces (each once).
    rows: Vec<u32>,
    /// Newton iterations of the last step.
    pub iterations: usize,
    /// Whether the last step stopped at [`MAX_ITERATIONS`] short of the
    /// tolerance.
    pub capped: bool,
}

/// The vertices of `field`'s points and of the applied forces, each once,
/// into `cs.rows` (the slots left clean).
fn gather_rows<F: ForceTerm>(field: &F, cs: &mut ContactSolve) {
    cs.rows.clear();
    let points = field.points().iter().flat_map(|p| p.vertices());
    for v in points.chain(cs.applied_vertices.iter().copied()) {
        if cs.slot[v as usize] == u32::MAX {
            cs.slot[v as usize] = 0;
            cs.rows.push(v);
        }
    }
    for &v in &cs.rows {
        cs.slot[v as usize] = u32::MAX;
    }
}

/// The largest change of a row's displacement component under the
/// direction in `cs.du` (m).
fn largest_change(cs: &ContactSolve) -> Real {
    (cs.rows.iter()).fold(0.0 as Real, |w, &v| {
        w.max(cs.du[v as usize].abs().max_element())
    })
}

/// G = 0 on every vertex (`cs.applied` and its list cleared).
fn clear_applied(cs: &mut ContactSolve) {
    for &v in &cs.applied_vertices {
        cs.applied[v as usize] = [0.0; 3];
    }
    cs.applied_vertices.clear();
}

/// No contact forces of an earlier step to predict from.
fn forget_previous(cs: &mut ContactSolve) {
    for &v in &cs.previous_vertices {
        cs.previous[v as usize] = None;
    }
    cs.previous_vertices.clear();
}

/// Contact vertex `s`'s three entries of a 3c vector.
fn step_at(x: &[Real], s: usize) -> Vec3 {
    Vec3::new(x[3 * s], x[3 * s + 1], x[3 * s + 2])
}

/// The sum over the contact vertices of a . b (per-vertex arrays).
fn dot(vertices: &[u32], a: &[[Real; 3]], b: &[Vec3]) -> Real {
    (vertices.iter())
        .map(|&v| Vec3::from_array(a[v as usize]).dot(b[v as usize]))
        .sum()
}

/// One step under the penalty contact `field` (see the module docs).
pub(crate) fn step_with_penalty<C: Compliance, F: ForceTerm>(
    body: &mut C,
    field: &mut F,
    cs: &mut ContactSolve,
) {
    let n = body.vertex_len();
    if cs.force.len() != n {
        cs.force = vec![[0.0; 3]; n];
        cs.applied = vec![[0.0; 3]; n];
        cs.trial = vec![[0.0; 3]; n];
        cs.slot = vec![u32::MAX; n];
        cs.u_at = vec![Vec3::ZERO; n];
        cs.du = vec![Vec3::ZERO; n];
        cs.previous = vec![None; n];
        cs.previous_vertices.clear();
    }
    cs.iterations = 0;
    cs.capped = false;
    if field.is_idle() {
        body.clear_contact_forces();
        forget_previous(cs);
        body.step_static();
    } else {
        // Warm: from the last step's contact forces (its equilibrium,
        // with this step's loads, holds and tool pose) carried on by
        // their change over that step, where the free solution would
        // start the press's whole depth away. The iterations need the
        // springs' vertices only; the whole body once, at the end.
        body.prepare_rows();
        let predicted = warm_start(body, cs);
        gather_rows(field, cs);
        solve_contact(body, field, cs, predicted);
        body.set_contact_forces(&cs.applied_vertices, &cs.applied);
        body.step_static();
    }
}

/// G from the last step's contact forces G_n, on vertices still
/// loadable, each carried on by its change over that step where it had
/// one (2 G_n - G_n-1: a linear predictor, so that a tool moving
/// steadily starts the iterations a second-order distance from the
/// solution instead of a first-order one; measured on the liver poke
/// and sway: docs/results/precomputed-contact.md). A vertex that only now carries a force starts at
/// it. The line search makes any start safe: the iterates are
/// consistent states and only descend. Returns whether any vertex was
/// carried on (see [`restart_unpredicted`]).
fn warm_start<C: Compliance>(body: &C, cs: &mut ContactSolve) -> bool {
    let mut predicted = false;
    clear_applied(cs);
    for (v, f) in body.contact_forces() {
        if body.loadable(v as usize) {
            let start = match cs.previous[v as usize] {
                Some(before) if before != f => {
                    predicted = true;
                    2.0 * f - before
                }
                _ => f,
            };
            cs.applied[v as usize] = start.to_array();
            cs.applied_vertices.push(v);
        }
    }
    forget_previous(cs);
    for (v, f) in body.contact_forces() {
        cs.previous[v as usize] = Some(f);
        cs.previous_vertices.push(v);
    }
    predicted
}

/// G back at the last step's contact forces G_n (kept in `cs.previous`
/// by [`warm_start`]) unpredicted; returns E there
/// ([`start_at`]). Where the Newton
/// direction with the whole Hessian does not descend from the
/// predicted start, that start left the region where Newton converges
/// quadratically: on the liver demo's grasp, falling back to the slopes
/// alone from there ended 273 steps a run at the iteration limit
/// (stagnating, or walking off towards another equilibrium) where the
/// plain warm start ended 15-19.
fn restart_unpredicted<C: Compliance, F: ForceTerm>(
    body: &mut C,
    field: &mut F,
    cs: &mut ContactSolve,
) -> Real {
    clear_applied(cs);
    for &v in &cs.previous_vertices {
        if let Some(f) = cs.previous[v as usize]
            && body.loadable(v as usize)
        {
            cs.applied[v as usize] = f.to_array();
            cs.applied_vertices.push(v);
        }
    }
    start_at(body, field, cs)
}

/// The iterations' starting state for G = `cs.applied`: S applied at
/// the rows (kept in `cs.u_at`), no chord yet, and the springs there;
/// returns E there.
fn start_at<C: Compliance, F: ForceTerm>(
    body: &mut C,
    field: &mut F,
    cs: &mut ContactSolve,
) -> Real {
    body.set_contact_forces(&cs.applied_vertices, &cs.applied);
    body.step_rows(&cs.rows);
    for &v in &cs.rows {
        cs.u_at[v as usize] = body.displacement_of(v);
    }
    cs.chord = None;
    evaluate_springs(body, field, cs)
}

/// The springs at the current state: their forces into `cs.force`, the
/// field's report and penetrations, and their energy (J).
fn evaluate_springs<C: Compliance, F: ForceTerm>(
    body: &C,
    field: &mut F,
    cs: &mut ContactSolve,
) -> Real {
    field.restart_report();
    let (rest, u) = (body.model().mesh().positions_m(), body.displacements());
    field.static_forces(rest, u, &mut cs.force);
    field.spring_energy_j()
}

fn solve_contact<C: Compliance, F: ForceTerm>(
    body: &mut C,
    field: &mut F,
    cs: &mut ContactSolve,
    mut predicted: bool,
) {
    cs.compliance_of.clear();
    let mut energy = start_at(body, field, cs);
    // Whether the field's last evaluation is of the current state.
    let mut current = true;
    let mut whole_hessian = true;
    for k in 0..MAX_ITERATIONS {
        cs.iterations = k + 1;
        gather_contact_vertices(body, field, cs);
        let c = cs.vertices.len();
        if c == 0 {
            break;
        }
        if chord_converged(body, field, cs) {
            break;
        }
        // The Newton direction with the springs' whole Hessian, the
        // normal's turning round the tool included (quadratic where it
        // descends); where it does not (that turning makes it
        // indefinite), with their slopes alone for the rest of the step.
        newton_direction(body, field, cs, whole_hessian);
        let mut slope = slope_of(cs);
        if slope >= 0.0 && whole_hessian && predicted && k + 1 < MAX_ITERATIONS {
            // Once, and not in the last iteration (which would then
            // end the step unconverged without marking it capped).
            predicted = false;
            energy = restart_unpredicted(body, field, cs);
            continue;
        }
        if slope >= 0.0 && whole_hessian {
            whole_hessian = false;
            newton_direction(body, field, cs, false);
            slope = slope_of(cs);
        }
        if largest_change(cs) <= TOLERANCE_M {
            // Converged: the state is within the tolerance of the
            // solution (the step left is that small), and the springs
            // were evaluated at it (no evaluation for a step that would
            // not change them measurably).
            break;
        }
        if k + 1 == MAX_ITERATIONS {
            cs.capped = true;
            break;
        }
        if slope >= 0.0 {
            // Not a descent direction either: dG = f - G, which is one.
            cs.chord = None;
            newton_rhs(cs);
            try_direction(body, cs);
            slope = slope_of(cs);
            if slope >= 0.0 {
                break;
            }
        }
        // G^T dU and dG^T dU: E along the step is
        // E(0) + a G^T dU + a^2/2 dG^T dU + Phi(a) - Phi(0).
        let g_du = dot(&cs.vertices, &cs.applied, &cs.du);
        let curvature: Real = (cs.vertices.iter().enumerate())
            .map(|(s, &v)| {
                let dg = step_at(&cs.rhs, s);
                dg.dot(cs.du[v as usize])
            })
            .sum();
        let mut alpha: Real = 1.0;
        let mut taken = false;
        for _ in 0..=MAX_HALVINGS {
            for &v in &cs.rows {
                let u = cs.u_at[v as usize] + alpha * cs.du[v as usize];
                body.set_displacement(v, u);
            }
            let trial = evaluate_springs(body, field, cs);
            let change = alpha * g_du + 0.5 * alpha * alpha * curvature + trial - energy;
            if change <= ARMIJO * alpha * slope {
                energy = trial;
                taken = true;
                break;
            }
            alpha *= 0.5;
        }
        if !taken {
            // No decrease along it: stay (the state is consistent).
            restore_rows(body, cs);
            current = false;
            break;
        }
        take_step(body, cs, alpha);
        if alpha != 1.0 {
            // Not the whole Newton step: the rest of it is no small
            // quantity for the chord test to confirm.
            cs.chord = None;
        }
    }
    if !current {
        evaluate_springs(body, field, cs);
    }
    for &v in &cs.vertices {
        cs.slot[v as usize] = u32::MAX;
    }
}

/// `cs.rhs` = f - G over the contact vertices.
fn newton_rhs(cs: &mut ContactSolve) {
    cs.rhs.clear();
    for &v in &cs.vertices {
        let d = Vec3::from_array(cs.force[v as usize]) - Vec3::from_array(cs.applied[v as usize]);
        cs.rhs.extend_from_slice(&[d.x, d.y, d.z]);
    }
}

/// The state for G + dG (`cs.rhs`) at the rows, and its change from
/// the current one into `cs.du` (the rows keep the current state).
fn try_direction<C: Compliance>(body: &mut C, cs: &mut ContactSolve) {
    for (s, &v) in cs.vertices.iter().enumerate() {
        let g = Vec3::from_array(cs.applied[v as usize]);
        let dg = step_at(&cs.rhs, s);
        cs.trial[v as usize] = (g + dg).to_array();
    }
    body.set_contact_forces(&cs.vertices, &cs.trial);
    body.step_rows(&cs.rows);
    for &v in &cs.rows {
        cs.du[v as usize] = body.displacement_of(v) - cs.u_at[v as usize];
    }
    restore_rows(body, cs);
}

/// The rows back at the current state.
fn restore_rows<C: Compliance>(body: &mut C, cs: &ContactSolve) {
    for &v in &cs.rows {
        body.set_displacement(v, cs.u_at[v as usize]);
    }
}

/// E's slope along the direction at its start: (G - f)^T dU.
fn slope_of(cs: &ContactSolve) -> Real {
    dot(&cs.vertices, &cs.applied, &cs.du) - dot(&cs.vertices, &cs.force, &cs.du)
}

/// G += alpha dG and the rows' state with it (S is affine).
fn take_step<C: Compliance>(body: &mut C, cs: &mut ContactSolve, alpha: Real) {
    for (s, &v) in cs.vertices.iter().enumerate() {
        let dg = step_at(&cs.rhs, s);
        let g = Vec3::from_array(cs.applied[v as usize]) + alpha * dg;
        cs.applied[v as usize] = g.to_array();
    }
    // The contact vertices hold every applied vertex (loadable, as
    // they all are).
    cs.applied_vertices.clear();
    cs.applied_vertices.extend_from_slice(&cs.vertices);
    for &v in &cs.rows {
        let u = cs.u_at[v as usize] + alpha * cs.du[v as usize];
        cs.u_at[v as usize] = u;
        body.set_displacement(v, u);
    }
}

/// The contact vertices: the loadable vertices of the acting points and
/// of the applied forces.
fn gather_contact_vertices<C: Compliance, F: ForceTerm>(
    body: &C,
    field: &F,
    cs: &mut ContactSolve,
) {
    for &v in &cs.vertices {
        cs.slot[v as usize] = u32::MAX;
    }
    cs.vertices.clear();
    let acting = (field.points().iter().zip(field.penetrations_m()))
        .filter(|(_, d)| **d > 0.0)
        .flat_map(|(p, _)| p.vertices());
    for v in acting.chain(cs.applied_vertices.iter().copied()) {
        let vi = v as usize;
        if cs.slot[vi] == u32::MAX && body.loadable(vi) {
            cs.slot[vi] = cs.vertices.len() as u32;
            cs.vertices.push(v);
        }
    }
}
