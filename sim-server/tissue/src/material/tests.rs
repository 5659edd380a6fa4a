//! Material laws: construction, refusals with the admissible range, and the
//! engineering constants against the compliance.

use super::*;

fn liver() -> Isotropic {
    Isotropic::from_young_poisson(4500.0, 0.45).unwrap()
}

#[test]
fn young_poisson_round_trip() {
    let m = liver();
    assert!((m.young_pa() - 4500.0).abs() < 1e-9);
    assert!((m.poisson() - 0.45).abs() < 1e-12);
    assert!(Isotropic::from_young_poisson(1.0, 0.5).is_err());
    assert!(Isotropic::from_young_poisson(-1.0, 0.3).is_err());
    // lambda must exceed -2 mu / 3 = -0.8 Pa for mu = 1.2 Pa.
    assert!(Isotropic::from_lame(-0.79, 1.2).is_ok());
    let e = Isotropic::from_lame(-0.81, 1.2).unwrap_err().to_string();
    assert!(e.contains("-0.8"), "{e}");
}

#[test]
fn refusals_name_the_admissible_range() {
    let t = liver();
    let err = TransverselyIsotropic::new(t, 0.0, -2.0 * t.mu_pa(), Terms::ALL).unwrap_err();
    assert!(err.to_string().contains("must exceed"), "{err}");
    let err = TransverselyIsotropic::new(t, 1e9, 0.0, Terms::ALL).unwrap_err();
    let MaterialError::DeltaLambda { min_pa, max_pa, .. } = err else {
        panic!("{err}")
    };
    // Just inside the interval is accepted, just outside refused.
    let inside = min_pa + 1e-6 * (max_pa - min_pa);
    assert!(TransverselyIsotropic::new(t, inside, 0.0, Terms::ALL).is_ok());
    assert!(TransverselyIsotropic::new(t, max_pa * 1.0001, 0.0, Terms::ALL).is_err());
    assert!(TransverselyIsotropic::new(t, min_pa - 1e-3 * min_pa.abs(), 0.0, Terms::ALL).is_err());
}

/// The interval from the closed form agrees with a direct eigen check of
/// the Voigt matrix, for every subset of terms.
#[test]
fn pd_interval_matches_voigt_eigenvalues() {
    let t = liver();
    for bits in 1..8u8 {
        let terms = Terms {
            stretch: bits & 1 != 0,
            cross: bits & 2 != 0,
            shear: bits & 4 != 0,
        };
        for dm in [-0.5 * t.mu_pa(), 0.0, 3.0 * t.mu_pa()] {
            for k in -40..=40 {
                let dl = k as Real * 2000.0;
                let accepted = TransverselyIsotropic::new(t, dl, dm, terms).is_ok();
                let c = TransverselyIsotropic {
                    transverse: t,
                    delta_lambda_pa: dl,
                    delta_mu_pa: dm,
                    terms,
                }
                .voigt_fiber_z();
                let m = nalgebra::Matrix6::from_fn(|i, j| c[i][j]);
                let min_eig = m.symmetric_eigen().eigenvalues.min();
                let pd = min_eig > 1e-9 * t.mu_pa();
                if (min_eig.abs() > 1e-6 * t.mu_pa()) || accepted == pd {
                    assert_eq!(
                        accepted, pd,
                        "terms {terms} dl {dl} dm {dm}: min eig {min_eig}"
                    );
                }
            }
        }
    }
}

#[test]
fn engineering_constants_round_trip() {
    for t in [liver(), Isotropic::from_young_poisson(4500.0, 0.3).unwrap()] {
        let mu = t.mu_pa();
        for (dl, dm) in [
            (0.0, mu),
            (-0.2 * mu, 3.0 * mu),
            (0.5 * mu, -0.3 * mu),
            (2.0 * mu, 0.0),
        ] {
            let Ok(m) = TransverselyIsotropic::new(t, dl, dm, Terms::ALL) else {
                continue;
            };
            let eng = m.engineering();
            let back =
                TransverselyIsotropic::from_engineering(t, eng.young_fiber_pa, eng.shear_fiber_pa)
                    .unwrap_or_else(|e| panic!("{eng:?}: {e}"));
            let again = back.engineering();
            assert!((again.young_fiber_pa - eng.young_fiber_pa).abs() < 1e-8 * eng.young_fiber_pa);
            assert!((again.shear_fiber_pa - eng.shear_fiber_pa).abs() < 1e-9 * eng.shear_fiber_pa);
            // The paper's closed forms agree with the compliance.
            let (l, dl, dm) = (t.lambda_pa(), m.delta_lambda_pa(), m.delta_mu_pa());
            let nu_lt = (l + dl) / (2.0 * (l + mu));
            assert!((eng.poisson_fiber_transverse - nu_lt).abs() < 1e-12);
            let e_l = t.young_pa() + 2.0 * dm - dl * (dl + l - mu) / (l + mu);
            assert!((eng.young_fiber_pa - e_l).abs() < 1e-9 * e_l);
        }
    }
    // A fibre three times stiffer with twice the shear is out of reach of
    // the 4-parameter model when the transverse plane is nearly
    // incompressible (C33 - C13 = 2 C44 ties them): refused with the range.
    let err = TransverselyIsotropic::from_engineering(liver(), 13500.0, 3104.0).unwrap_err();
    let MaterialError::Engineering { max_pa, .. } = err else {
        panic!("{err}")
    };
    assert!(
        max_pa < 13500.0 && err.to_string().contains("must lie in"),
        "{err}"
    );
    assert!(TransverselyIsotropic::from_engineering(liver(), 0.99 * max_pa, 3104.0).is_ok());
}

#[test]
fn density_and_damping_checked() {
    assert!(Material::isotropic(4500.0, 0.45, 0.0, 1.0).is_err());
    assert!(Material::isotropic(4500.0, 0.45, 1060.0, -1.0).is_err());
    assert!(Material::isotropic(4500.0, 0.45, 1060.0, 0.0).is_ok());
}
