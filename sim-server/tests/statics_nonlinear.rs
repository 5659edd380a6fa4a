//! The nonlinear static solver: equal to the linear solver on a linear
//! model, equal to the explicit dynamics settled under damping for StVK and
//! corotational bodies stretched by 40%, in equilibrium with its supports,
//! and different from the linear answer where the deformation is large.

mod common;

use sim_server::material::MaterialModel;
use sim_server::prelude::*;
use sim_server::static_newton::{NewtonConfig, solve_static_nonlinear};
use sim_server::tensor_mass::element_bound;

const LENGTH_M: f64 = 0.02;

fn model_with(model: MaterialModel, damping_per_s: f64) -> ElasticModel {
    let mesh = common::box_mesh([4, 2, 2], 0.005, 0.15, 11);
    let base = common::aniso_material(2000.0, 1500.0, Terms::ALL).unwrap();
    let mat = Material::new(*base.elasticity(), 1060.0, damping_per_s)
        .unwrap()
        .with_model(model);
    let mut mats = TetMaterials::uniform(mat, mesh.tet_count());
    for t in 0..mesh.tet_count() {
        mats.set_fiber(TetId::from(t), Vec3::new(1.0, 0.5, 0.2))
            .unwrap();
    }
    ElasticModel::new(mesh, mats).unwrap()
}

/// Clamped at x = 0, the far end pulled along x by `pull_m` and down by a
/// fifth of it.
fn supports(model: &ElasticModel, pull_m: f64) -> (Dirichlet, Vec<(VertexId, Vec3)>) {
    let mut bc = Dirichlet::new(model.vertex_count());
    let mut held = Vec::new();
    for (v, p) in model.mesh().positions_m().iter().enumerate() {
        let v = VertexId::from(v);
        if p.x < 1e-9 {
            bc.fix(v);
            held.push((v, Vec3::ZERO));
        } else if p.x > LENGTH_M - 1e-9 {
            let d = Vec3::new(pull_m, 0.0, -0.2 * pull_m);
            bc.prescribe(v, d);
            held.push((v, d));
        }
    }
    (bc, held)
}

fn max_diff(a: &[Vec3], b: &[Vec3]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).length())
        .fold(0.0, f64::max)
}

#[test]
fn on_a_linear_model_newton_gives_the_linear_solution() {
    let model = model_with(MaterialModel::Linear, 0.0);
    let (bc, _) = supports(&model, 0.002);
    let mut loads = vec![Vec3::ZERO; model.vertex_count()];
    loads[20] = Vec3::new(0.0, 0.003, 0.0);
    let linear = solve_static(&model, &bc, &loads).unwrap();
    let newton = solve_static_nonlinear(&model, &bc, &loads, NewtonConfig::default()).unwrap();
    let scale = linear
        .displacement_m
        .iter()
        .map(|u| u.length())
        .fold(0.0, f64::max);
    assert!(max_diff(&linear.displacement_m, &newton.solution.displacement_m) < 1e-9 * scale);
    assert!(max_diff(&linear.force_n, &newton.solution.force_n) < 1e-8);
}

#[test]
fn newton_equals_the_settled_dynamics_and_balances_its_supports() {
    for model_kind in [MaterialModel::Stvk, MaterialModel::Corotational] {
        let pull = 0.4 * LENGTH_M;
        let model = model_with(model_kind, 200.0);
        let (bc, held) = supports(&model, pull);
        let loads = vec![Vec3::ZERO; model.vertex_count()];
        let newton = solve_static_nonlinear(&model, &bc, &loads, NewtonConfig::default())
            .unwrap_or_else(|e| panic!("{model_kind:?}: {e}"));
        let u = &newton.solution.displacement_m;
        // Equilibrium: the supports' forces add up to zero (no load).
        let total = newton
            .solution
            .force_n
            .iter()
            .fold(Vec3::ZERO, |a, f| a + *f);
        let pull_force = held
            .iter()
            .filter(|(_, d)| *d != Vec3::ZERO)
            .map(|(v, _)| newton.solution.force_n[v.idx()].x)
            .sum::<f64>();
        assert!(pull_force > 0.0, "{model_kind:?}: the end is pulled");
        assert!(
            total.length() < 1e-8 * pull_force,
            "{model_kind:?}: {total}"
        );
        // The same body settled by the explicit dynamics under damping.
        let bound = element_bound(&model).dt_max_s;
        let mut sim =
            Explicit::<f64>::new(model.clone(), ExplicitConfig::new(0.9 * bound)).unwrap();
        for (v, d) in &held {
            sim.prescribe(*v, *d);
        }
        let steps = (0.6 / (0.9 * bound)) as usize;
        for _ in 0..steps {
            sim.step();
        }
        let dynamic: Vec<Vec3> = sim
            .displacements()
            .iter()
            .map(|d| Vec3::from_array(*d))
            .collect();
        let diff = max_diff(u, &dynamic);
        assert!(
            diff < 1e-6 * pull,
            "{model_kind:?}: static and settled dynamics differ by {diff} m ({} Newton iterations)",
            newton.iterations
        );
        // And the linear model gives another answer at this stretch.
        let linear = solve_static(&model_with(MaterialModel::Linear, 0.0), &bc, &loads).unwrap();
        let gap = max_diff(u, &linear.displacement_m);
        assert!(
            gap > 1e-2 * pull,
            "{model_kind:?}: only {gap} m from the linear answer"
        );
    }
}

/// A 6 x 2 x 2 cm beam clamped at x = 0 whose far end is turned by
/// `angle_deg` about the beam's axis (a `rotate` load).
fn twisted_beam(model: &str, angle_deg: f64) -> sim_server::scene::BuiltScene {
    let text = format!(
        r#"
[mesh]
generate = {{ shape = "box", size_m = [0.06, 0.02, 0.02], cell_m = 0.005 }}

[material]
young_pa = 4500.0
poisson = 0.45
density_kg_m3 = 1060.0
model = "{model}"

[[fixed]]
select = {{ box_m = [[-1.0, -1.0, -1.0], [0.0001, 1.0, 1.0]] }}

[[load]]
select = {{ box_m = [[0.0599, -1.0, -1.0], [1.0, 1.0, 1.0]] }}
rotate = {{ axis = [1.0, 0.0, 0.0], origin_m = [0.0, 0.01, 0.01], angle_deg = {angle_deg} }}
"#
    );
    let src = sim_server::scene::SceneSource {
        name: "twist.toml".into(),
        dir: ".".into(),
        text,
    };
    let spec = src.parse().unwrap();
    sim_server::scene::build_scene(&src, &spec).unwrap()
}

#[test]
fn a_twisted_beam_is_held_by_a_moment_that_balances_the_clamp() {
    // The far end turned 60 degrees about the beam's axis: the rotate load
    // moves it rigidly, Newton converges for both nonlinear models, the
    // supports balance (forces and moments), and the turned end is held by
    // a moment about +x in the sense of the turn.
    for model in ["stvk", "corotational"] {
        let scene = twisted_beam(model, 60.0);
        let m = &scene.model;
        let mut bc = Dirichlet::new(m.vertex_count());
        for v in &scene.fixed {
            bc.fix(*v);
        }
        for (v, d) in &scene.prescribed {
            bc.prescribe(*v, *d);
        }
        let p = m.mesh().positions_m();
        let r = |x: Vec3| ((x.y - 0.01).powi(2) + (x.z - 0.01).powi(2)).sqrt();
        for (v, d) in &scene.prescribed {
            let q = p[v.idx()] + *d;
            assert!((q.x - p[v.idx()].x).abs() < 1e-15);
            assert!((r(q) - r(p[v.idx()])).abs() < 1e-12);
        }
        let loads = vec![Vec3::ZERO; m.vertex_count()];
        let sol = solve_static_nonlinear(m, &bc, &loads, NewtonConfig::default())
            .unwrap_or_else(|e| panic!("{model}: {e}"))
            .solution;
        let axis = Vec3::new(0.0, 0.01, 0.01);
        let moment = |vs: &mut dyn Iterator<Item = VertexId>| {
            vs.map(|v| {
                let at = p[v.idx()] + sol.displacement_m[v.idx()] - axis;
                (at.cross(sol.force_n[v.idx()]), sol.force_n[v.idx()])
            })
            .fold((Vec3::ZERO, Vec3::ZERO), |a, b| (a.0 + b.0, a.1 + b.1))
        };
        let (turned_m, turned_f) = moment(&mut scene.prescribed.iter().map(|(v, _)| *v));
        let (clamp_m, clamp_f) = moment(&mut scene.fixed.iter().copied());
        assert!(turned_m.x > 0.0, "{model}: moment {turned_m}");
        assert!(
            (turned_f + clamp_f).length() < 1e-8 * turned_f.length().max(1e-6),
            "{model}"
        );
        assert!(
            (turned_m + clamp_m).length() < 1e-8 * turned_m.length(),
            "{model}: {turned_m} vs {clamp_m}"
        );
    }
}
