//! The static solver against analytic solutions: uniaxial stretch is exact
//! for P1 elements (isotropic, and transversally isotropic along and across
//! the fibre, against the engineering constants from the compliance), and the
//! patch test on a mesh with perturbed interior vertices.

mod common;

use common::*;
use sim_server::prelude::*;
use sim_server::static_solve::StaticError;

const L: f64 = 0.05;
const W: f64 = 0.02;
const H: f64 = 0.02;

/// Uniaxial stress along x on a box [0, len] x [0, wid] x [0, hei] by
/// prescribed end displacements with only the rigid motions removed (the
/// corners (0,0,0) and (0,wid,0) must be vertices); returns (displacements,
/// total x-reaction on x = len).
fn uniaxial(model: &ElasticModel, strain: f64, len: f64, wid: f64) -> (Vec<Vec3>, f64) {
    let p = model.mesh().positions_m();
    let n = model.vertex_count();
    let mut bc = Dirichlet::new(n);
    // Selects boundary vertices; meshes from files carry round-off in their coordinates.
    let eps = 1e-9;
    let mut corners = 0;
    for (v, x) in p.iter().enumerate() {
        let v = VertexId::from(v);
        if x.x < eps {
            bc.prescribe_axis(v, 0, 0.0);
        }
        if x.x > len - eps {
            bc.prescribe_axis(v, 0, strain * len);
        }
        if x.x < eps && x.y < eps && x.z < eps {
            bc.prescribe_axis(v, 1, 0.0);
            bc.prescribe_axis(v, 2, 0.0);
            corners += 1;
        }
        if x.x < eps && (x.y - wid).abs() < eps && x.z < eps {
            bc.prescribe_axis(v, 2, 0.0);
            corners += 1;
        }
    }
    assert_eq!(corners, 2, "the box must have its corners as vertices");
    let sol = solve_static(model, &bc, &vec![Vec3::ZERO; n]).unwrap();
    let reaction: f64 = p
        .iter()
        .zip(&sol.force_n)
        .filter(|(x, _)| x.x > len - eps)
        .map(|(_, f)| f.x)
        .sum();
    (sol.displacement_m, reaction)
}

fn uniform_model(material: Material, fiber: Option<Vec3>) -> ElasticModel {
    let mesh = BoxSpec::new(Vec3::new(L, W, H), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let n = mesh.tet_count();
    let mut mats = TetMaterials::uniform(material, n);
    if let Some(a) = fiber {
        for t in 0..n {
            mats.set_fiber(TetId::from(t), a).unwrap();
        }
    }
    ElasticModel::new(mesh, mats).unwrap()
}

/// Checks u = (e x, -nu_y e y, -nu_z e z) everywhere and the reaction
/// E e wid hei on a box of sides `size` = (len, wid, hei).
fn check_uniaxial_box(
    name: &str,
    model: &ElasticModel,
    size: [f64; 3],
    young_pa: f64,
    nu_y: f64,
    nu_z: f64,
) {
    let [len, wid, hei] = size;
    let e = 0.02;
    let (u, reaction) = uniaxial(model, e, len, wid);
    for (x, d) in model.mesh().positions_m().iter().zip(&u) {
        let exact = Vec3::new(e * x.x, -nu_y * e * x.y, -nu_z * e * x.z);
        assert!(
            (*d - exact).length() < 1e-10 * e * len,
            "{name}: at {x}: {d} vs {exact}"
        );
    }
    let expect = young_pa * e * wid * hei;
    assert!(
        (reaction - expect).abs() < 1e-9 * expect,
        "{name}: reaction {reaction} vs {expect}"
    );
}

/// [`check_uniaxial_box`] on the generated L x W x H box.
fn check_uniaxial(name: &str, model: &ElasticModel, young_pa: f64, nu_y: f64, nu_z: f64) {
    check_uniaxial_box(name, model, [L, W, H], young_pa, nu_y, nu_z);
}

#[test]
fn uniaxial_stretch_is_exact_isotropic() {
    let iso = liver_iso();
    check_uniaxial(
        "isotropic",
        &uniform_model(iso_material(), None),
        iso.young_pa(),
        iso.poisson(),
        iso.poisson(),
    );
}

#[test]
fn uniaxial_stretch_is_exact_along_and_across_the_fibre() {
    let mu = liver_iso().mu_pa();
    for terms in term_sets() {
        for (dl, dm) in [(0.8 * mu, 2.0 * mu), (-0.3 * mu, 5.0 * mu)] {
            let material = aniso_material(dl, dm, terms).unwrap();
            let Elasticity::Transverse(t) = material.elasticity() else {
                unreachable!()
            };
            let eng = t.engineering();
            // Along the fibre (fibre = x): E_L and nu_LT in both transverse directions.
            let name = format!("along fibre {terms} dl {dl:.0} dm {dm:.0}");
            let model = uniform_model(material, Some(Vec3::X));
            let nu = eng.poisson_fiber_transverse;
            check_uniaxial(&name, &model, eng.young_fiber_pa, nu, nu);
            // Across (fibre = z): E_T, nu_TT towards y, nu_TL towards z.
            let name = format!("across fibre {terms} dl {dl:.0} dm {dm:.0}");
            let model = uniform_model(material, Some(Vec3::Z));
            check_uniaxial(
                &name,
                &model,
                eng.young_transverse_pa,
                eng.poisson_transverse,
                eng.poisson_transverse_fiber,
            );
        }
    }
}

#[test]
fn patch_test_on_a_perturbed_mesh() {
    let mu = liver_iso().mu_pa();
    let mut rng = Rng::new(21);
    let mut materials = vec![(iso_material(), None)];
    for terms in term_sets() {
        let a = rng.vec3().normalize();
        materials.push((aniso_material(0.8 * mu, 2.0 * mu, terms).unwrap(), Some(a)));
    }
    for (material, fiber) in materials {
        let mesh = box_mesh([4, 3, 3], 0.01, 0.2, 4);
        let n = mesh.tet_count();
        let mut mats = TetMaterials::uniform(material, n);
        if let Some(a) = fiber {
            for t in 0..n {
                mats.set_fiber(TetId::from(t), a).unwrap();
            }
        }
        let model = ElasticModel::new(mesh, mats).unwrap();
        // A general linear field u = A p + b imposed on the boundary.
        let a = Mat3::from_cols(rng.vec3(), rng.vec3(), rng.vec3()) * 0.05;
        let b = rng.vec3() * 1e-3;
        let size = Vec3::new(0.04, 0.03, 0.03);
        let mut bc = Dirichlet::new(model.vertex_count());
        let p = model.mesh().positions_m();
        for (v, x) in p.iter().enumerate() {
            if (0..3).any(|k| x[k] < 1e-9 || x[k] > size[k] - 1e-9) {
                bc.prescribe(VertexId::from(v), a * *x + b);
            }
        }
        let interior = model.vertex_count() - bc.count() / 3;
        assert!(interior >= 12);
        let sol = solve_static(&model, &bc, &vec![Vec3::ZERO; model.vertex_count()]).unwrap();
        for (x, u) in p.iter().zip(&sol.displacement_m) {
            let exact = a * *x + b;
            assert!((*u - exact).length() < 1e-11, "{fiber:?}: {u} vs {exact}");
        }
        // Interior vertices carry no load and the boundary reactions balance.
        let total: Vec3 = sol.force_n.iter().sum();
        assert!(total.length() < 1e-9 * sol.force_n.iter().map(|f| f.length()).sum::<f64>());
    }
}

#[test]
fn unconstrained_static_problem_is_refused() {
    let model = uniform_model(iso_material(), None);
    let n = model.vertex_count();
    let err = solve_static(&model, &Dirichlet::new(n), &vec![Vec3::ZERO; n]).unwrap_err();
    assert!(matches!(err, StaticError::Singular { .. }), "{err}");
    assert!(err.to_string().contains("rigid"));
    // Under a load, held nowhere, at one vertex or along one line of
    // vertices: the rigid motions are free (a factorization got through
    // such a box by round-off, "moving" it 1e11 m under 1 N). Three
    // vertices not on a line hold them.
    let p = model.mesh().positions_m();
    let mut pushed = vec![Vec3::ZERO; n];
    pushed[n - 1] = Vec3::new(0.0, 0.0, -1.0);
    let on_x_axis: Vec<usize> = (0..n).filter(|&v| p[v].y < 1e-9 && p[v].z < 1e-9).collect();
    assert!(on_x_axis.len() >= 3);
    let corner_y = (0..n)
        .find(|&v| p[v].x < 1e-9 && (p[v].y - W).abs() < 1e-9 && p[v].z < 1e-9)
        .unwrap();
    let held = |vs: &[usize]| {
        let mut bc = Dirichlet::new(n);
        for &v in vs {
            bc.fix(VertexId::from(v));
        }
        bc
    };
    for (what, vs) in [
        ("nowhere", vec![]),
        ("one vertex", vec![0]),
        ("one line", on_x_axis.clone()),
    ] {
        let bc = held(&vs);
        assert!(!bc.holds_rigid_motions(p), "{what}");
        let err = solve_static(&model, &bc, &pushed).unwrap_err();
        assert!(matches!(err, StaticError::Singular { .. }), "{what}: {err}");
    }
    // A determinate roller support on a large face (its z rows many, the
    // rows holding x and y three) is held: each rigid mode weighs alike.
    let side = 300;
    let grid: Vec<Vec3> = (0..side * side)
        .map(|k| Vec3::new((k % side) as f64 * 1e-3, (k / side) as f64 * 1e-3, 0.0))
        .collect();
    let mut rollers = Dirichlet::new(grid.len());
    for v in 0..grid.len() {
        rollers.prescribe_axis(VertexId::from(v), 2, 0.0);
    }
    rollers.prescribe_axis(VertexId::from(0), 0, 0.0);
    rollers.prescribe_axis(VertexId::from(0), 1, 0.0);
    rollers.prescribe_axis(VertexId::from(1), 1, 0.0);
    assert!(rollers.holds_rigid_motions(&grid));
    let mut spinning = Dirichlet::new(grid.len());
    for v in 0..grid.len() {
        spinning.prescribe_axis(VertexId::from(v), 2, 0.0);
    }
    spinning.prescribe_axis(VertexId::from(0), 0, 0.0);
    spinning.prescribe_axis(VertexId::from(0), 1, 0.0);
    assert!(!spinning.holds_rigid_motions(&grid), "free to turn about z");
    let mut three = on_x_axis;
    three.push(corner_y);
    let bc = held(&three);
    assert!(bc.holds_rigid_motions(p));
    let sol = solve_static(&model, &bc, &pushed).unwrap();
    assert!(sol.displacement_m.iter().all(|d| d.is_finite()));
    let mut loads = vec![Vec3::ZERO; n];
    loads[3].y = f64::NAN;
    let err = solve_static(&model, &Dirichlet::new(n), &loads).unwrap_err();
    assert_eq!(
        err,
        StaticError::NonFinite {
            what: "load",
            vertex: 3
        }
    );
}

/// The static solver reproduces uniaxial stretch exactly on an unstructured
/// mesh made by Gmsh (not by this project): box 100 x 20 x 20 mm.
#[test]
fn uniaxial_stretch_is_exact_on_a_gmsh_mesh() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/meshes/box_v41.msh");
    let imported = sim_server::mesh::io::read_mesh(std::path::Path::new(path)).unwrap();
    let mesh = imported.mesh;
    assert_eq!(mesh.tet_count(), 1816);
    let n_tets = mesh.tet_count();
    let model = ElasticModel::new(mesh, TetMaterials::uniform(iso_material(), n_tets)).unwrap();
    let iso = liver_iso();
    let nu = iso.poisson();
    check_uniaxial_box(
        "gmsh box",
        &model,
        [0.1, 0.02, 0.02],
        iso.young_pa(),
        nu,
        nu,
    );
}
