//! A backend step allocates nothing once it is running: a counting global
//! allocator counts allocations on this thread over 200 steps of each
//! backend (each prepared ahead as a live loop does, `Backend::prepare_step`), with loads and a tool hold that moves every step (the hold set
//! is unchanged, so the implicit backend's Cholesky factor and the static
//! backends' hold systems are reused, not rebuilt). The one exception is
//! the multi-threaded tensor-mass step: handing the step to its rayon pool
//! goes through rayon's job injector, a queue that allocates one block per
//! 63 jobs; that is bounded here, not zero. (The count sees the calling
//! thread only, so that row checks the hand-off; the pass itself is the
//! same code the single-thread row runs on the counted thread.)
//!
//! The implicit backend's background rebuild allocates nothing on the
//! stepping thread either: posting a rebuild copies into buffers made at
//! construction, and swapping the new factor in moves it (the worker thread
//! builds it and frees the old one, outside the count).

use tissue::test_support as common;

use shared::alloc_count::{Counting, count};
use tissue::backend::{Backend, Hybrid, HybridConfig, Implicit, ImplicitConfig, Precomputed};
use tissue::prelude::*;

#[global_allocator]
static ALLOCATOR: Counting = Counting;

const SIZE: [f64; 3] = common::BLOCK_M;

fn model() -> ElasticModel {
    common::block(0.005)
}

#[test]
fn two_hundred_steps_of_each_backend_allocate_nothing() {
    let m = model();
    let p = m.mesh().positions_m().to_vec();
    let wall: Vec<VertexId> = (0..p.len())
        .filter(|&v| p[v].x < 1e-9)
        .map(VertexId::from)
        .collect();
    let end: Vec<VertexId> = (0..p.len())
        .filter(|&v| p[v].x > SIZE[0] - 1e-9)
        .map(VertexId::from)
        .collect();
    // A top-face vertex in the middle: on the precomputed part of the hybrid.
    let held = VertexId::from(
        (0..p.len())
            .find(|&v| (p[v] - Vec3::new(0.015, 0.01, SIZE[2])).length() < 1e-9)
            .unwrap(),
    );
    let bound = tissue::tensor_mass::element_bound(&m).dt_max_s;
    let cuttable: Vec<TetId> = (0..m.mesh().tet_count())
        .map(TetId::from)
        .filter(|t| m.mesh().tet_points(*t).iter().all(|q| q.x >= 0.02))
        .collect();
    let mut threaded = ExplicitConfig::new(0.9 * bound);
    threaded.threads = 2;
    // StVK: the large-strain pass and the sub-steps following its tangent.
    let stvk = {
        let mat = *m.materials().material(TetId(0));
        let mats = TetMaterials::uniform(
            mat.with_model(tissue::material::MaterialModel::Stvk),
            m.mesh().tet_count(),
        );
        ElasticModel::new(m.mesh().clone(), mats).unwrap()
    };
    // (backend, allocations allowed in 200 steps)
    let sims: Vec<(Box<dyn Backend>, u64)> = vec![
        (
            Box::new(Explicit::<f32>::new(m.clone(), ExplicitConfig::new(0.9 * bound)).unwrap()),
            0,
        ),
        (
            Box::new(Explicit::<f64>::new(m.clone(), threaded).unwrap()),
            200 / 63 + 1,
        ),
        (
            Box::new(Explicit::<f32>::new(stvk, ExplicitConfig::new(0.9 * bound)).unwrap()),
            0,
        ),
        (
            Box::new(Implicit::new(m.clone(), ImplicitConfig::new(10.0 * bound)).unwrap()),
            0,
        ),
        (
            Box::new(Precomputed::new(m.clone(), &wall, 10.0 * bound, None, |_, _| {}).unwrap()),
            0,
        ),
        (
            Box::new(
                Hybrid::new(
                    m.clone(),
                    &wall,
                    &cuttable,
                    HybridConfig::new(10.0 * bound),
                    |_, _| {},
                )
                .unwrap(),
            ),
            0,
        ),
    ];
    for (mut sim, allowed) in sims {
        for &v in &wall {
            sim.fix(v);
        }
        for &v in &end {
            sim.set_external_force(v, Vec3::new(0.0, 0.0, -0.01 / end.len() as f64));
        }
        sim.prescribe(held, Vec3::new(0.0, 0.0, -1e-4));
        // Warm-up: first-step set-up (factors, hold systems) may allocate.
        // A live loop prepares each step while it waits for the pose.
        for _ in 0..3 {
            sim.prepare_step();
            sim.step();
        }
        let ((), allocations) = count(|| {
            for k in 0..200 {
                sim.prepare_step();
                // The hold moves (same set): the right side changes only.
                sim.prescribe(held, Vec3::new(0.0, 0.0, -1e-4 * (1.0 + k as f64 * 1e-3)));
                sim.step();
            }
        });
        assert!(
            allocations <= allowed,
            "{}: {allocations} allocations in 200 steps (at most {allowed})",
            sim.capabilities().name
        );
        assert!(sim.displacement(held).z < -1e-4);
    }
}

#[test]
fn a_background_factor_rebuild_allocates_nothing_on_the_stepping_thread() {
    background_rebuilds(None);
}

#[test]
fn steps_stopped_by_the_iteration_budget_allocate_nothing_either() {
    // A budget of one: every step the stale factor cannot finish in one
    // iteration is capped and posts its rebuild at once.
    background_rebuilds(Some(1));
}

/// Holds, a release and a cut with the factor rebuilt in the background,
/// under the per-step iteration `budget`: no allocation in the steps.
fn background_rebuilds(budget: Option<usize>) {
    let m = model();
    let p = m.mesh().positions_m().to_vec();
    let at = |q: Vec3| {
        VertexId::from(
            (0..p.len())
                .min_by(|&a, &b| (p[a] - q).length().total_cmp(&(p[b] - q).length()))
                .unwrap(),
        )
    };
    let bound = tissue::tensor_mass::element_bound(&m).dt_max_s;
    let cuttable = TetId::from(
        (0..m.mesh().tet_count())
            .find(|&t| {
                m.mesh()
                    .tet_points(TetId::from(t))
                    .iter()
                    .all(|q| q.x >= 0.02)
            })
            .unwrap(),
    );
    let mut cfg = ImplicitConfig::new(10.0 * bound);
    cfg.step_iterations = budget;
    let mut sim = Implicit::new(m, cfg).unwrap();
    for (v, q) in p.iter().enumerate() {
        if q.x < 1e-9 {
            sim.fix(VertexId::from(v));
        }
    }
    let (a, b) = (
        at(Vec3::new(0.015, 0.01, SIZE[2])),
        at(Vec3::new(0.025, 0.01, SIZE[2])),
    );
    sim.prescribe(a, Vec3::new(0.0, 0.0, -1e-4));
    for _ in 0..3 {
        sim.step();
    }
    assert_eq!(sim.factor_builds(), 1);
    // A new hold, a release and a cut (outside the count: a cut may grow the
    // model's buffers): each falls behind the factor until a rebuild is
    // posted, waited for and swapped in; the steps are counted.
    let mut allocations = 0;
    for change in 0..3 {
        match change {
            0 => sim.prescribe(b, Vec3::new(0.0, 0.0, -1e-4)),
            1 => sim.release(a),
            _ => {
                sim.remove_tet(cuttable).unwrap();
            }
        }
        let before = sim.factor_builds();
        let ((), n) = count(|| {
            for _ in 0..500 {
                sim.step();
                if sim.factor_builds() > before {
                    break;
                }
                // Blocking, for the test only: the step itself never waits.
                sim.wait_for_rebuild();
            }
        });
        allocations += n;
    }
    let builds = sim.factor_builds();
    if budget.is_some() {
        assert!(sim.capped_steps() >= 3, "{} capped", sim.capped_steps());
        assert!(builds >= 4, "{builds} factors");
    } else {
        assert_eq!(builds, 4, "three rebuilds swapped in");
    }
    assert_eq!(allocations, 0, "{allocations} allocations");
}
