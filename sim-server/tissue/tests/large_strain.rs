//! The explicit backend with StVK and corotational materials: a rigid
//! rotation of the whole body is force-free (and not for the linear model),
//! an undamped body keeps its energy, cutting is a rebuild without the
//! element and restoring gives back the original, the result does not
//! depend on the thread count, the stable step follows the stretch, and
//! the backends that cannot run a nonlinear model refuse it.

use tissue::test_support as common;

use tissue::backend::{Implicit, ImplicitConfig, Precomputed};
use tissue::material::MaterialModel;
use tissue::prelude::*;
use tissue::static_solve::StaticError;
use tissue::tensor_mass::element_bound;

fn model_with(model: MaterialModel, damping_per_s: f64, anisotropic: bool) -> ElasticModel {
    let mesh = common::box_mesh([4, 2, 2], 0.005, 0.15, 7);
    let base = if anisotropic {
        common::aniso_material(2000.0, 1500.0, Terms::ALL).unwrap()
    } else {
        common::iso_material()
    };
    let mat = Material::new(*base.elasticity(), 1060.0, damping_per_s)
        .unwrap()
        .with_model(model);
    let mut mats = TetMaterials::uniform(mat, mesh.tet_count());
    if anisotropic {
        for t in 0..mesh.tet_count() {
            mats.set_fiber(TetId::from(t), Vec3::new(1.0, 0.4, 0.2))
                .unwrap();
        }
    }
    ElasticModel::new(mesh, mats).unwrap()
}

fn sim(model: ElasticModel, threads: usize) -> Explicit<f64> {
    let bound = element_bound(&model).dt_max_s;
    let mut cfg = ExplicitConfig::new(0.5 * bound);
    cfg.threads = threads;
    Explicit::new(model, cfg).unwrap()
}

fn state(sim: &Explicit<f64>) -> Vec<Vec3> {
    sim.displacements()
        .iter()
        .map(|u| Vec3::from_array(*u))
        .collect()
}

#[test]
fn a_rotated_body_stays_put_unless_the_model_is_linear() {
    let turn = Mat3::from_axis_angle(Vec3::new(0.2, 1.0, 0.3).normalize(), 90f64.to_radians());
    for (model, anisotropic) in [
        (MaterialModel::Stvk, false),
        (MaterialModel::Stvk, true),
        (MaterialModel::Corotational, false),
        (MaterialModel::Corotational, true),
        (MaterialModel::Linear, false),
    ] {
        let mut s = sim(model_with(model, 0.0, anisotropic), 1);
        let rotated: Vec<Vec3> = s
            .model()
            .mesh()
            .positions_m()
            .iter()
            .map(|p| turn * *p - *p)
            .collect();
        s.set_state(&rotated, &rotated);
        for _ in 0..20 {
            s.step();
        }
        let moved = state(&s)
            .iter()
            .zip(&rotated)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f64::max);
        if model == MaterialModel::Linear {
            assert!(
                moved > 1e-4,
                "linear: a rotation should strain it ({moved} m)"
            );
        } else {
            assert!(
                moved < 1e-12,
                "{model:?} aniso {anisotropic}: moved {moved} m"
            );
        }
    }
}

#[test]
fn an_undamped_stretched_body_keeps_its_energy() {
    for (model, anisotropic) in [
        (MaterialModel::Stvk, false),
        (MaterialModel::Stvk, true),
        (MaterialModel::Corotational, false),
    ] {
        let mut s = sim(model_with(model, 0.0, anisotropic), 1);
        // A 30% stretch along x, released from rest.
        let stretched: Vec<Vec3> = s
            .model()
            .mesh()
            .positions_m()
            .iter()
            .map(|p| Vec3::new(0.3 * p.x, -0.05 * p.y, 0.02 * p.z))
            .collect();
        s.set_state(&stretched, &stretched);
        let e0 = s.energy_j();
        let mut worst: f64 = 0.0;
        for _ in 0..3000 {
            s.step();
            worst = worst.max((s.energy_j() - e0).abs());
        }
        // Central differences keep a nearby energy; measured with the
        // backward-difference velocity at half the rest bound it wanders by
        // up to ~15% (the linear model does the same), while a sub-step
        // count toggling every few steps pumped it to 2.8x.
        assert!(
            worst < 0.25 * e0,
            "{model:?} aniso {anisotropic}: energy moved by {worst} of {e0} J"
        );
        assert!(state(&s).iter().all(|u| u.is_finite()));
    }
}

#[test]
fn cutting_is_a_rebuild_without_the_element_and_restoring_gives_it_back() {
    for model in [MaterialModel::Stvk, MaterialModel::Corotational] {
        let cut = TetId(5);
        let loaded = |s: &mut Explicit<f64>| {
            s.fix(VertexId(0));
            s.fix(VertexId(1));
            s.set_external_force(VertexId(40), Vec3::new(0.0, 0.02, -0.05));
        };
        let run = |s: &mut Explicit<f64>| {
            for _ in 0..300 {
                s.step();
            }
            state(s)
        };
        // Removed after construction (with the body deformed) and a rebuild
        // without it from the start, both from rest: the same trajectory.
        let mut live = sim(model_with(model, 10.0, true), 1);
        loaded(&mut live);
        live.remove_tet(cut).unwrap();
        let mut rebuilt_model = model_with(model, 10.0, true);
        rebuilt_model.remove_tet(cut).unwrap();
        let mut rebuilt = sim(rebuilt_model, 1);
        loaded(&mut rebuilt);
        let (a, b) = (run(&mut live), run(&mut rebuilt));
        let diff = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (*x - *y).length())
            .fold(0.0, f64::max);
        assert!(
            diff < 1e-12,
            "{model:?}: removed vs rebuilt differ by {diff} m"
        );
        // Remove then restore at rest = never cut.
        let mut restored = sim(model_with(model, 10.0, true), 1);
        restored.remove_tet(cut).unwrap();
        restored.restore_tet(cut).unwrap();
        loaded(&mut restored);
        let mut never = sim(model_with(model, 10.0, true), 1);
        loaded(&mut never);
        let (a, b) = (run(&mut restored), run(&mut never));
        let diff = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (*x - *y).length())
            .fold(0.0, f64::max);
        assert!(
            diff < 1e-12,
            "{model:?}: restored vs never cut differ by {diff} m"
        );
        assert!(
            a.iter().map(|u| u.length()).fold(0.0, f64::max) > 1e-4,
            "the load moved nothing"
        );
    }
}

#[test]
fn threads_do_not_change_the_result() {
    let mut runs = Vec::new();
    for threads in [1, 3] {
        let mut s = sim(model_with(MaterialModel::Stvk, 5.0, true), threads);
        s.fix(VertexId(0));
        s.set_external_force(VertexId(30), Vec3::new(0.1, 0.0, 0.0));
        for _ in 0..200 {
            s.step();
        }
        runs.push(state(&s));
    }
    // The nonlinear pass is order-independent; the linear kernel's parts
    // add the rows they share in another order, so equal to round-off.
    let diff = runs[0]
        .iter()
        .zip(&runs[1])
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f64::max);
    assert!(diff < 1e-12, "1 and 3 threads differ by {diff} m");
}

#[test]
fn the_stable_step_follows_the_stretch() {
    let mut s = sim(model_with(MaterialModel::Stvk, 50.0, false), 1);
    assert_eq!(s.substeps(), 1);
    // Pull one end 60% of the length away and hold it: StVK stiffens.
    let p = s.model().mesh().positions_m().to_vec();
    for (v, q) in p.iter().enumerate() {
        if q.x < 1e-9 {
            s.fix(VertexId::from(v));
        } else if q.x > 0.02 - 1e-9 {
            s.prescribe(VertexId::from(v), Vec3::new(0.012, 0.0, 0.0));
        }
    }
    for _ in 0..2000 {
        s.step();
    }
    let report = s.large_strain().unwrap().last();
    assert!(
        s.substeps() > 1,
        "stretched StVK needs more sub-steps (tangent bound {:.3e} /s^2)",
        report.lambda
    );
    assert!(state(&s).iter().all(|u| u.is_finite() && u.length() < 0.05));
}

#[test]
fn backends_that_run_the_linear_model_only_refuse_a_nonlinear_one() {
    let model = model_with(MaterialModel::Corotational, 5.0, false);
    let dt = 10.0 * element_bound(&model).dt_max_s;
    let msg = Implicit::new(model.clone(), ImplicitConfig::new(dt))
        .err()
        .expect("implicit refuses")
        .to_string();
    assert!(
        msg.contains("implicit backend runs the linear model only"),
        "{msg}"
    );
    assert!(msg.contains("model = \"corotational\""), "{msg}");
    let msg = Precomputed::new(model.clone(), &[VertexId(0)], dt, None, |_, _| {})
        .err()
        .expect("precomputed refuses")
        .to_string();
    assert!(msg.contains("precomputed backend"), "{msg}");
    let err = solve_static(
        &model,
        &Dirichlet::new(model.vertex_count()),
        &vec![Vec3::ZERO; model.vertex_count()],
    );
    assert!(matches!(err, Err(StaticError::LinearOnly(_))), "{err:?}");
}

#[test]
fn a_sudden_jump_refines_the_step_it_happens_in() {
    // One end of a 6 cm StVK beam jumps 3 cm in one 1 ms step: the elements
    // next to it are sheared 6:1. The sub-step after the jump sees the
    // tangent and refines before it integrates (a coarse one flung a vertex
    // 12 cm and then the state went to NaN).
    let mesh = BoxSpec::new(Vec3::new(0.06, 0.02, 0.02), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let mat = Material::isotropic(4500.0, 0.45, 1060.0, 30.0)
        .unwrap()
        .with_model(MaterialModel::Stvk);
    let model =
        ElasticModel::new(mesh.clone(), TetMaterials::uniform(mat, mesh.tet_count())).unwrap();
    let mut s = Explicit::<f32>::new(model, ExplicitConfig::new(1e-3)).unwrap();
    let before = s.substeps();
    let p = s.model().mesh().positions_m().to_vec();
    for (v, q) in p.iter().enumerate() {
        if q.x < 1e-4 {
            s.fix(VertexId::from(v));
        } else if q.x > 0.0599 {
            s.prescribe(VertexId::from(v), Vec3::new(0.0, 0.0, -0.03));
        }
    }
    for _ in 0..20 {
        s.step();
        let u: Vec<Vec3> = s
            .displacements()
            .iter()
            .map(|d| Vec3::from_array(*d))
            .collect();
        assert!(
            u.iter().all(|d| d.is_finite() && d.length() < 0.08),
            "flung: {:?}",
            u.iter().map(|d| d.length()).fold(0.0, f64::max)
        );
    }
    assert!(s.substeps() > 4 * before, "{} sub-steps", s.substeps());
}
