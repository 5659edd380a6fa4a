//! One conformance suite for every backend, generated per backend (a module
//! each, one test per law, so one backend's failure hides no other's):
//! static equilibrium agrees with the static solver, energy decays with
//! damping once the load is gone, and a tool pressing the same depth feels
//! the same reaction as on the explicit backend. The implicit backend runs
//! at ten times the explicit stability bound; the precomputed one is static
//! (responses to unit forces on the surface); the hybrid runs twice, the
//! probe once on its tensor-mass part and once on its precomputed part.

mod common;

use sim_server::backend::{Backend, Hybrid, HybridConfig, Implicit, ImplicitConfig, Precomputed};
use sim_server::contact::{ToolInput, Tools};
use sim_server::prelude::*;
use sim_server::scene::ToolDecl;
use sim_server::scene::spec::ToolKind;

const SIZE: [f64; 3] = common::BLOCK_M;

fn model() -> ElasticModel {
    common::block(0.005)
}

fn wall(model: &ElasticModel) -> Vec<VertexId> {
    let p = model.mesh().positions_m();
    (0..p.len())
        .filter(|&v| p[v].x < 1e-9)
        .map(VertexId::from)
        .collect()
}

fn free_end(model: &ElasticModel) -> Vec<VertexId> {
    let p = model.mesh().positions_m();
    (0..p.len())
        .filter(|&v| p[v].x > SIZE[0] - 1e-9)
        .map(VertexId::from)
        .collect()
}

/// The backends under test.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Explicit,
    Implicit,
    Precomputed,
    /// Hybrid with the probe on the tensor-mass part (x > 2 cm).
    HybridProbeOnTensorMass,
    /// Hybrid with the probe on the precomputed part (tensor-mass at the
    /// free end only).
    HybridProbeOnPrecomputed,
}

/// A backend of `kind` on a fresh model, with its step.
fn backend(kind: Kind) -> Box<dyn Backend> {
    let m = model();
    let bound = element_bound_of(&m);
    let fixed = wall(&m);
    match kind {
        Kind::Explicit => {
            Box::new(Explicit::<f64>::new(m, ExplicitConfig::new(0.9 * bound)).unwrap())
        }
        Kind::Implicit => Box::new(Implicit::new(m, ImplicitConfig::new(10.0 * bound)).unwrap()),
        Kind::Precomputed => {
            Box::new(Precomputed::new(m, &fixed, 10.0 * bound, None, |_, _| {}).unwrap())
        }
        Kind::HybridProbeOnTensorMass => Box::new(hybrid(&m, &fixed, |x| x > 0.02, 10.0 * bound)),
        Kind::HybridProbeOnPrecomputed => Box::new(hybrid(&m, &fixed, |x| x > 0.032, 10.0 * bound)),
    }
}

/// The laws, one test per backend and law.
macro_rules! conformance {
    ($($name:ident => $kind:expr),* $(,)?) => {$(
        mod $name {
            #[test]
            fn static_equilibrium_agrees_with_the_static_solver() {
                super::static_equilibrium_agrees_with_the_static_solver($kind);
            }
            #[test]
            fn energy_decays_with_damping_once_the_load_is_gone() {
                super::energy_decays_with_damping_once_the_load_is_gone($kind);
            }
            #[test]
            fn a_tool_pressing_the_same_depth_feels_the_same_reaction() {
                super::a_tool_pressing_the_same_depth_feels_the_same_reaction($kind);
            }
        }
    )*};
}

conformance! {
    explicit => super::Kind::Explicit,
    implicit => super::Kind::Implicit,
    precomputed => super::Kind::Precomputed,
    hybrid_probe_on_tensor_mass => super::Kind::HybridProbeOnTensorMass,
    hybrid_probe_on_precomputed => super::Kind::HybridProbeOnPrecomputed,
}

fn hybrid(m: &ElasticModel, fixed: &[VertexId], cuttable: impl Fn(f64) -> bool, dt: f64) -> Hybrid {
    let tets: Vec<TetId> = (0..m.mesh().tet_count())
        .map(TetId::from)
        .filter(|t| {
            let p = m.mesh().tet_points(*t);
            cuttable((p[0].x + p[1].x + p[2].x + p[3].x) / 4.0)
        })
        .collect();
    Hybrid::new(m.clone(), fixed, &tets, HybridConfig::new(dt), |_, _| {}).unwrap()
}

fn element_bound_of(m: &ElasticModel) -> f64 {
    sim_server::tensor_mass::element_bound(m).dt_max_s
}

fn run_for(sim: &mut dyn Backend, seconds: f64) {
    let steps = (seconds / sim.dt_s()).ceil() as usize;
    for _ in 0..steps {
        sim.step();
    }
}

fn static_equilibrium_agrees_with_the_static_solver(kind: Kind) {
    let m = model();
    let n = m.vertex_count();
    let mut bc = Dirichlet::new(n);
    let mut loads = vec![Vec3::ZERO; n];
    let end = free_end(&m);
    for v in wall(&m) {
        bc.fix(v);
    }
    for v in &end {
        loads[v.idx()] = Vec3::new(0.0, 0.0, -0.02 / end.len() as f64);
    }
    let reference = solve_static(&m, &bc, &loads).unwrap().displacement_m;
    let scale = reference.iter().map(|u| u.length()).fold(0.0, f64::max);
    assert!(scale > 1e-4, "the load bends the block ({scale} m)");
    let mut sim = backend(kind);
    for v in wall(sim.model()) {
        sim.fix(v);
    }
    for v in &end {
        sim.set_external_force(*v, loads[v.idx()]);
    }
    run_for(sim.as_mut(), 3.0);
    let err = (0..n)
        .map(|v| (sim.displacement(VertexId::from(v)) - reference[v]).length())
        .fold(0.0, f64::max);
    assert!(
        err < 1e-3 * scale,
        "{}: {err} m from the static solution (scale {scale} m)",
        sim.capabilities().name
    );
}

fn energy_decays_with_damping_once_the_load_is_gone(kind: Kind) {
    let mut sim = backend(kind);
    let end = free_end(sim.model());
    for v in wall(sim.model()) {
        sim.fix(v);
    }
    for v in &end {
        sim.set_external_force(*v, Vec3::new(0.0, 0.0, -0.004));
    }
    run_for(sim.as_mut(), 0.3);
    for v in &end {
        sim.set_external_force(*v, Vec3::ZERO);
    }
    let mut energies = Vec::new();
    for _ in 0..10 {
        run_for(sim.as_mut(), 0.05);
        energies.push(energy(sim.as_ref()));
    }
    assert!(energies.iter().all(|e| e.is_finite()));
    // (A static backend is at rest at once: both are zero.)
    assert!(
        energies[9] <= 0.05 * energies[0],
        "{}: energy {:e} J -> {:e} J",
        sim.capabilities().name,
        energies[0],
        energies[9]
    );
}

/// Elastic energy 1/2 u.K u (kinetic left out: backends keep velocity
/// differently; the elastic part must vanish as the body comes to rest).
fn energy(sim: &dyn Backend) -> f64 {
    let u: Vec<Vec3> = sim
        .displacements()
        .iter()
        .map(|a| Vec3::from_array(*a))
        .collect();
    let mut f = vec![Vec3::ZERO; u.len()];
    sim.model().elastic_forces(&u, &mut f);
    u.iter().zip(&f).map(|(u, f)| -0.5 * u.dot(*f)).sum()
}

/// The force on a probe pressed 3 mm into the top face of `kind`'s block
/// and held.
fn pressed_reaction(kind: Kind) -> (String, Vec3) {
    let decl = ToolDecl {
        name: "probe".into(),
        kind: ToolKind::Hook,
        fulcrum_m: [0.025, 0.01, 0.12],
        length_m: 0.3,
        radius_m: 0.004,
        tip_length_m: 0.01,
        friction: Default::default(),
    };
    let mut sim = backend(kind);
    let mut tools = Tools::new(std::slice::from_ref(&decl), sim.model());
    for v in wall(sim.model()) {
        sim.fix(v);
        tools.reserve(v);
    }
    // Down to 3 mm into the top face over 0.2 s, then hold 1.5 s.
    let (dt, top) = (sim.dt_s(), SIZE[2] + decl.radius_m);
    let steps = (1.7 / dt).ceil() as usize;
    for k in 0..steps {
        let depth = 0.003 * ((k as f64 * dt) / 0.2).min(1.0);
        let input = ToolInput {
            tip_m: Vec3::new(0.025, 0.01, top - depth),
            jaw_opening: 1.0,
        };
        tools.update(sim.as_mut(), &[Some(input)]);
        sim.step();
    }
    let f = tools.reaction(0, sim.as_ref()).force_n;
    assert!(f.z > 0.01, "{}: {f}", sim.capabilities().name);
    (sim.capabilities().name.to_string(), f)
}

/// The explicit backend's pressed reaction, the reference every backend's
/// test compares with (computed once per test process).
fn explicit_reaction() -> Vec3 {
    static REFERENCE: std::sync::OnceLock<Vec3> = std::sync::OnceLock::new();
    *REFERENCE.get_or_init(|| pressed_reaction(Kind::Explicit).1)
}

fn a_tool_pressing_the_same_depth_feels_the_same_reaction(kind: Kind) {
    let (name, b) = pressed_reaction(kind);
    let a = explicit_reaction();
    assert!(
        (a - b).length() < 0.05 * a.length(),
        "explicit {a} N vs {name} ({kind:?}) {b} N"
    );
}

/// A body held nowhere has no static response: the precomputed backend
/// is refused at start (it accepted one, and a tool then passed through
/// it with zero force).
#[test]
fn the_precomputed_backend_refuses_a_body_held_nowhere() {
    let err = Precomputed::new(model(), &[], 0.01, None, |_, _| {})
        .err()
        .expect("refused");
    assert!(err.to_string().contains("rigid motion"), "{err}");
}

#[test]
fn a_mesh_too_large_for_precomputed_responses_is_refused_before_any_solve() {
    // A 40 mm cube on 1.2 mm cells: ~37k vertices, ~6.5k on the surface;
    // 3 x 6.5k responses of 37k vertices would take about 17 GiB.
    let mesh = BoxSpec::new(Vec3::splat(0.04), CellSize::EdgeM(0.0012))
        .generate()
        .unwrap();
    let mat = Material::isotropic(4500.0, 0.45, 1060.0, 5.0).unwrap();
    let m = ElasticModel::new(mesh.clone(), TetMaterials::uniform(mat, mesh.tet_count())).unwrap();
    let fixed = wall(&m);
    let mut solves = 0;
    let err = Precomputed::new(m.clone(), &fixed, 0.01, None, |_, _| solves += 1)
        .err()
        .expect("refused");
    let msg = err.to_string();
    assert!(
        msg.contains("GiB, more than the 8 GiB a backend keeps") && solves == 0,
        "{msg} ({solves} solves)"
    );
    // The hybrid's precomputed part is refused the same way.
    let cuttable: Vec<TetId> = (0..mesh.tet_count())
        .map(TetId::from)
        .filter(|t| mesh.tet_points(*t)[0].x > 0.036)
        .collect();
    let err = Hybrid::new(m, &fixed, &cuttable, HybridConfig::new(0.001), |_, _| {})
        .err()
        .expect("refused");
    assert!(err.to_string().starts_with("precomputed part: "), "{err}");
}

#[test]
fn precomputed_responses_are_cached_and_cutting_is_refused() {
    let m = model();
    let fixed = wall(&m);
    let dir = std::env::temp_dir().join(format!("hapsim-precomputed-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut solves = 0;
    let first = Precomputed::new(m.clone(), &fixed, 0.01, Some(&dir), |_, _| solves += 1).unwrap();
    assert!(!first.from_cache && solves == 3 * first.surface_len());
    let mut again = 0;
    let mut second = Precomputed::new(m, &fixed, 0.01, Some(&dir), |_, _| again += 1).unwrap();
    assert!(
        second.from_cache && again == 0,
        "the second start reads the cache"
    );
    // Same responses: the same load gives the same displacements.
    let mut first = first;
    for sim in [&mut first, &mut second] {
        sim.set_external_force(free_end(sim.model())[0], Vec3::new(0.0, 0.0, -0.01));
        sim.step();
    }
    assert_eq!(first.displacements(), second.displacements());
    assert!(!second.can_cut(TetId(0)) && !second.capabilities().dynamic);
    let err = second.remove_tet(TetId(0)).unwrap_err().to_string();
    assert!(
        err.contains("precomputed") && err.contains("cannot cut"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Holds that begin, move and end: each static backend settles on the
/// static solution with the same vertices imposed, at every stage (the
/// precomputed backends refactorise their hold system only when the set
/// changes, so a moved hold must reuse it and a new or released one must not).
#[test]
fn precomputed_holds_that_begin_move_and_end_match_the_static_solver() {
    holds_that_begin_move_and_end_match_the_static_solver(Kind::Precomputed);
}

#[test]
fn hybrid_holds_that_begin_move_and_end_match_the_static_solver() {
    holds_that_begin_move_and_end_match_the_static_solver(Kind::HybridProbeOnTensorMass);
}

fn holds_that_begin_move_and_end_match_the_static_solver(kind: Kind) {
    let m = model();
    let n = m.vertex_count();
    let p = m.mesh().positions_m();
    let at = |x: f64| {
        VertexId::from(
            (0..n)
                .find(|&v| (p[v] - Vec3::new(x, 0.01, SIZE[2])).length() < 1e-9)
                .expect("a top-face vertex there"),
        )
    };
    let (a, b) = (at(0.015), at(0.01));
    type Stage = Vec<(VertexId, Vec3)>;
    let stages: [Stage; 3] = [
        vec![(a, Vec3::new(0.0, 0.0, -1e-3))],
        vec![
            (a, Vec3::new(5e-4, 0.0, -2e-3)),
            (b, Vec3::new(0.0, 0.0, -1e-3)),
        ],
        vec![(b, Vec3::new(0.0, 3e-4, -1e-3))],
    ];
    let fixed = wall(&m);
    let mut sim = backend(kind);
    for &v in &fixed {
        sim.fix(v);
    }
    let mut held: Vec<VertexId> = Vec::new();
    for stage in &stages {
        for v in held.drain(..) {
            if !stage.iter().any(|(w, _)| *w == v) {
                sim.release(v);
            }
        }
        let mut bc = Dirichlet::new(n);
        for &v in &fixed {
            bc.fix(v);
        }
        for &(v, d) in stage {
            sim.prescribe(v, d);
            bc.prescribe(v, d);
            held.push(v);
        }
        let reference = solve_static(&m, &bc, &vec![Vec3::ZERO; n])
            .unwrap()
            .displacement_m;
        let scale = reference.iter().map(|u| u.length()).fold(0.0, f64::max);
        let settle_s = if sim.capabilities().dynamic { 3.0 } else { 0.0 };
        run_for(sim.as_mut(), settle_s);
        sim.step();
        let err = (0..n)
            .map(|v| (sim.displacement(VertexId::from(v)) - reference[v]).length())
            .fold(0.0, f64::max);
        assert!(
            err < 1e-3 * scale,
            "{} at stage {stage:?}: {err} m from the static solution (scale {scale} m)",
            sim.capabilities().name
        );
    }
}
