//! The surface membrane (paper 3.7): k = alpha * (sum of altitudes), forces
//! are minus the gradient of the spring energy, the linearised model agrees
//! with eq 29 for small displacements, cutting removes the capsule of the
//! removed tissue only and restoring gives it back, and the stability bound
//! still holds with a stiff capsule.

use tissue::test_support as common;

use common::*;
use std::collections::HashMap;
use tissue::membrane::MembraneModel;
use tissue::prelude::*;
use tissue::tensor_mass::element_bound;

const ALPHA: f64 = 2.0e5; // N/m^2

fn model(alpha: f64, m: MembraneModel) -> ElasticModel {
    let mesh = box_mesh([3, 2, 2], 0.01, 0.12, 9);
    let n = mesh.tet_count();
    ElasticModel::new(mesh, TetMaterials::uniform(iso_material(), n))
        .unwrap()
        .with_membrane(alpha, m)
        .unwrap()
}

#[test]
fn spring_stiffness_is_alpha_times_the_summed_altitudes() {
    let model = model(ALPHA, MembraneModel::Nonlinear);
    let p = model.mesh().positions_m();
    // Independent: sum 2 A / |e| over the surface triangles of each edge.
    let mut expect: HashMap<(u32, u32), f64> = HashMap::new();
    for [a, b, c] in model.topology().surface_triangles(model.mesh()) {
        let twice_area = (p[b.idx()] - p[a.idx()])
            .cross(p[c.idx()] - p[a.idx()])
            .length();
        for (x, y) in [(a, b), (b, c), (c, a)] {
            let key = (x.0.min(y.0), x.0.max(y.0));
            *expect.entry(key).or_default() += ALPHA * twice_area / p[x.idx()].distance(p[y.idx()]);
        }
    }
    let m = model.membrane().unwrap();
    let mut seen = 0;
    for (e, [a, b]) in model.topology().edges().iter().enumerate() {
        let k = m.stiffness_n_per_m()[e];
        match expect.get(&(a.0, b.0)) {
            Some(x) => {
                assert!((k - x).abs() < 1e-12 * x, "edge {a:?}-{b:?}: {k} vs {x}");
                seen += 1;
            }
            None => assert_eq!(k, 0.0),
        }
    }
    assert_eq!(seen, expect.len());
    assert_eq!(m.capsule_edges().len(), expect.len());
}

#[test]
fn nonlinear_forces_are_minus_the_energy_gradient_and_match_linear_when_small() {
    let nl = model(ALPHA, MembraneModel::Nonlinear);
    let lin = model(ALPHA, MembraneModel::Linear);
    let n = nl.vertex_count();
    let mut rng = Rng::new(4);
    let u: Vec<Vec3> = (0..n).map(|_| rng.vec3() * 2e-3).collect();
    let ua: Vec<[f64; 3]> = u.iter().map(|v| v.to_array()).collect();
    let mut f = vec![[0.0; 3]; n];
    nl.membrane_forces(&ua, &mut f);
    let membrane = nl.membrane().unwrap();
    let energy = |u: &[Vec3]| membrane.energy_j(nl.topology(), nl.mesh().positions_m(), u);
    let fmax = f.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
    let h = 1e-7;
    for v in (0..n).step_by(2) {
        for a in 0..3 {
            let (mut up, mut dn) = (u.clone(), u.clone());
            up[v][a] += h;
            dn[v][a] -= h;
            let g = (energy(&up) - energy(&dn)) / (2.0 * h);
            assert!(
                (f[v][a] + g).abs() < 1e-5 * fmax,
                "vertex {v} axis {a}: {} vs {}",
                f[v][a],
                -g
            );
        }
    }
    // Small displacements: eq 29 and the linearised springs agree to first order.
    let small: Vec<Vec3> = u.iter().map(|x| *x * 1e-4).collect();
    let sa: Vec<[f64; 3]> = small.iter().map(|v| v.to_array()).collect();
    let mut f_nl = vec![[0.0; 3]; n];
    nl.membrane_forces(&sa, &mut f_nl);
    let (mut k_lin, mut k_none) = (vec![Vec3::ZERO; n], vec![Vec3::ZERO; n]);
    lin.elastic_forces(&small, &mut k_lin);
    nl.elastic_forces(&small, &mut k_none); // tensors without the (nonlinear) membrane
    let scale = f_nl.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
    for v in 0..n {
        let lin_membrane = k_lin[v] - k_none[v];
        let d = (lin_membrane - Vec3::from_array(f_nl[v]))
            .abs()
            .max_element();
        assert!(
            d < 1e-3 * scale,
            "vertex {v}: linear {lin_membrane} vs eq 29 {:?}",
            f_nl[v]
        );
    }
}

#[test]
fn cutting_removes_the_capsule_of_removed_tissue_and_restoring_gives_it_back() {
    for m in [MembraneModel::Linear, MembraneModel::Nonlinear] {
        let original = model(ALPHA, m);
        let mut cut = original.clone();
        let faces0 = original.membrane().unwrap().face_count(original.topology());
        let mut removed = Vec::new();
        for t in (0..original.mesh().tet_count()).step_by(4) {
            cut.remove_tet(TetId::from(t)).unwrap();
            removed.push(TetId::from(t));
            // Cut faces never get a capsule: the count only goes down.
            let faces = cut.membrane().unwrap().face_count(cut.topology());
            assert!(faces <= faces0);
        }
        assert!(cut.membrane().unwrap().face_count(cut.topology()) < faces0);
        for t in removed.iter().rev() {
            cut.restore_tet(*t).unwrap();
        }
        let (a, b) = (cut.membrane().unwrap(), original.membrane().unwrap());
        for (x, y) in a.stiffness_n_per_m().iter().zip(b.stiffness_n_per_m()) {
            assert!(
                (x - y).abs() <= 1e-12 * y.abs().max(1.0),
                "{m:?}: k {x} vs {y}"
            );
        }
        let tol = 1e-12 * max_entry(original.vertex_tensors());
        for (x, y) in cut.vertex_tensors().iter().zip(original.vertex_tensors()) {
            assert!(tissue::math::max_abs(&(*x - *y)) <= tol);
        }
        for (x, y) in cut.edge_tensors().iter().zip(original.edge_tensors()) {
            assert!(tissue::math::max_abs(&(*x - *y)) <= tol);
        }
    }
}

#[test]
fn removing_everything_leaves_no_spring() {
    let mut m = model(ALPHA, MembraneModel::Linear);
    for t in 0..m.mesh().tet_count() {
        m.remove_tet(TetId::from(t)).unwrap();
    }
    assert!(
        m.membrane()
            .unwrap()
            .stiffness_n_per_m()
            .iter()
            .all(|k| *k == 0.0)
    );
    assert!(m.vertex_tensors().iter().all(|k| *k == Mat3::ZERO));
}

#[test]
fn element_bound_holds_with_a_stiff_capsule() {
    for alpha in [0.0, ALPHA, 1e3 * ALPHA] {
        let m = model(alpha, MembraneModel::Linear);
        let n3 = 3 * m.vertex_count();
        let k = m.dense_stiffness();
        let mass = m.masses_kg();
        let a: Vec<f64> = (0..n3 * n3)
            .map(|x| k[x] / (mass[(x / n3) / 3] * mass[(x % n3) / 3]).sqrt())
            .collect();
        let lambda = *sym_eigenvalues(n3, &a).last().unwrap();
        let bound = element_bound(&m).omega_max_rad_s.powi(2);
        assert!(
            bound >= lambda * (1.0 - 1e-12),
            "alpha {alpha}: bound {bound} < {lambda}"
        );
        assert!(
            bound < 4.0 * lambda,
            "alpha {alpha}: bound {bound} too loose for {lambda}"
        );
    }
}

#[test]
fn explicit_step_includes_the_nonlinear_membrane() {
    let m = model(ALPHA, MembraneModel::Nonlinear);
    let n = m.vertex_count();
    let dt = 0.5 * element_bound(&m).dt_max_s;
    let mut sim = Explicit::<f64>::new(m.clone(), ExplicitConfig::new(dt)).unwrap();
    let mut rng = Rng::new(3);
    let u0: Vec<Vec3> = (0..n).map(|_| rng.vec3() * 1e-4).collect();
    sim.set_state(&u0, &u0);
    sim.step();
    let ua: Vec<[f64; 3]> = u0.iter().map(|v| v.to_array()).collect();
    let mut fm = vec![[0.0; 3]; n];
    m.membrane_forces(&ua, &mut fm);
    let mut f = vec![Vec3::ZERO; n];
    m.elastic_forces(&u0, &mut f);
    for v in 0..n {
        let mass = m.masses_kg()[v];
        let expect = u0[v] + (f[v] + Vec3::from_array(fm[v])) * (dt * dt / mass);
        let got = sim.displacement(VertexId::from(v));
        assert!(
            (got - expect).length() < 1e-12 * 1e-4,
            "vertex {v}: {got} vs {expect}"
        );
    }
}

#[test]
fn bad_alpha_is_refused() {
    let mesh = box_mesh([1, 1, 1], 0.01, 0.0, 0);
    let n = mesh.tet_count();
    let model = ElasticModel::new(mesh, TetMaterials::uniform(iso_material(), n)).unwrap();
    let err = model
        .with_membrane(f64::NAN, MembraneModel::Linear)
        .unwrap_err();
    assert!(err.to_string().contains("alpha"), "{err}");
}
