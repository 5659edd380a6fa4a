//! The implicit backend's preconditioners: the Cholesky factor and Jacobi
//! follow the same trajectory through loads, tool holds that begin, move
//! and end, and cuts (both solve to the same residual); the factor keeps the
//! conjugate gradients at one or two iterations whenever the held set is the
//! one it was built for, and is rebuilt when it falls behind.

mod common;

use sim_server::backend::{Backend, Implicit, ImplicitConfig, Preconditioner};
use sim_server::prelude::*;

const SIZE: [f64; 3] = common::BLOCK_M;
const STEPS: usize = 170;

fn model() -> ElasticModel {
    // Nearly incompressible: where Jacobi needs hundreds of iterations.
    common::block(0.004)
}

fn vertex_at(m: &ElasticModel, p: Vec3) -> VertexId {
    let q = m.mesh().positions_m();
    VertexId::from(
        (0..q.len())
            .min_by(|&a, &b| (q[a] - p).length().total_cmp(&(q[b] - p).length()))
            .unwrap(),
    )
}

/// Runs a scripted session and returns, per step, the displacements and
/// the CG iterations.
fn session(pre: Preconditioner) -> (Vec<Vec<Vec3>>, Vec<usize>, &'static str) {
    let m = model();
    let n = m.vertex_count();
    let (a, b) = (
        vertex_at(&m, Vec3::new(0.02, 0.01, SIZE[2])),
        vertex_at(&m, Vec3::new(0.028, 0.01, SIZE[2])),
    );
    let cut = m
        .mesh()
        .tets()
        .iter()
        .position(|t| {
            let p = t.map(|v| m.mesh().positions_m()[v.idx()]);
            p.iter().all(|q| q.x > 0.03 && q.z < 0.006)
        })
        .map(TetId::from)
        .unwrap();
    let end: Vec<VertexId> = (0..n)
        .filter(|&v| m.mesh().positions_m()[v].x > SIZE[0] - 1e-9)
        .map(VertexId::from)
        .collect();
    let wall: Vec<VertexId> = (0..n)
        .filter(|&v| m.mesh().positions_m()[v].x < 1e-9)
        .map(VertexId::from)
        .collect();
    let mut cfg = ImplicitConfig::new(0.004);
    cfg.preconditioner = pre;
    let mut sim = Implicit::new(m, cfg).unwrap();
    for &v in &wall {
        sim.fix(v);
    }
    for &v in &end {
        sim.set_external_force(v, Vec3::new(0.0, 0.0, -0.01 / end.len() as f64));
    }
    let (mut states, mut iterations) = (Vec::new(), Vec::new());
    for k in 0..STEPS {
        match k {
            20 => sim.prescribe(a, Vec3::new(0.0, 0.0, -1e-3)),
            50 => sim.prescribe(a, Vec3::new(0.0, 5e-4, -2e-3)),
            80 => sim.prescribe(b, Vec3::new(0.0, 0.0, -1e-3)),
            110 => sim.release(a),
            140 => {
                sim.remove_tet(cut).unwrap();
            }
            _ => {}
        }
        sim.step();
        states.push(
            (0..n)
                .map(|v| sim.displacement(VertexId::from(v)))
                .collect(),
        );
        iterations.push(sim.iterations());
    }
    let name = sim.preconditioner();
    (states, iterations, name)
}

#[test]
fn cholesky_and_jacobi_follow_the_same_trajectory() {
    let (chol, chol_its, chol_name) = session(Preconditioner::Cholesky);
    let (jac, jac_its, jac_name) = session(Preconditioner::Jacobi);
    assert_eq!((chol_name, jac_name), ("cholesky", "jacobi"));
    let scale = jac.iter().flatten().map(|u| u.length()).fold(0.0, f64::max);
    assert!(scale > 5e-4, "the session moves the block ({scale} m)");
    for (k, (x, y)) in chol.iter().zip(&jac).enumerate() {
        let err = x
            .iter()
            .zip(y)
            .map(|(p, q)| (*p - *q).length())
            .fold(0.0, f64::max);
        assert!(
            err < 1e-6 * scale,
            "step {k}: {err} m apart (scale {scale} m)"
        );
    }
    let total = |its: &[usize]| its.iter().sum::<usize>();
    assert!(
        10 * total(&chol_its) < total(&jac_its),
        "cholesky {} vs jacobi {} iterations",
        total(&chol_its),
        total(&jac_its)
    );
}

#[test]
fn the_factor_keeps_the_iterations_low_and_is_rebuilt_when_it_falls_behind() {
    let (_, its, _) = session(Preconditioner::Cholesky);
    // Before any change of the held set, the factor is A^-1.
    assert!(its[..20].iter().all(|&i| i <= 2), "{:?}", &its[..20]);
    // A hold that begins or ends, or a cut, costs a few iterations per step
    // until the excess passes the budget; then the factor is rebuilt and
    // the steps are back to at most two.
    for change in [20, 80, 110, 140] {
        let after = &its[change..change + 30];
        assert!(
            after.iter().all(|&i| i <= 12),
            "after step {change}: {after:?}"
        );
        assert!(
            after[25..].iter().all(|&i| i <= 2),
            "after step {change}: {after:?}"
        );
    }
    // Moving a held vertex (step 50) changes the right side only.
    assert!(its[45..80].iter().all(|&i| i <= 2), "{:?}", &its[45..80]);
}
