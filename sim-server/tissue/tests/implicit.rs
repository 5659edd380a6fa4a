//! The implicit backend's preconditioners: the Cholesky factor and Jacobi
//! follow the same trajectory through loads, tool holds that begin, move
//! and end, and cuts (both solve to the same residual); the factor keeps the
//! conjugate gradients at one or two iterations whenever the held set is the
//! one it was built for, and is rebuilt when it falls behind. Rebuilt on the
//! backend's worker thread, it gives the same trajectory, a step never waits
//! for it, and the worker ends with the backend.

use tissue::test_support as common;

use std::sync::mpsc;
use std::time::Duration;
use tissue::backend::{Backend, Implicit, ImplicitConfig, Preconditioner};
use tissue::prelude::*;

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

/// How a session is preconditioned.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Mode {
    Jacobi,
    /// Cholesky, rebuilt inside the step that needs it.
    Inline,
    /// Cholesky rebuilt by the worker, the test waiting for the worker after
    /// each step, so every rebuild is swapped in by the step after the one
    /// that posted it (reproducible).
    Settled,
    /// Cholesky rebuilt by the worker, never waited for: swaps land whenever
    /// the worker is done.
    Free,
}

/// The steps at which the session changes something (before stepping):
/// holds at 20, 50 (a move: the same held set), 80, a release at 110 and a
/// cut at 140.
const CHANGES: [usize; 5] = [20, 50, 80, 110, 140];

/// Per step of a session: the displacements, the CG iterations and the
/// factors put to use so far; and the preconditioner at the end.
struct Run {
    states: Vec<Vec<Vec3>>,
    iterations: Vec<usize>,
    builds: Vec<usize>,
    preconditioner: &'static str,
}

/// The block with a wall fixed and its end loaded, a vertex to hold and a
/// tetrahedron to cut.
struct Setup {
    sim: Implicit,
    a: VertexId,
    b: VertexId,
    cut: TetId,
}

fn setup(cfg: ImplicitConfig) -> Setup {
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
    let mut sim = Implicit::new(m, cfg).unwrap();
    for &v in &wall {
        sim.fix(v);
    }
    for &v in &end {
        sim.set_external_force(v, Vec3::new(0.0, 0.0, -0.01 / end.len() as f64));
    }
    Setup { sim, a, b, cut }
}

/// Runs the scripted session.
fn session(mode: Mode) -> Run {
    let mut cfg = ImplicitConfig::new(0.004);
    cfg.preconditioner = match mode {
        Mode::Jacobi => Preconditioner::Jacobi,
        _ => Preconditioner::Cholesky,
    };
    cfg.background_rebuild = matches!(mode, Mode::Settled | Mode::Free);
    let Setup { mut sim, a, b, cut } = setup(cfg);
    let n = sim.model().vertex_count();
    let mut run = Run {
        states: Vec::new(),
        iterations: Vec::new(),
        builds: Vec::new(),
        preconditioner: "",
    };
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
        if mode == Mode::Settled {
            sim.wait_for_rebuild();
        }
        run.states.push(
            (0..n)
                .map(|v| sim.displacement(VertexId::from(v)))
                .collect(),
        );
        run.iterations.push(sim.iterations());
        run.builds.push(sim.factor_builds());
        if matches!(mode, Mode::Jacobi | Mode::Inline) {
            assert!(sim.rebuild_worker().is_none() && !sim.rebuild_in_flight());
        }
    }
    run.preconditioner = sim.preconditioner();
    run
}

/// Asserts two sessions' displacements agree at every step to well within
/// the CG tolerance's reach; returns the largest displacement.
fn same_trajectory(x: &Run, y: &Run) -> f64 {
    let scale = y
        .states
        .iter()
        .flatten()
        .map(|u| u.length())
        .fold(0.0, f64::max);
    assert!(scale > 5e-4, "the session moves the block ({scale} m)");
    for (k, (x, y)) in x.states.iter().zip(&y.states).enumerate() {
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
    scale
}

#[test]
fn cholesky_and_jacobi_follow_the_same_trajectory() {
    let chol = session(Mode::Inline);
    let jac = session(Mode::Jacobi);
    assert_eq!(
        (chol.preconditioner, jac.preconditioner),
        ("cholesky", "jacobi")
    );
    same_trajectory(&chol, &jac);
    let total = |its: &[usize]| its.iter().sum::<usize>();
    let (chol_its, jac_its) = (total(&chol.iterations), total(&jac.iterations));
    assert!(
        10 * chol_its < jac_its,
        "cholesky {chol_its} vs jacobi {jac_its} iterations"
    );
}

#[test]
fn a_hold_that_moves_tissue_at_rest_converges_in_as_few_iterations_as_any() {
    // No load: the block at rest has b = 0, and the held vertex's known
    // velocity is the whole right side.
    for preconditioner in [Preconditioner::Cholesky, Preconditioner::Jacobi] {
        let mut cfg = ImplicitConfig::new(0.004);
        cfg.preconditioner = preconditioner;
        cfg.background_rebuild = false;
        let Setup { mut sim, a, .. } = setup(cfg);
        for v in 0..sim.model().vertex_count() {
            sim.set_external_force(VertexId::from(v), Vec3::ZERO);
        }
        sim.step();
        assert_eq!(sim.displacement(a), Vec3::ZERO, "at rest");
        sim.prescribe(a, Vec3::new(0.0, 0.0, -1e-3));
        sim.step();
        let its = sim.iterations();
        let limit = match preconditioner {
            // A rank-3 change of the factor's held set, as in the session.
            Preconditioner::Cholesky => 12,
            // Nearly incompressible: hundreds, but not the limit.
            Preconditioner::Jacobi => 500,
        };
        assert!(
            its <= limit && sim.residual() <= cfg.tolerance,
            "{preconditioner:?}: {its} iterations, residual {}",
            sim.residual()
        );
        // It moved the tissue around the held vertex.
        let moved = (0..sim.model().vertex_count())
            .map(|v| sim.displacement(VertexId::from(v)))
            .filter(|u| u.length() > 1e-7)
            .count();
        assert!(moved > 2, "{moved} vertices moved");
    }
}

#[test]
fn the_factor_keeps_the_iterations_low_and_is_rebuilt_when_it_falls_behind() {
    let its = session(Mode::Inline).iterations;
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

#[test]
fn background_rebuilds_follow_the_inline_trajectory_and_bring_the_iterations_back() {
    let inline = session(Mode::Inline);
    let settled = session(Mode::Settled);
    let free = session(Mode::Free);
    // The preconditioner changes the iterations, not the solution: whenever
    // the factors arrive, the trajectory is the inline one.
    same_trajectory(&settled, &inline);
    same_trajectory(&free, &inline);
    for run in [&settled, &free] {
        assert_eq!(run.preconditioner, "cholesky");
        assert_eq!(
            run.builds[0], 1,
            "the first factor is built in the first step"
        );
    }
    // Each change of the held set or of K is followed, within 30 steps, by
    // a factor built for it (posted by the step that passed the budget,
    // swapped in at the start of the next one), and from that step on the
    // conjugate gradients are back to at most two iterations.
    let its = &settled.iterations;
    let builds = &settled.builds;
    for change in [20, 80, 110, 140] {
        let swap = (change + 1..change + 30)
            .find(|&k| builds[k] > builds[k - 1])
            .unwrap_or_else(|| panic!("no factor swapped in after step {change}: {builds:?}"));
        let next = CHANGES
            .iter()
            .copied()
            .find(|&c| c > change && c != 50)
            .unwrap_or(STEPS);
        assert!(
            its[swap..next].iter().all(|&i| i <= 2),
            "after the swap at step {swap} (change at {change}): {:?}",
            &its[swap..next]
        );
        // Until then the old factor served, at a few iterations a step.
        assert!(
            its[change..swap].iter().all(|&i| i <= 12),
            "{:?}",
            &its[change..swap]
        );
    }
    assert!(builds[STEPS - 1] >= 5, "{builds:?}");
}

/// Runs `steps` steps on another thread and returns, per step, (iterations,
/// factors put to use, rebuild in flight); a step that waited for the gated
/// worker would never return, so after a generous wait the gate is opened
/// and the test fails instead of hanging (a deadlock guard, not a timing).
fn steps_beside_a_closed_gate(sim: &mut Implicit, steps: usize) -> Vec<(usize, usize, bool)> {
    let gate = sim.rebuild_gate().expect("a worker");
    let (tx, rx) = mpsc::channel();
    std::thread::scope(|s| {
        s.spawn(move || {
            for _ in 0..steps {
                sim.step();
                let seen = (
                    sim.iterations(),
                    sim.factor_builds(),
                    sim.rebuild_in_flight(),
                );
                if tx.send(seen).is_err() {
                    return;
                }
            }
        });
        let mut seen = Vec::new();
        for k in 0..steps {
            match rx.recv_timeout(Duration::from_secs(300)) {
                Ok(x) => seen.push(x),
                Err(_) => {
                    gate.open();
                    panic!("step {k} waited for the rebuild held at the gate");
                }
            }
        }
        seen
    })
}

#[test]
fn a_step_never_waits_for_a_rebuild_in_flight() {
    let Setup { mut sim, a, .. } = setup(ImplicitConfig::new(0.004));
    sim.step();
    assert_eq!(sim.factor_builds(), 1);
    assert!(sim.iterations() <= 2);
    let gate = sim
        .rebuild_gate()
        .expect("background rebuilds are the default");
    gate.close();
    // A new hold: the old factor falls behind until a rebuild is posted.
    sim.prescribe(a, Vec3::new(0.0, 0.0, -1e-3));
    let mut posted = 0;
    while !sim.rebuild_in_flight() {
        sim.step();
        posted += 1;
        assert!(posted < 200, "no rebuild posted");
    }
    // The worker holds the job at the gate: the steps go on with the old
    // factor (the newly held row out of it), and nothing is swapped in.
    let seen = steps_beside_a_closed_gate(&mut sim, 10);
    for (k, &(its, builds, in_flight)) in seen.iter().enumerate() {
        assert_eq!(
            (builds, in_flight),
            (1, true),
            "step {k} with the gate closed"
        );
        assert!((3..=12).contains(&its), "step {k}: {its} iterations");
    }
    assert_eq!(sim.preconditioner(), "cholesky");
    // Open: the factor is built, and the next step boundary swaps it in.
    gate.open();
    sim.wait_for_rebuild();
    assert_eq!(
        sim.factor_builds(),
        1,
        "nothing is swapped in between steps"
    );
    sim.step();
    assert_eq!(sim.factor_builds(), 2);
    assert!(!sim.rebuild_in_flight());
    for _ in 0..5 {
        assert!(sim.iterations() <= 2, "{} iterations", sim.iterations());
        sim.step();
    }
}

#[test]
fn a_factor_that_arrives_after_more_changes_still_serves() {
    // The held set and K change while the rebuild is held in flight: the
    // factor that arrives belongs to the snapshot taken before them, and the
    // steps must still solve (rows held since are out of it, rows released
    // since get the Jacobi step, the cut rows see the K before the cut).
    let reference = {
        let mut cfg = ImplicitConfig::new(0.004);
        cfg.background_rebuild = false;
        cfg
    };
    let mut runs = Vec::new();
    for cfg in [reference, ImplicitConfig::new(0.004)] {
        let Setup { mut sim, a, b, cut } = setup(cfg);
        let gate = sim.rebuild_gate();
        let mut states = Vec::new();
        for k in 0..120 {
            match k {
                1 => {
                    if let Some(g) = &gate {
                        g.close();
                    }
                    sim.prescribe(a, Vec3::new(0.0, 0.0, -1e-3));
                }
                40 => {
                    if gate.is_some() {
                        assert!(sim.rebuild_in_flight(), "posted before the changes");
                    }
                    sim.prescribe(b, Vec3::new(0.0, 0.0, -1e-3));
                }
                41 => sim.release(a),
                42 => {
                    sim.remove_tet(cut).unwrap();
                }
                60 => {
                    if let Some(g) = &gate {
                        assert_eq!(sim.factor_builds(), 1, "held at the gate");
                        g.open();
                        sim.wait_for_rebuild();
                    }
                }
                _ => {}
            }
            sim.step();
            assert!(
                sim.residual() <= 1e-9,
                "step {k}: residual {}",
                sim.residual()
            );
            states.push(sim.displacements().to_vec());
        }
        if gate.is_some() {
            // Swapped in at step 60 (stale for b, a and the cut); the budget
            // then orders another, for the set and K of now, which brings
            // the iterations back once swapped in.
            sim.wait_for_rebuild();
            sim.step();
            assert!(sim.factor_builds() >= 3, "{} factors", sim.factor_builds());
            assert!(sim.iterations() <= 2, "{} iterations", sim.iterations());
        }
        runs.push(states);
    }
    let scale = runs[0]
        .iter()
        .flatten()
        .map(|u| Vec3::from_array(*u).length())
        .fold(0.0, f64::max);
    for (k, (x, y)) in runs[0].iter().zip(&runs[1]).enumerate() {
        let err = x
            .iter()
            .zip(y)
            .map(|(p, q)| (Vec3::from_array(*p) - Vec3::from_array(*q)).length())
            .fold(0.0, f64::max);
        assert!(
            err < 1e-6 * scale,
            "step {k}: {err} m apart (scale {scale} m)"
        );
    }
}

#[test]
fn the_worker_thread_ends_with_the_backend() {
    let mut inline = ImplicitConfig::new(0.004);
    inline.background_rebuild = false;
    let sim = setup(inline).sim;
    assert!(
        sim.rebuild_worker().is_none(),
        "inline rebuilds start no thread"
    );
    let mut jacobi = ImplicitConfig::new(0.004);
    jacobi.preconditioner = Preconditioner::Jacobi;
    assert!(setup(jacobi).sim.rebuild_worker().is_none());

    // Idle worker.
    let sim = setup(ImplicitConfig::new(0.004)).sim;
    let worker = sim.rebuild_worker().expect("a worker");
    assert!(worker.upgrade().is_some(), "running");
    drop(sim);
    assert!(worker.upgrade().is_none(), "ended by the drop");

    // A worker holding a job at the closed gate ends too.
    let Setup { mut sim, a, .. } = setup(ImplicitConfig::new(0.004));
    sim.step();
    sim.rebuild_gate().unwrap().close();
    sim.prescribe(a, Vec3::new(0.0, 0.0, -1e-3));
    while !sim.rebuild_in_flight() {
        sim.step();
    }
    let worker = sim.rebuild_worker().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        drop(sim);
        let _ = tx.send(());
    });
    rx.recv_timeout(Duration::from_secs(300))
        .expect("dropping the backend ends its worker (deadlock guard)");
    assert!(worker.upgrade().is_none());
}
