//! Laws of the nonlinear element: rotations are force-free, forces are minus
//! the gradient of the energy, the tangent is the derivative of the forces,
//! small strains reduce to the linear model, uniaxial strain matches the
//! closed form along and across the fibre.

use super::*;
use crate::material::{Isotropic, Material, Terms, TransverselyIsotropic};

fn tet() -> Geometry {
    Geometry::new(points())
}

fn points() -> [Vec3; 4] {
    [
        Vec3::new(0.001, 0.0, 0.0),
        Vec3::new(0.011, 0.001, 0.0),
        Vec3::new(0.0, 0.009, 0.002),
        Vec3::new(0.002, 0.001, 0.012),
    ]
}

fn isotropic() -> TetElastic {
    let m = Material::isotropic(4500.0, 0.45, 1000.0, 0.0).unwrap();
    TetElastic::new(&m, Vec3::X)
}

fn anisotropic(fiber: Vec3) -> TetElastic {
    let iso = Isotropic::from_young_poisson(4500.0, 0.4).unwrap();
    let t = TransverselyIsotropic::new(iso, 3000.0, 2500.0, Terms::ALL).unwrap();
    let m = Material::new(crate::material::Elasticity::Transverse(t), 1000.0, 0.0).unwrap();
    TetElastic::new(&m, fiber.normalize())
}

/// Displacements taking the rest points through x -> a x + b.
fn affine(_g: &Geometry, a: Mat3, b: Vec3) -> [Vec3; 4] {
    points().map(|p| a * p + b - p)
}

fn some_stretch() -> Mat3 {
    Mat3::from_cols(
        Vec3::new(1.3, 0.1, -0.05),
        Vec3::new(0.05, 0.85, 0.2),
        Vec3::new(-0.1, 0.15, 1.1),
    )
}

/// A fresh rotation state (the element's rotation before its first step).
fn q0() -> DQuat {
    DQuat::IDENTITY
}

const NONLINEAR: [MaterialModel; 2] = [MaterialModel::Stvk, MaterialModel::Corotational];

fn norm(f: &[Vec3; 4]) -> Real {
    f.iter().map(|v| v.length()).sum()
}

#[test]
fn a_rigid_rotation_is_force_free_for_nonlinear_models_but_not_linear() {
    let g = tet();
    let r = Mat3::from_axis_angle(Vec3::new(1.0, 2.0, 0.5).normalize(), 90f64.to_radians());
    let u = affine(&g, r, Vec3::new(0.01, -0.02, 0.005));
    let scale = norm(&element_forces(
        MaterialModel::Linear,
        &isotropic(),
        &g,
        &affine(
            &g,
            Mat3::from_diagonal(Vec3::new(1.1, 1.0, 1.0)),
            Vec3::ZERO,
        ),
        &mut q0(),
    ));
    for el in [isotropic(), anisotropic(Vec3::new(1.0, 1.0, 0.0))] {
        for model in NONLINEAR {
            let f = element_forces(model, &el, &g, &u, &mut q0());
            assert!(norm(&f) < 1e-9 * scale, "{model:?}: {f:?}");
        }
        // The linear model's artefact: a 90 degree rotation strains it by
        // more than a 10% stretch would.
        let f = element_forces(MaterialModel::Linear, &el, &g, &u, &mut q0());
        assert!(norm(&f) > scale, "linear under rotation: {f:?}");
    }
}

#[test]
fn forces_are_minus_the_gradient_of_the_energy() {
    let g = tet();
    let squashed = Mat3::from_diagonal(Vec3::new(0.7, 0.9, 0.5)) * some_stretch();
    assert!(in_barrier(&squashed));
    for u in [
        affine(&g, some_stretch(), Vec3::new(0.001, 0.002, 0.0)),
        affine(&g, squashed, Vec3::ZERO),
    ] {
        let cases = [
            (MaterialModel::Stvk, isotropic()),
            (MaterialModel::Stvk, anisotropic(Vec3::new(1.0, 0.3, 0.2))),
            (MaterialModel::Corotational, isotropic()),
            (MaterialModel::Linear, anisotropic(Vec3::new(0.2, 1.0, 0.0))),
        ];
        for (model, el) in cases {
            let f = element_forces(model, &el, &g, &u, &mut q0());
            let h = 1e-7;
            for k in 0..4 {
                for d in 0..3 {
                    let energy = |s: Real| {
                        let mut v = u;
                        v[k][d] += s * h;
                        element_energy_j(model, &el, &g, &v, &mut q0())
                    };
                    let grad = (energy(1.0) - energy(-1.0)) / (2.0 * h);
                    let scale = f[k].length().max(1e-6);
                    assert!(
                        (f[k][d] + grad).abs() < 1e-6 * scale,
                        "{model:?} vertex {k} axis {d}: force {} gradient {grad}",
                        f[k][d]
                    );
                }
            }
        }
    }
}

#[test]
fn the_tangent_is_the_derivative_of_the_forces() {
    let g = tet();
    let turn = Mat3::from_axis_angle(Vec3::new(0.3, -1.0, 0.4).normalize(), 1.2);
    let states = [
        affine(&g, some_stretch(), Vec3::ZERO),
        affine(&g, turn * some_stretch(), Vec3::new(0.0, 0.01, 0.0)),
        // In the StVK barrier (det F < 0.5).
        affine(
            &g,
            turn * Mat3::from_diagonal(Vec3::new(0.7, 0.9, 0.5)) * some_stretch(),
            Vec3::ZERO,
        ),
    ];
    for u in states {
        for model in NONLINEAR {
            for el in [isotropic(), anisotropic(Vec3::new(1.0, 0.3, 0.2))] {
                let k = element_tangent(model, &el, &g, &u, &mut q0());
                let h = 1e-8;
                for j in 0..4 {
                    for c in 0..3 {
                        let at = |s: Real| {
                            let mut v = u;
                            v[j][c] += s * h;
                            element_forces(model, &el, &g, &v, &mut q0())
                        };
                        let (fp, fm) = (at(1.0), at(-1.0));
                        for i in 0..4 {
                            let fd = -(fp[i] - fm[i]) / (2.0 * h);
                            let an = k[i][j].col(c);
                            let scale = k[i][i].col(c).length().max(1.0);
                            assert!(
                                (fd - an).length() < 2e-5 * scale,
                                "{model:?} K[{i}][{j}] column {c}: analytic {an} finite difference {fd}"
                            );
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn the_stvk_tangent_is_symmetric_and_equals_the_linear_blocks_at_rest() {
    let g = tet();
    for el in [isotropic(), anisotropic(Vec3::new(1.0, 0.3, 0.2))] {
        let rest = element_tangent(MaterialModel::Stvk, &el, &g, &[Vec3::ZERO; 4], &mut q0());
        let stretched = element_tangent(
            MaterialModel::Stvk,
            &el,
            &g,
            &affine(&g, some_stretch(), Vec3::ZERO),
            &mut q0(),
        );
        for i in 0..4 {
            for j in 0..4 {
                let lin = el.block(&g, i, j);
                let tol = 1e-9 * crate::math::max_abs(&el.block(&g, i, i));
                assert!(
                    crate::math::max_abs(&(rest[i][j] - lin)) < tol,
                    "rest K[{i}][{j}]"
                );
                let asym = stretched[i][j] - stretched[j][i].transpose();
                assert!(
                    crate::math::max_abs(&asym) < tol,
                    "K[{i}][{j}] not symmetric"
                );
            }
        }
    }
}

#[test]
fn small_strains_reproduce_the_linear_model_to_first_order() {
    let g = tet();
    let el = anisotropic(Vec3::new(1.0, 0.3, 0.2));
    let shape = some_stretch() - Mat3::IDENTITY;
    let mut previous = None;
    for eps in [1e-3, 1e-4] {
        let u = affine(&g, Mat3::IDENTITY + shape * eps, Vec3::ZERO);
        let lin = element_forces(MaterialModel::Linear, &el, &g, &u, &mut q0());
        let diff: Vec<Real> = NONLINEAR
            .iter()
            .map(|m| {
                let f = element_forces(*m, &el, &g, &u, &mut q0());
                f.iter()
                    .zip(&lin)
                    .map(|(a, b)| (*a - *b).length())
                    .sum::<Real>()
                    / norm(&lin)
            })
            .collect();
        // The relative difference is O(eps): ten times smaller strain, ten
        // times smaller difference (the second-order terms).
        if let Some(prev) = previous.replace(diff.clone()) {
            for (a, b) in diff.iter().zip(prev.iter()) {
                assert!(*a < 0.15 * b, "{diff:?} after {prev:?}");
            }
        }
        assert!(diff.iter().all(|d| *d < 20.0 * eps), "{diff:?}");
    }
}

#[test]
fn uniaxial_strain_matches_the_closed_form_along_and_across_the_fibre() {
    // F = diag(s, 1, 1): E11 = (s^2 - 1) / 2 and P11 = s S11 with
    // S11 = (lambda_L + 2 mu_L) E11 along the fibre, (lambda + 2 mu) E11
    // across it and for the isotropic material.
    let iso = Isotropic::from_young_poisson(4500.0, 0.4).unwrap();
    let (l, m) = (iso.lambda_pa(), iso.mu_pa());
    let (dl, dm) = (3000.0, 2500.0);
    let cases = [
        (isotropic(), {
            let i = Material::isotropic(4500.0, 0.45, 1000.0, 0.0)
                .unwrap()
                .lame();
            i.lambda_pa() + 2.0 * i.mu_pa()
        }),
        (anisotropic(Vec3::X), l + dl + 2.0 * (m + dm)),
        (anisotropic(Vec3::Y), l + 2.0 * m),
    ];
    for s in [0.55, 0.7, 1.0, 1.5, 2.0] {
        let f = Mat3::from_diagonal(Vec3::new(s, 1.0, 1.0));
        for (el, modulus) in &cases {
            let p = first_piola(Law::Stvk, el, &f, &mut q0());
            assert_eq!(in_barrier(&f), s < STVK_BARRIER_J);
            let expect = s * modulus * (s * s - 1.0) / 2.0;
            assert!(
                (p.x_axis.x - expect).abs() <= 1e-9 * expect.abs().max(1.0),
                "s = {s}: P11 = {} expected {expect}",
                p.x_axis.x
            );
            // Through the element: the forces are -V P m_k.
            let g = tet();
            let u = affine(&g, f, Vec3::ZERO);
            let forces = element_forces(MaterialModel::Stvk, el, &g, &u, &mut q0());
            for (force, m) in forces.iter().zip(&g.shape) {
                let expect = p * *m * (-g.volume_m3);
                assert!((*force - expect).length() <= 1e-12 * expect.length().max(1e-9));
            }
        }
    }
}

#[test]
fn the_rotation_is_the_polar_one_and_proper_when_inverted() {
    let turn = Mat3::from_axis_angle(Vec3::new(0.3, -1.0, 0.4).normalize(), 2.0);
    let mut q = DQuat::IDENTITY;
    extract_rotation(&turn, &mut q);
    assert!(crate::math::max_abs(&(Mat3::from_quat(q) - turn)) < 1e-12);
    let f = turn * some_stretch();
    extract_rotation(&f, &mut q);
    let s = Mat3::from_quat(q).transpose() * f;
    assert!(
        crate::math::max_abs(&(s - s.transpose())) < 1e-11,
        "R^T F symmetric: {s}"
    );
    // Inverted: flip one axis.
    let inverted = f * Mat3::from_diagonal(Vec3::new(1.0, 1.0, -0.5));
    assert!(inverted.determinant() < 0.0);
    let mut q = DQuat::IDENTITY;
    extract_rotation(&inverted, &mut q);
    assert!((Mat3::from_quat(q).determinant() - 1.0).abs() < 1e-12);
}

#[test]
fn a_collapsed_or_inverted_element_is_pushed_back_out() {
    // Flattened (det F = 0.05), inverted, and inverted into StVK's
    // force-free mirror state (a reflection: F^T F = I; for the
    // corotational model a saddle where both rotations fit equally, so
    // only StVK's barrier is checked there).
    let g = tet();
    for (f, models) in [
        (
            Mat3::from_diagonal(Vec3::new(1.0, 1.0, 0.05)),
            &NONLINEAR[..],
        ),
        (
            Mat3::from_diagonal(Vec3::new(1.0, 1.0, -0.3)),
            &NONLINEAR[..],
        ),
        (
            Mat3::from_diagonal(Vec3::new(1.0, 1.0, -1.0)),
            &NONLINEAR[..1],
        ),
    ] {
        assert!(in_barrier(&f));
        let u = affine(&g, f, Vec3::ZERO);
        for &model in models {
            let forces = element_forces(model, &isotropic(), &g, &u, &mut q0());
            // d(volume)/d(x_k) = V0 cof(F) m_k: the forces must raise the volume.
            let cof = cofactor(&f);
            let power: Real = forces
                .iter()
                .zip(&g.shape)
                .map(|(p, m)| p.dot(cof * *m))
                .sum();
            assert!(
                power > 0.0,
                "{model:?} at {f}: the forces shrink the element ({power})"
            );
        }
    }
}
