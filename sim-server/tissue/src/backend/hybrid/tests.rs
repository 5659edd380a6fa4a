use super::static_part::StaticPart;
use super::*;
use crate::material::Material;
use crate::material_map::TetMaterials;
use crate::mesh::{BoxSpec, CellSize};
use crate::static_solve::{Dirichlet, solve_static};

const SIZE: [Real; 3] = [0.04, 0.02, 0.02];

fn body(membrane: bool) -> ElasticModel {
    let mesh = BoxSpec::new(Vec3::from_array(SIZE), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let tissue = Material::isotropic(5000.0, 0.45, 1000.0, 40.0).unwrap();
    let n = mesh.tet_count();
    let m = ElasticModel::new(mesh, TetMaterials::uniform(tissue, n)).unwrap();
    if membrane {
        m.with_membrane(400.0, MembraneModel::Linear).unwrap()
    } else {
        m
    }
}

fn select(m: &ElasticModel, keep: impl Fn(Vec3) -> bool) -> Vec<TetId> {
    (0..m.mesh().tet_count())
        .map(TetId::from)
        .filter(|t| {
            let p = m.mesh().tet_points(*t);
            keep((p[0] + p[1] + p[2] + p[3]) / 4.0)
        })
        .collect()
}

fn vertices(m: &ElasticModel, keep: impl Fn(Vec3) -> bool) -> Vec<VertexId> {
    let p = m.mesh().positions_m();
    (0..p.len())
        .filter(|&v| keep(p[v]))
        .map(VertexId::from)
        .collect()
}

/// The condensation is exact: for any shared displacements, loads and a
/// tool hold, the part's displacements are in equilibrium at its free
/// vertices, the held vertex is where the tool put it, and the force on
/// each shared vertex is the part's elastic force there (to the single
/// precision the lifting is stored in for placing vertices).
#[test]
fn the_precomputed_part_is_condensed_exactly_on_the_shared_vertices() {
    let m = body(true);
    let part_tets = select(&m, |c| c.x < 0.025);
    let part = m.submodel(&part_tets, None).unwrap();
    let pm = &part.model;
    let pos = pm.mesh().positions_m();
    let fixed: Vec<VertexId> = (0..pos.len())
        .filter(|&v| pos[v].x < 1e-9)
        .map(VertexId::from)
        .collect();
    let tm = m.submodel(&select(&m, |c| c.x >= 0.025), None).unwrap();
    let shared: Vec<VertexId> = part
        .vertices
        .iter()
        .enumerate()
        .filter(|(_, g)| tm.vertices.contains(g))
        .map(|(l, _)| VertexId::from(l))
        .collect();
    assert!(shared.len() > 5);
    let mut sp = StaticPart::new(pm, &fixed, &shared, None, |_, _| {}).unwrap();
    let u_shared: Vec<Vec3> = (0..shared.len())
        .map(|i| {
            let x = i as Real;
            Vec3::new((x * 0.7).sin(), (x * 1.3).cos(), (x * 0.4).sin()) * 1e-4
        })
        .collect();
    // A load on a top vertex and a hold on another, both off the interface.
    let top: Vec<usize> = (0..pos.len())
        .filter(|&v| pos[v].z > SIZE[2] - 1e-9 && pos[v].x > 0.004 && pos[v].x < 0.016)
        .collect();
    let (loaded, held) = (top[0], top[top.len() - 1]);
    sp.set_force(loaded, Vec3::new(0.0, 0.003, -0.01));
    let d = Vec3::new(0.0, 0.0, -5e-4);
    sp.hold(held, Some(d));
    let mut f_shared = vec![Vec3::ZERO; shared.len()];
    sp.shared_forces(&u_shared, &mut f_shared);
    let mut u = vec![Vec3::ZERO; pos.len()];
    sp.displacements(&u_shared, &mut u);
    let mut f = vec![Vec3::ZERO; pos.len()];
    pm.elastic_forces(&u, &mut f);
    let scale = f.iter().map(|x| x.length()).fold(0.0, Real::max);
    assert!(scale > 1e-3, "the part is loaded ({scale} N)");
    assert!((u[held] - d).length() < 1e-15);
    for (i, v) in shared.iter().enumerate() {
        assert!((u[v.idx()] - u_shared[i]).length() < 1e-15);
        assert!(
            (f[v.idx()] - f_shared[i]).length() < 1e-6 * scale,
            "shared vertex {i}: {} vs {}",
            f[v.idx()],
            f_shared[i]
        );
    }
    for (v, fv) in f.iter().enumerate() {
        let clamped = fixed.contains(&VertexId::from(v)) || shared.contains(&VertexId::from(v));
        if clamped || v == held {
            continue;
        }
        let ext = if v == loaded {
            Vec3::new(0.0, 0.003, -0.01)
        } else {
            Vec3::ZERO
        };
        assert!(
            (*fv + ext).length() < 1e-6 * scale,
            "vertex {v} out of equilibrium by {}",
            *fv + ext
        );
    }
}

fn settle(sim: &mut Hybrid, seconds: Real) {
    for _ in 0..(seconds / sim.dt_s()).ceil() as usize {
        sim.step();
    }
}

/// `total_n` straight down, shared by the vertices of the free end.
fn end_loads(m: &ElasticModel, total_n: Real) -> Vec<(VertexId, Vec3)> {
    let end = vertices(m, |p| p.x > SIZE[0] - 1e-9);
    let share = Vec3::new(0.0, 0.0, -total_n / end.len() as Real);
    end.into_iter().map(|v| (v, share)).collect()
}

/// The hybrid just under the whole body's element bound, loaded.
fn loaded_hybrid(
    m: &ElasticModel,
    fixed: &[VertexId],
    cuttable: &[TetId],
    loads: &[(VertexId, Vec3)],
) -> Hybrid {
    let dt = 0.9 * element_bound(m).dt_max_s;
    let mut sim =
        Hybrid::new(m.clone(), fixed, cuttable, HybridConfig::new(dt), |_, _| {}).unwrap();
    for (v, l) in loads {
        sim.set_external_force(*v, *l);
    }
    sim
}

/// (largest distance of `sim` from the static solution of `body` over its
/// live vertices, largest static displacement) (m).
fn static_error(
    sim: &Hybrid,
    body: &ElasticModel,
    fixed: &[VertexId],
    loads: &[(VertexId, Vec3)],
) -> (Real, Real) {
    let mut bc = Dirichlet::new(body.vertex_count());
    for v in fixed {
        bc.fix(*v);
    }
    let mut f = vec![Vec3::ZERO; body.vertex_count()];
    for (v, l) in loads {
        f[v.idx()] = *l;
    }
    let reference = solve_static(body, &bc, &f).unwrap().displacement_m;
    let scale = reference.iter().map(|u| u.length()).fold(0.0, Real::max);
    let err = (0..reference.len())
        .filter(|&v| body.topology().vertex_tet_count(VertexId::from(v)) > 0)
        .map(|v| (sim.displacement(VertexId::from(v)) - reference[v]).length())
        .fold(0.0, Real::max);
    (err, scale)
}

/// Cut the tensor-mass part until a shared vertex has no tensor-mass
/// tetrahedron left: the hybrid still settles on the static solution of the
/// cut body, and a cut in the precomputed part is refused.
#[test]
fn after_cuts_the_hybrid_settles_on_the_static_solution_of_the_cut_body() {
    let m = body(true);
    let fixed = vertices(&m, |p| p.x < 1e-9);
    let loads = end_loads(&m, 0.01);
    let cuttable = select(&m, |c| c.x > 0.015 && c.x < 0.03);
    let mut sim = loaded_hybrid(&m, &fixed, &cuttable, &loads);
    // The tensor-mass tetrahedra at the top of the x = 1.5 cm interface.
    let mut cut = m.clone();
    assert_eq!(
        crate::backend::cuttable(&sim),
        (cuttable.len(), m.mesh().tet_count())
    );
    for t in select(&m, |c| c.x > 0.015 && c.x < 0.02 && c.z > 0.015) {
        assert!(sim.can_cut(t));
        sim.remove_tet(t).unwrap();
        cut.remove_tet(t).unwrap();
    }
    let orphaned = sim
        .shared_tm
        .iter()
        .filter(|&&l| sim.tm.model().topology().vertex_tet_count(VertexId(l)) == 0)
        .count();
    assert!(
        orphaned > 0,
        "a shared vertex lost its last tensor-mass tetrahedron"
    );
    assert!(!sim.can_cut(TetId(0)));
    let err = sim.remove_tet(TetId(0)).unwrap_err().to_string();
    assert!(err.contains("precomputed part"), "{err}");
    settle(&mut sim, 3.0);
    let (err, scale) = static_error(&sim, &cut, &fixed, &loads);
    assert!(err < 1e-3 * scale, "{err} m off (scale {scale} m)");
    // The body the tools see is the cut one.
    assert_eq!(
        sim.model().topology().alive_count(),
        cut.topology().alive_count()
    );
}

#[test]
fn a_split_without_both_parts_is_refused() {
    let m = body(false);
    let all: Vec<TetId> = (0..m.mesh().tet_count()).map(TetId::from).collect();
    for region in [&[][..], &all[..]] {
        let err = Hybrid::new(m.clone(), &[], region, HybridConfig::new(1e-4), |_, _| {})
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("needs both parts"), "{err}");
    }
    let fixed = vertices(&m, |p| p.x < 1e-9);
    let mut cfg = HybridConfig::new(1.0);
    cfg.policy = DtPolicy::Refuse;
    let err = Hybrid::new(m.clone(), &fixed, &all[..10], cfg, |_, _| {})
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("exceeds the stable step"), "{err}");
}

/// With the stiff elements in the precomputed part, the hybrid's step is not
/// bounded by them the way the whole body's is: larger, and still stable
/// for many steps just under it.
#[test]
fn stiff_precomputed_elements_do_not_limit_the_step() {
    let mesh = BoxSpec::new(Vec3::from_array(SIZE), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let soft = Material::isotropic(5000.0, 0.45, 1000.0, 40.0).unwrap();
    let stiff = Material::isotropic(500_000.0, 0.45, 1000.0, 40.0).unwrap();
    let mut mats = TetMaterials::uniform(soft, mesh.tet_count());
    let id = mats.add(stiff).unwrap();
    let centroid = |t: TetId| {
        let p = mesh.tet_points(t);
        (p[0] + p[1] + p[2] + p[3]) / 4.0
    };
    for t in (0..mesh.tet_count()).map(TetId::from) {
        if centroid(t).x < 0.02 {
            mats.assign(t, id).unwrap();
        }
    }
    let m = ElasticModel::new(mesh.clone(), mats).unwrap();
    let fixed = vertices(&m, |p| p.x < 1e-9);
    let cuttable = select(&m, |c| c.x > 0.02);
    let whole = element_bound(&m).dt_max_s;
    let probe = Hybrid::new(
        m.clone(),
        &fixed,
        &cuttable,
        HybridConfig::new(whole),
        |_, _| {},
    )
    .unwrap();
    let own = probe.stable_step().dt_max_s;
    // The shared vertices still touch the stiff elements (their condensed
    // stiffness over the precomputed share of mass), so the gain is modest.
    assert!(
        own > 1.2 * whole,
        "hybrid step {own} s vs whole body {whole} s"
    );
    let mut sim = Hybrid::new(
        m,
        &fixed,
        &cuttable,
        HybridConfig::new(0.95 * own),
        |_, _| {},
    )
    .unwrap();
    assert_eq!(sim.substeps(), 1);
    let end = vertices(sim.model(), |p| p.x > SIZE[0] - 1e-9);
    for v in &end {
        sim.set_external_force(*v, Vec3::new(0.0, 0.0, -0.001));
    }
    for _ in 0..20_000 {
        sim.step();
    }
    let worst = sim
        .displacements()
        .iter()
        .map(|u| Vec3::from_array(*u).length())
        .fold(0.0, Real::max);
    assert!(worst.is_finite() && worst < 0.01, "{worst} m");
}

/// Parts that meet only at fixed vertices exchange nothing: each settles
/// on its own static solution (and nothing indexes an empty interface).
#[test]
fn parts_joined_only_at_fixed_vertices_settle_independently() {
    let m = body(false);
    let plane = |p: Vec3| p.x < 1e-9 || (p.x - 0.03).abs() < 1e-9;
    let fixed = vertices(&m, plane);
    let loads = end_loads(&m, 0.002);
    let mut sim = loaded_hybrid(&m, &fixed, &select(&m, |c| c.x > 0.03), &loads);
    assert_eq!(sim.shared_len(), 0);
    settle(&mut sim, 2.0);
    let (err, scale) = static_error(&sim, &m, &fixed, &loads);
    assert!(
        scale > 0.0 && err < 1e-3 * scale,
        "{err} m off (scale {scale} m)"
    );
}

/// The body with its free half (x > 2 cm) StVK and selected as the
/// tensor-mass region, the rest linear; the vertices fixed at x = 0.
fn stvk_half() -> (ElasticModel, Vec<TetId>, Vec<VertexId>) {
    use crate::material::MaterialModel;
    let mesh = BoxSpec::new(Vec3::from_array(SIZE), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let linear = Material::isotropic(5000.0, 0.45, 1000.0, 40.0).unwrap();
    let n = mesh.tet_count();
    let plain = ElasticModel::new(mesh.clone(), TetMaterials::uniform(linear, n)).unwrap();
    let tm_tets = select(&plain, |c| c.x > 0.02);
    let mut mats = TetMaterials::uniform(linear, n);
    let stvk = mats.add(linear.with_model(MaterialModel::Stvk)).unwrap();
    for t in &tm_tets {
        mats.assign(*t, stvk).unwrap();
    }
    let m = ElasticModel::new(mesh, mats).unwrap();
    let fixed = vertices(&m, |p| p.x < 1e-9);
    (m, tm_tets, fixed)
}

/// `m` as a hybrid with `held` pulled out by `by` over half a second (a
/// jump of several millimetres would invert the StVK elements there), then
/// held for two seconds to settle.
fn pulled_out(
    m: &ElasticModel,
    fixed: &[VertexId],
    tm_tets: &[TetId],
    held: &[VertexId],
    by: Vec3,
) -> Hybrid {
    let dt = 0.9 * element_bound(m).dt_max_s;
    let mut sim = Hybrid::new(m.clone(), fixed, tm_tets, HybridConfig::new(dt), |_, _| {}).unwrap();
    let ramp = (0.5 / sim.dt_s()).ceil() as usize;
    for k in 1..=ramp {
        for v in held {
            sim.prescribe(*v, by * (k as Real / ramp as Real));
        }
        sim.step();
    }
    settle(&mut sim, 2.0);
    sim
}

/// A hybrid whose tensor-mass half is StVK, its free end held stretched
/// by a fifth of the body's length: the held end feels the nonlinear
/// force (a hybrid gave the linear -(K U) there before), the same as the
/// tensor-mass part's own view of it, and at the free vertices shared with
/// the precomputed part the whole elastic force balances once settled
/// (the precomputed part's share is in it: the StVK elements' alone do
/// not balance).
#[test]
fn a_hybrid_reports_the_force_of_its_nonlinear_part() {
    use crate::contact::response::reaction::{elastic_force_n, vertex_force_n};
    use crate::contact::surface::adjacency::Adjacency;
    let (m, tm_tets, fixed) = stvk_half();
    let held = vertices(&m, |p| p.x > SIZE[0] - 1e-9);
    let sim = pulled_out(&m, &fixed, &tm_tets, &held, Vec3::new(0.008, 0.0, -0.002));
    let adj = Adjacency::new(&m);
    let felt: Vec3 = held.iter().map(|v| vertex_force_n(&sim, &adj, *v)).sum();
    let linear_only: Vec3 = held
        .iter()
        .map(|v| elastic_force_n(&adj, &m, *v, |w| sim.displacement(w)))
        .sum();
    let scale = felt.length();
    assert!(
        (felt - linear_only).length() > 0.05 * scale,
        "nonlinear enough to tell: felt {felt}, linear {linear_only}"
    );
    let adj_tm = Adjacency::new(sim.tm.model());
    let own: Vec3 = held
        .iter()
        .map(|v| vertex_force_n(&sim.tm, &adj_tm, VertexId(sim.tm_of[v.idx()])))
        .sum();
    assert!(
        (felt - own).length() < 1e-9 * scale,
        "felt {felt}, the tensor-mass part's own {own}"
    );
    let per_vertex = scale / held.len() as Real;
    let mut checked = 0;
    for &l in &sim.shared_tm {
        let v = sim.tm_vertices[l as usize];
        let whole = vertex_force_n(&sim, &adj, v);
        assert!(
            whole.length() < 0.02 * per_vertex,
            "shared vertex {v:?} out of balance by {whole} (held vertices carry {per_vertex} N each)"
        );
        checked += 1;
    }
    assert!(checked > 0);
}

/// A tool gripping the vertices where the StVK tensor-mass half meets the
/// linear precomputed half, pulled out by 6 mm (the free half follows, the
/// clamped half stretches): once settled, the force on the grip is minus
/// the support force the whole body's nonlinear static solution reports
/// there, so the precomputed part's share is in it and right (without it
/// the StVK half, nearly unloaded, gives almost nothing).
#[test]
fn a_grip_on_the_parts_interface_feels_the_whole_body_s_force() {
    use crate::contact::response::reaction::vertex_force_n;
    use crate::contact::surface::adjacency::Adjacency;
    use crate::static_newton::{NewtonConfig, solve_static_nonlinear};
    let (m, tm_tets, fixed) = stvk_half();
    let grip = vertices(&m, |p| (p.x - 0.02).abs() < 1e-9);
    let pull = Vec3::new(0.006, 0.0, -0.001);
    let mut bc = Dirichlet::new(m.vertex_count());
    for v in &fixed {
        bc.fix(*v);
    }
    for v in &grip {
        bc.prescribe(*v, pull);
    }
    let statics = solve_static_nonlinear(
        &m,
        &bc,
        &vec![Vec3::ZERO; m.vertex_count()],
        NewtonConfig::default(),
    )
    .unwrap()
    .solution;
    let support: Vec3 = grip.iter().map(|v| statics.force_n[v.idx()]).sum();
    let sim = pulled_out(&m, &fixed, &tm_tets, &grip, pull);
    let adj = Adjacency::new(&m);
    let felt: Vec3 = grip.iter().map(|v| vertex_force_n(&sim, &adj, *v)).sum();
    assert!(
        (felt + support).length() < 0.02 * support.length(),
        "felt {felt} N against the static support {support} N"
    );
}
