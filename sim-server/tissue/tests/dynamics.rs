//! Explicit integration laws: the fused kernel equals a plain central
//! difference step, threads do not change the result, one mode oscillates at
//! omega_d = (2/dt) asin(omega dt / 2), the stability bounds bracket the true
//! limit, a step just under it stays bounded for 1e5 steps while one above it
//! is refused or sub-stepped, and cutting never breaks the enforced bound.

use tissue::test_support as common;

use common::*;
use tissue::prelude::*;
use tissue::tensor_mass::{ExplicitError, element_bound, power_iteration};

fn model(cells: [usize; 3], damping: f64) -> ElasticModel {
    let mesh = box_mesh(cells, 0.01, 0.1, 3);
    let n = mesh.tet_count();
    let mat = Material::isotropic(4500.0, 0.45, 1060.0, damping).unwrap();
    let mut mats = TetMaterials::uniform(mat, n);
    let mu = liver_iso().mu_pa();
    let aniso = mats
        .add(
            Material::new(
                *aniso_material(0.5 * mu, 3.0 * mu, Terms::ALL)
                    .unwrap()
                    .elasticity(),
                1060.0,
                damping,
            )
            .unwrap(),
        )
        .unwrap();
    for t in (0..n).step_by(2) {
        mats.assign(TetId::from(t), aniso).unwrap();
        mats.set_fiber(TetId::from(t), Vec3::new(1.0, 0.3, 0.0))
            .unwrap();
    }
    ElasticModel::new(mesh, mats).unwrap()
}

fn config(dt_s: f64, threads: usize) -> ExplicitConfig {
    ExplicitConfig {
        threads,
        ..ExplicitConfig::new(dt_s)
    }
}

/// Largest eigenvalue of M^-1 K by a dense solve (free vertices only).
fn exact_lambda(model: &ElasticModel, free: &[bool]) -> f64 {
    let n = model.vertex_count();
    let k = model.dense_stiffness();
    let idx: Vec<usize> = (0..3 * n).filter(|d| free[d / 3]).collect();
    let m = model.masses_kg();
    let a: Vec<f64> = idx
        .iter()
        .flat_map(|&r| idx.iter().map(move |&c| (r, c)))
        .map(|(r, c)| k[r * 3 * n + c] / (m[r / 3] * m[c / 3]).sqrt())
        .collect();
    *sym_eigenvalues(idx.len(), &a).last().unwrap()
}

#[test]
fn fused_step_equals_a_plain_central_difference() {
    let model = model([4, 3, 3], 30.0);
    let n = model.vertex_count();
    let dt = 0.5 * element_bound(&model).dt_max_s;
    let mut sim = Explicit::<f64>::new(model.clone(), config(dt, 1)).unwrap();
    let mut rng = Rng::new(4);
    let u0: Vec<Vec3> = (0..n).map(|_| rng.vec3() * 1e-4).collect();
    let u1: Vec<Vec3> = u0.iter().map(|u| *u + rng.vec3() * 1e-6).collect();
    sim.set_state(&u1, &u0);
    sim.fix(VertexId(0));
    sim.prescribe(VertexId(5), Vec3::new(1e-4, 0.0, 0.0));
    sim.set_external_force(VertexId(7), Vec3::new(0.0, 0.0, -1e-3));
    sim.step();
    // Reference: (m/dt^2 + c/2dt) U+ = F + 2m/dt^2 U - (m/dt^2 - c/2dt) U-.
    let mut f = vec![Vec3::ZERO; n];
    model.elastic_forces(&u1, &mut f);
    f[7].z -= 1e-3;
    for v in 0..n {
        let (m, c) = (model.masses_kg()[v], model.damping_kg_s()[v]);
        let expect = match v {
            0 => Vec3::ZERO,
            5 => Vec3::new(1e-4, 0.0, 0.0),
            _ => {
                (f[v] + u1[v] * (2.0 * m / (dt * dt)) - u0[v] * (m / (dt * dt) - c / (2.0 * dt)))
                    / (m / (dt * dt) + c / (2.0 * dt))
            }
        };
        let got = sim.displacement(VertexId::from(v));
        assert!(
            (got - expect).length() < 1e-12 * 1e-4,
            "vertex {v}: {got} vs {expect}"
        );
    }
}

#[test]
fn thread_counts_that_would_allocate_without_bound_are_refused() {
    let model = model([3, 2, 2], 10.0);
    let dt = 0.5 * element_bound(&model).dt_max_s;
    // More threads than a step may use: refused before any is started.
    match Explicit::<f64>::new(model.clone(), config(dt, 100_000)) {
        Err(ExplicitError::Threads { threads, reason }) => {
            assert_eq!(threads, 100_000);
            assert!(reason.contains("at most 256"), "{reason}");
        }
        other => panic!("accepted 100000 threads: {:?}", other.map(|s| s.parts())),
    }
    // A large mesh numbered at random: each part's ring is about the
    // vertex count, so a few parts are refused, one is not.
    let mesh = box_mesh([40, 40, 40], 0.001, 0.0, 7);
    let n = mesh.vertex_count();
    let mut order: Vec<u32> = (0..n as u32).collect();
    let mut rng = Rng::new(3);
    for i in (1..n).rev() {
        order.swap(i, (rng.vec3().x.abs() * 1e9) as usize % (i + 1));
    }
    let shuffled = TetMesh::new(
        {
            let mut p = vec![Vec3::ZERO; n];
            for (old, &new) in order.iter().enumerate() {
                p[new as usize] = mesh.positions_m()[old];
            }
            p
        },
        mesh.tets()
            .iter()
            .map(|t| t.map(|v| order[v.idx()]))
            .collect(),
    )
    .unwrap();
    let mat = Material::isotropic(4500.0, 0.45, 1060.0, 5.0).unwrap();
    let big = ElasticModel::new(
        shuffled.clone(),
        TetMaterials::uniform(mat, shuffled.tet_count()),
    )
    .unwrap();
    let dt = 0.5 * element_bound(&big).dt_max_s;
    match Explicit::<f32>::new(big.clone(), config(dt, 32)) {
        Err(ExplicitError::Threads { reason, .. }) => {
            assert!(reason.contains("renumber the mesh"), "{reason}")
        }
        other => panic!(
            "32 parts on a shuffled mesh: {:?}",
            other.map(|s| s.parts())
        ),
    }
    assert_eq!(Explicit::<f32>::new(big, config(dt, 1)).unwrap().parts(), 1);
}

#[test]
fn threads_do_not_change_the_result() {
    // Small meshes make parts shorter than the bandwidth, so spills reach
    // across several parts: the hardest case for the deferred rows.
    for cells in [[3, 2, 2], [8, 4, 4]] {
        let model = model(cells, 10.0);
        let n = model.vertex_count();
        let dt = 0.9 * element_bound(&model).dt_max_s;
        let mut rng = Rng::new(8);
        let u0: Vec<Vec3> = (0..n).map(|_| rng.vec3() * 1e-4).collect();
        let run = |threads: usize| {
            let mut sim = Explicit::<f64>::new(model.clone(), config(dt, threads)).unwrap();
            sim.set_state(&u0, &u0);
            sim.fix(VertexId(0));
            for _ in 0..200 {
                sim.step();
            }
            (sim.parts(), sim.displacements().to_vec())
        };
        let (_, one) = run(1);
        for threads in [2, 3, 4, 7] {
            let (parts, many) = run(threads);
            assert_eq!(parts, threads.min(n));
            for (a, b) in one.iter().zip(&many) {
                for d in 0..3 {
                    assert!(
                        (a[d] - b[d]).abs() < 1e-12 * 1e-4,
                        "{cells:?} {threads} threads: {a:?} vs {b:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn one_mode_oscillates_at_the_discrete_frequency() {
    // One tetrahedron with three vertices fixed: vertex 3 is a 3-DOF spring.
    let p = vec![
        Vec3::ZERO,
        Vec3::new(0.01, 0.0, 0.0),
        Vec3::new(0.0, 0.01, 0.0),
        Vec3::new(0.002, 0.003, 0.01),
    ];
    let mesh = TetMesh::new(p, vec![[0, 1, 2, 3]]).unwrap();
    let model = ElasticModel::new(mesh, TetMaterials::uniform(iso_material(), 1)).unwrap();
    let k = model.vertex_tensors()[3];
    let m = model.masses_kg()[3];
    let eig = nalgebra::Matrix3::from_fn(|r, c| k.col(c)[r]).symmetric_eigen();
    let (i, _) = eig.eigenvalues.argmax();
    let omega = (eig.eigenvalues[i] / m).sqrt();
    let mode = Vec3::new(
        eig.eigenvectors[(0, i)],
        eig.eigenvectors[(1, i)],
        eig.eigenvectors[(2, i)],
    );
    for ratio in [0.2, 0.5, 0.9] {
        let dt = ratio * 2.0 / omega;
        // The bounds ignore the three fixed vertices (fixing only lowers
        // omega_max), so they refuse this dt: the caller vouches for it.
        let cfg = ExplicitConfig {
            policy: DtPolicy::Refuse,
            ..config(dt, 1)
        };
        if ratio > 0.5 {
            assert!(matches!(
                Explicit::<f64>::new(model.clone(), cfg),
                Err(ExplicitError::Unstable { .. })
            ));
        }
        let cfg = ExplicitConfig {
            policy: DtPolicy::Unchecked,
            ..cfg
        };
        let mut sim = Explicit::<f64>::new(model.clone(), cfg).unwrap();
        assert_eq!(sim.substeps(), 1);
        for v in 0..3 {
            sim.fix(VertexId(v));
        }
        let u0 = vec![Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, mode * 1e-4];
        sim.set_state(&u0, &u0);
        // Time the upward zero crossings of the modal coordinate.
        let mut crossings = Vec::new();
        let mut prev = 1e-4;
        for s in 1..200_000 {
            sim.step();
            let q = sim.displacement(VertexId(3)).dot(mode);
            if prev < 0.0 && q >= 0.0 {
                crossings.push((s - 1) as f64 + prev / (prev - q));
            }
            prev = q;
            if crossings.len() == 60 {
                break;
            }
        }
        let period_steps = (crossings[59] - crossings[0]) / 59.0;
        let omega_d = 2.0 * std::f64::consts::PI / (period_steps * dt);
        let expect = (2.0 / dt) * (omega * dt / 2.0).asin();
        // Linear interpolation of crossings limits accuracy at coarse dt.
        let tol = if ratio > 0.5 { 2e-3 } else { 2e-4 };
        assert!(
            (omega_d / expect - 1.0).abs() < tol,
            "dt ratio {ratio}: omega_d {omega_d} vs {expect} (omega {omega})"
        );
        if ratio >= 0.5 {
            assert!(
                (omega_d / omega - 1.0).abs() > 5.0 * tol,
                "the test must tell omega_d from omega"
            );
        }
    }
}

#[test]
fn bounds_bracket_the_true_limit_and_just_under_it_is_stable() {
    let model = model([2, 2, 2], 0.0);
    let n = model.vertex_count();
    let p = model.mesh().positions_m().to_vec();
    let fixed: Vec<bool> = p.iter().map(|x| x.z < 1e-9).collect();
    let free: Vec<bool> = fixed.iter().map(|f| !f).collect();
    let lambda_free = exact_lambda(&model, &free);
    let lambda_all = exact_lambda(&model, &vec![true; n]);
    let element = element_bound(&model);
    let power = power_iteration(&model, 1e-10, 20_000);
    assert!(
        element.omega_max_rad_s.powi(2) >= lambda_all * (1.0 - 1e-12),
        "Irons' bound must hold"
    );
    assert!(power.lambda <= lambda_all * (1.0 + 1e-9));
    assert!(
        (power.lambda / lambda_all - 1.0).abs() < 1e-3,
        "power iteration {} vs {lambda_all}",
        power.lambda
    );
    assert!(power.lambda_upper >= lambda_all * (1.0 - 1e-9));
    let ratio = element.omega_max_rad_s / lambda_all.sqrt();
    assert!(
        ratio < 3.0,
        "element bound is {ratio}x omega_max: too pessimistic to be useful"
    );

    let run = |dt: f64| {
        let cfg = ExplicitConfig {
            policy: DtPolicy::Substep,
            bound: BoundMethod::PowerIteration,
            ..config(dt, 1)
        };
        let mut sim = Explicit::<f64>::new(model.clone(), cfg).unwrap();
        let mut rng = Rng::new(2);
        let u0: Vec<Vec3> = (0..n)
            .map(|v| {
                if fixed[v] {
                    Vec3::ZERO
                } else {
                    rng.vec3() * 1e-4
                }
            })
            .collect();
        sim.set_state(&u0, &u0);
        for (v, f) in fixed.iter().enumerate() {
            if *f {
                sim.fix(VertexId::from(v));
            }
        }
        let e0 = sim.model().energy_j(&u0);
        let mut emax: f64 = 0.0;
        for s in 0..100_000 {
            sim.step();
            if s % 100 == 0 {
                let u: Vec<Vec3> = sim
                    .displacements()
                    .iter()
                    .map(|a| Vec3::from_array(*a))
                    .collect();
                emax = emax.max(sim.model().energy_j(&u));
                if !emax.is_finite() || emax > 1e6 * e0 {
                    break;
                }
            }
        }
        emax / e0
    };
    let dt_true = 2.0 / lambda_free.sqrt();
    let under = run(0.99 * dt_true);
    assert!(under < 10.0, "0.99 x the limit grew the energy {under}x");
    // Substepping is off for this check only because the power-iteration
    // bound (of the unconstrained body) is below the constrained limit.
    let mut cfg = ExplicitConfig {
        policy: DtPolicy::Refuse,
        bound: BoundMethod::PowerIteration,
        ..config(1.01 * dt_true, 1)
    };
    let refused = Explicit::<f64>::new(model.clone(), cfg)
        .err()
        .expect("above the bound must be refused");
    assert!(matches!(refused, ExplicitError::Unstable { .. }));
    assert!(refused.to_string().contains("stable step"), "{refused}");
    cfg.policy = DtPolicy::Substep;
    let sim = Explicit::<f64>::new(model.clone(), cfg).unwrap();
    assert!(
        sim.substeps() >= 2,
        "sub-stepping must split a step above the bound"
    );
    assert!(
        run(1.01 * dt_true) < 10.0,
        "sub-stepped run must stay bounded"
    );
    // Without the guard, a step 1% above the true limit diverges: the bound is sharp.
    let unguarded = {
        let mut u = vec![Vec3::ZERO; n];
        let mut prev = u.clone();
        let mut rng = Rng::new(2);
        for v in 0..n {
            if !fixed[v] {
                u[v] = rng.vec3() * 1e-4;
                prev[v] = u[v];
            }
        }
        let dt = 1.01 * dt_true;
        let mut f = vec![Vec3::ZERO; n];
        let m = model.masses_kg();
        for _ in 0..20_000 {
            model.elastic_forces(&u, &mut f);
            for v in 0..n {
                if !fixed[v] {
                    let next = f[v] * (dt * dt / m[v]) + u[v] * 2.0 - prev[v];
                    prev[v] = u[v];
                    u[v] = next;
                }
            }
        }
        u.iter().any(|x| !x.is_finite() || x.length() > 1.0)
    };
    assert!(unguarded, "1.01 x the limit should diverge");
}

#[test]
fn cutting_never_breaks_the_element_bound() {
    let model = model([5, 3, 3], 0.0);
    let n = model.vertex_count();
    let dt = 0.99 * element_bound(&model).dt_max_s;
    let mut sim = Explicit::<f32>::new(model, config(dt, 2)).unwrap();
    assert_eq!(sim.substeps(), 1);
    let mut rng = Rng::new(12);
    let u0: Vec<Vec3> = (0..n).map(|_| rng.vec3() * 1e-4).collect();
    sim.set_state(&u0, &u0);
    let e0 = sim.energy_j();
    let tets = sim.model().mesh().tet_count();
    // Remove 90% of the tetrahedra, leaving small, lightly held pieces.
    let mut order: Vec<usize> = (0..tets).collect();
    for i in (1..tets).rev() {
        order.swap(i, ((rng.next() + 0.5) * (i + 1) as f64) as usize % (i + 1));
    }
    for (k, t) in order.iter().take(tets * 9 / 10).enumerate() {
        sim.remove_tet(TetId::from(*t)).unwrap();
        if k % 10 == 0 {
            for _ in 0..50 {
                sim.step();
            }
        }
    }
    for _ in 0..20_000 {
        sim.step();
    }
    // Undamped: cutting only removes elastic energy and mass, so the total
    // must stay near its start (detached pieces may drift, which is fine);
    // an instability grows it exponentially.
    let e = sim.energy_j();
    assert!(
        e.is_finite() && e < 2.0 * e0,
        "unstable after cutting: energy {e} from {e0}"
    );
}

#[test]
fn damping_dissipates_energy() {
    let model = model([3, 2, 2], 5.0);
    let n = model.vertex_count();
    let dt = 0.5 * element_bound(&model).dt_max_s;
    let mut sim = Explicit::<f64>::new(model, config(dt, 1)).unwrap();
    let mut rng = Rng::new(6);
    let u0: Vec<Vec3> = (0..n).map(|_| rng.vec3() * 1e-4).collect();
    sim.set_state(&u0, &u0);
    let e0 = sim.energy_j();
    let mut last = e0;
    for _ in 0..10 {
        for _ in 0..100 {
            sim.step();
        }
        let e = sim.energy_j();
        assert!(e < last, "energy rose from {last} to {e}");
        last = e;
    }
    assert!(
        last < 0.9 * e0,
        "damping removed too little: {last} of {e0}"
    );
    assert!(sim.displacements().iter().flatten().all(|x| x.is_finite()));
}

#[test]
fn bad_dt_is_refused() {
    let m = model([2, 2, 2], 0.0);
    for dt in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            Explicit::<f32>::new(m.clone(), config(dt, 1)),
            Err(ExplicitError::BadDt(_))
        ));
    }
}

/// The step's worker threads are reachable (for the run loop to give them
/// its real-time priority: a step waits for them): each of a two-thread
/// integrator's pool runs the callback once, on its own named thread; a
/// one-thread integrator steps on the caller's and has none.
#[test]
fn the_step_workers_are_each_reached_once() {
    use tissue::backend::Backend;
    let names = std::sync::Mutex::new(Vec::new());
    let record = || {
        let name = std::thread::current().name().unwrap_or("").to_string();
        names.lock().unwrap().push(name);
    };
    let two = Explicit::<f32>::new(model([4, 2, 2], 0.0), config(1e-5, 2)).unwrap();
    assert_eq!(Backend::on_step_workers(&two, &record), 2);
    let mut seen = names.lock().unwrap().clone();
    seen.sort();
    assert_eq!(seen, ["tensor-mass-0", "tensor-mass-1"]);
    let one = Explicit::<f32>::new(model([4, 2, 2], 0.0), config(1e-5, 1)).unwrap();
    assert_eq!(Backend::on_step_workers(&one, &record), 0);
    assert_eq!(names.lock().unwrap().len(), 2);
}

/// A sliver sets the explicit step: moving the centre vertex of a 2 x 2 x 2
/// box of cubes 85% of the way to a face flattens the tetrahedra between
/// them, and `step_outliers` names exactly tetrahedra that use it, shortest
/// first, each below a quarter of the median element's step, the shortest
/// being the whole model's bound; the regular box has none.
#[test]
fn step_outliers_name_the_slivers_that_set_the_step() {
    use tissue::tensor_mass::step_outliers;
    let regular = BoxSpec::new(Vec3::splat(0.02), CellSize::EdgeM(0.01))
        .generate()
        .unwrap();
    let model_of = |mesh: TetMesh| {
        let n = mesh.tet_count();
        ElasticModel::new(mesh, TetMaterials::uniform(iso_material(), n)).unwrap()
    };
    assert_eq!(step_outliers(&model_of(regular.clone()), 4.0, 5), None);
    let centre = (regular.positions_m().iter())
        .position(|p| p.distance(Vec3::splat(0.01)) < 1e-9)
        .expect("a centre vertex");
    let mut positions = regular.positions_m().to_vec();
    positions[centre].x += 0.0085;
    let tets = regular.tets().iter().map(|t| t.map(|v| v.0)).collect();
    let model = model_of(TetMesh::new(positions, tets).unwrap());
    let o = step_outliers(&model, 4.0, 5).expect("slivers");
    assert!(o.count > 0 && o.shortest.len() == o.count.min(5), "{o:?}");
    for w in o.shortest.windows(2) {
        assert!(w[0].1 <= w[1].1, "shortest first: {o:?}");
    }
    for (t, dt) in &o.shortest {
        let uses = model.mesh().tets()[t.idx()]
            .iter()
            .any(|v| v.idx() == centre);
        assert!(
            uses && 4.0 * dt < o.median_dt_s,
            "tetrahedron {t:?}: {dt} s, {o:?}"
        );
    }
    let bound = element_bound(&model).dt_max_s;
    assert!(
        (o.shortest[0].1 - bound).abs() <= 1e-12 * bound,
        "{bound} vs {o:?}"
    );
}
