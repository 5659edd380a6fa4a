//! Laws of the stiffness tensors: forces are minus the energy gradient, the
//! assembled stiffness is symmetric with exactly six zero modes for a free
//! body, rigid motions produce no force, and the hot kernel reproduces the
//! double-precision model.

use tissue::test_support as common;

use common::*;
use tissue::prelude::*;
use tissue::tensor_mass::Kernel;

fn all_models() -> Vec<(String, ElasticModel)> {
    let mesh = || box_mesh([3, 2, 2], 0.01, 0.15, 7);
    let mut out = vec![(
        "isotropic".to_string(),
        ElasticModel::new(
            mesh(),
            TetMaterials::uniform(iso_material(), mesh().tet_count()),
        )
        .unwrap(),
    )];
    for terms in term_sets() {
        out.push((format!("mixed {terms}"), mixed_model(mesh(), terms, 11)));
    }
    out
}

#[test]
fn forces_are_minus_the_gradient_of_the_energy() {
    for (name, model) in all_models() {
        let mut rng = Rng::new(3);
        let n = model.vertex_count();
        let u: Vec<Vec3> = (0..n).map(|_| rng.vec3() * 1e-3).collect();
        let mut f = vec![Vec3::ZERO; n];
        model.elastic_forces(&u, &mut f);
        // The energy is quadratic, so central differences are exact up to round-off.
        let h = 1e-6;
        let fmax = f.iter().map(|x| x.abs().max_element()).fold(0.0, f64::max);
        for v in (0..n).step_by(3) {
            for a in 0..3 {
                let mut up = u.clone();
                up[v][a] += h;
                let mut dn = u.clone();
                dn[v][a] -= h;
                let grad = (model.energy_j(&up) - model.energy_j(&dn)) / (2.0 * h);
                let err = (f[v][a] + grad).abs();
                assert!(
                    err < 1e-6 * fmax,
                    "{name}: vertex {v} axis {a}: F {} vs -dE/du {}",
                    f[v][a],
                    -grad
                );
            }
        }
        // And the energy is exactly (1/2) U.K U.
        let quad: f64 = -0.5 * u.iter().zip(&f).map(|(a, b)| a.dot(*b)).sum::<f64>();
        let e = model.energy_j(&u);
        assert!((quad - e).abs() < 1e-12 * e.abs(), "{name}: {quad} vs {e}");
    }
}

#[test]
fn stiffness_is_symmetric_with_six_rigid_modes() {
    for (name, model) in all_models() {
        let n3 = 3 * model.vertex_count();
        let k = model.dense_stiffness();
        let kmax = k.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        for r in 0..n3 {
            for c in 0..r {
                let d = (k[r * n3 + c] - k[c * n3 + r]).abs();
                assert!(d <= 1e-13 * kmax, "{name}: K[{r},{c}] asymmetric by {d}");
            }
        }
        let ev = sym_eigenvalues(n3, &k);
        let top = ev[n3 - 1];
        let zeros = ev.iter().filter(|e| e.abs() < 1e-10 * top).count();
        assert_eq!(
            zeros,
            6,
            "{name}: {zeros} zero modes; smallest {:?}",
            &ev[..8]
        );
        assert!(
            ev[6] > 1e-6 * top,
            "{name}: 7th eigenvalue {} too small",
            ev[6]
        );
        assert!(
            ev[0] > -1e-10 * top,
            "{name}: negative eigenvalue {}",
            ev[0]
        );
    }
}

#[test]
fn rigid_motions_give_zero_force() {
    for (name, model) in all_models() {
        let n = model.vertex_count();
        let p = model.mesh().positions_m();
        let mut f = vec![Vec3::ZERO; n];
        let mut rng = Rng::new(5);
        let scale = 1e-3
            * model
                .vertex_tensors()
                .iter()
                .map(tissue::math::max_abs)
                .fold(0.0, f64::max);
        for _ in 0..3 {
            let t = rng.vec3() * 1e-3;
            let w = rng.vec3() * 1e-2;
            // Translation plus infinitesimal rotation (w x p): zero strain.
            let u: Vec<Vec3> = p.iter().map(|x| t + w.cross(*x)).collect();
            model.elastic_forces(&u, &mut f);
            let fmax = f.iter().map(|x| x.abs().max_element()).fold(0.0, f64::max);
            assert!(
                fmax < 1e-10 * scale,
                "{name}: rigid motion gave force {fmax}"
            );
        }
    }
}

#[test]
fn block_transpose_pairs_and_kernel_matches_model() {
    for (name, model) in all_models() {
        // K_ji = K_ij^T element by element.
        for t in 0..model.mesh().tet_count() {
            let (el, g) = model.element(TetId::from(t));
            for i in 0..4 {
                for j in 0..4 {
                    let d = el.block(&g, i, j) - el.block(&g, j, i).transpose();
                    assert!(
                        tissue::math::max_abs(&d)
                            < 1e-12 * tissue::math::max_abs(&el.block(&g, i, i))
                    );
                }
            }
        }
        let n = model.vertex_count();
        let mut rng = Rng::new(9);
        let u: Vec<Vec3> = (0..n).map(|_| rng.vec3()).collect();
        let mut f = vec![Vec3::ZERO; n];
        model.elastic_forces(&u, &mut f);
        let ua: Vec<[f64; 3]> = u.iter().map(|v| v.to_array()).collect();
        let fmax = f.iter().map(|x| x.abs().max_element()).fold(0.0, f64::max);
        for (tol, ku) in [
            (1e-12, {
                let mut o = vec![[0.0; 3]; n];
                Kernel::<f64>::new(&model).apply(&ua, &mut o);
                o
            }),
            (1e-6, {
                let mut o = vec![[0.0; 3]; n];
                Kernel::<f32>::new(&model).apply(&ua, &mut o);
                o
            }),
        ] {
            for v in 0..n {
                for a in 0..3 {
                    let err = (ku[v][a] + f[v][a]).abs();
                    assert!(
                        err <= tol * fmax,
                        "{name}: kernel (tol {tol}) off by {err} at {v}/{a}"
                    );
                }
            }
        }
    }
}
