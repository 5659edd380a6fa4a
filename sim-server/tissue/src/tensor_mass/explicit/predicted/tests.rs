//! [`Explicit::prepare_step`]: the step computed ahead (the whole step
//! without the tools on a linear model, see `predicted`) changes nothing
//! in the step, what changes constraints or loads between the two is
//! recomputed where it acts, and what changes the model or the state
//! discards it.

use crate::ids::{TetId, VertexId};
use crate::material::{Elasticity, Isotropic, Material};
use crate::material_map::TetMaterials;
use crate::math::Vec3;
use crate::mesh::{BoxSpec, CellSize};
use crate::tensor_mass::*;

/// A 2 x 1 x 1 cm block held at x = 0, pulled and pushed at x = 2 cm,
/// stepped at 3 ms (several sub-steps).
fn block<S: Storage>() -> Explicit<S> {
    block_at(3e-3)
}

/// [`block`] stepping `dt_s` at a time.
fn block_at<S: Storage>(dt_s: f64) -> Explicit<S> {
    let mesh = BoxSpec::new(Vec3::new(0.02, 0.01, 0.01), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let iso = Isotropic::from_young_poisson(4500.0, 0.4).unwrap();
    let material = Material::new(Elasticity::Isotropic(iso), 1000.0, 5.0).unwrap();
    let mats = TetMaterials::uniform(material, mesh.tet_count());
    let model = ElasticModel::new(mesh, mats).unwrap();
    let rest: Vec<Vec3> = model.mesh().positions_m().to_vec();
    let mut sim = Explicit::<S>::new(model, ExplicitConfig::new(dt_s)).unwrap();
    assert!(sim.substeps() > 1, "the test wants several sub-steps");
    for (v, x) in rest.iter().enumerate() {
        if x.x < 1e-9 {
            sim.fix(VertexId::from(v));
        } else if x.x > 0.02 - 1e-9 {
            sim.set_external_force(VertexId::from(v), Vec3::new(0.002, -0.001, -0.003));
        }
    }
    sim
}

fn same<S: Storage>(a: &Explicit<S>, b: &Explicit<S>, when: &str) {
    let bits = |s: &Explicit<S>| -> Vec<u64> {
        s.displacements()
            .iter()
            .flatten()
            .map(|x| x.to_bits())
            .collect()
    };
    assert!(bits(a) == bits(b), "states differ {when}");
    let moved = a.displacements().iter().flatten().any(|x| *x != 0.0);
    assert!(moved, "nothing moved {when}: the comparison would be empty");
}

fn prepared_steps_equal_plain_ones<S: Storage>() {
    let (mut plain, mut prepared) = (block::<S>(), block::<S>());
    for k in 0..20 {
        plain.step();
        prepared.prepare_step();
        prepared.step();
        same(&plain, &prepared, &format!("after step {k}"));
    }
    // A cut after the preparation: the step uses the new kernel.
    prepared.prepare_step();
    for sim in [&mut plain, &mut prepared] {
        sim.remove_tet(TetId(5)).unwrap();
        sim.step();
    }
    same(&plain, &prepared, "after a cut");
    // The cut's rows were recomputed; the rest of the prediction served.
    assert_eq!(prepared.predicted_steps(), 21);
    // A new state after the preparation: K U of the new state.
    prepared.prepare_step();
    let u: Vec<Vec3> = plain
        .displacements()
        .iter()
        .map(|d| Vec3::from_array(*d) * 0.5)
        .collect();
    for sim in [&mut plain, &mut prepared] {
        sim.set_state(&u, &u);
        sim.step();
    }
    same(&plain, &prepared, "after set_state");
    assert_eq!(prepared.predicted_steps(), 21, "a new state discards it");
    // Preparing twice is preparing once.
    prepared.prepare_step();
    prepared.prepare_step();
    plain.step();
    prepared.step();
    same(&plain, &prepared, "after a double preparation");
}

#[test]
fn a_prepared_step_is_the_plain_step_to_the_bit() {
    prepared_steps_equal_plain_ones::<f32>();
    prepared_steps_equal_plain_ones::<f64>();
}

#[test]
fn a_preparation_the_step_does_not_use_is_forgotten() {
    // Prepared, then not used for the step it was for (a cut): the next
    // step must not pick up the stale K U.
    let (mut plain, mut prepared) = (block::<f32>(), block::<f32>());
    for sim in [&mut plain, &mut prepared] {
        sim.step();
    }
    prepared.prepare_step();
    for sim in [&mut plain, &mut prepared] {
        sim.remove_tet(TetId(9)).unwrap();
        sim.step();
        sim.step();
    }
    same(&plain, &prepared, "two steps after the cut");
}

#[test]
fn constraints_and_loads_changed_after_the_preparation_count() {
    check_changes::<f32>();
    check_changes::<f64>();
}

/// Between the preparation and the step (as a tool's update does): a load
/// changed, a vertex prescribed and moved each step, one released, one
/// fixed; the prepared block follows the plain one to the bit.
fn check_changes<S: Storage>() {
    let (mut plain, mut prepared) = (block::<S>(), block::<S>());
    let rest: Vec<Vec3> = plain.model().mesh().positions_m().to_vec();
    let inner = (0..rest.len())
        .filter(|&v| rest[v].x > 0.004 && rest[v].x < 0.016)
        .map(VertexId::from)
        .collect::<Vec<_>>();
    let (held, freed, loaded) = (inner[0], inner[inner.len() / 2], inner[inner.len() - 1]);
    for k in 0..40 {
        prepared.prepare_step();
        let kf = k as f64;
        for sim in [&mut plain, &mut prepared] {
            sim.set_external_force(loaded, Vec3::new(0.0, 1e-3 * (0.3 * kf).sin(), 0.0));
            if k >= 5 {
                sim.prescribe(held, Vec3::new(0.0, 0.0, 2e-5 * kf));
            }
            if k == 10 {
                sim.fix(freed);
            }
            if k == 25 {
                sim.release(freed);
            }
            sim.step();
        }
        same(&plain, &prepared, &format!("after step {k}"));
    }
    assert_eq!(prepared.predicted_steps(), 40);
    assert_eq!(plain.predicted_steps(), 0);
}

#[test]
fn many_sub_steps_compute_only_the_first_ahead() {
    // Above PREDICTED_SUBSTEPS_MAX whole passes a step is not predicted
    // (its correction would reach most of the mesh): the first sub-step's
    // K U is, and the step is unchanged.
    let (mut plain, mut prepared) = (block_at::<f32>(0.03), block_at::<f32>(0.03));
    assert!(prepared.substeps() > crate::tensor_mass::explicit::PREDICTED_SUBSTEPS_MAX);
    for k in 0..10 {
        plain.step();
        prepared.prepare_step();
        prepared.step();
        same(&plain, &prepared, &format!("after step {k}"));
    }
    assert_eq!(prepared.predicted_steps(), 0);
}

/// An 80 x 40 x 20 mm block of 5 mm cells refined to 2.5 mm within 4 mm of
/// a point on its top, bottom fixed, stepped at 2 ms with multirate
/// stepping engaged (the refined cells' vertices fast).
fn multirate_block<S: Storage>() -> Explicit<S> {
    let coarse = BoxSpec::new(Vec3::new(0.08, 0.04, 0.02), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let centre = Vec3::new(0.02, 0.02, 0.02);
    let refined = crate::mesh::refine::refine(&coarse, 100_000, |_, p| {
        let c = (p[0] + p[1] + p[2] + p[3]) * 0.25;
        (c.distance(centre) < 0.004).then_some(0.0025)
    })
    .unwrap();
    let mesh = refined.mesh;
    let mats = TetMaterials::uniform(
        Material::isotropic(5000.0, 0.45, 1000.0, 20.0).unwrap(),
        mesh.tet_count(),
    );
    let model = ElasticModel::new(mesh, mats).unwrap();
    let rest: Vec<Vec3> = model.mesh().positions_m().to_vec();
    let mut sim = Explicit::<S>::new(model, ExplicitConfig::new(2e-3)).unwrap();
    for (v, x) in rest.iter().enumerate() {
        if x.z < 1e-9 {
            sim.fix(VertexId::from(v));
        }
    }
    let report = sim.set_multirate(true).unwrap().unwrap();
    assert!(report.engaged, "{report:?}");
    assert!(report.coarse_substeps < report.fine_substeps, "{report:?}");
    sim
}

/// With multirate stepping the prediction is the multirate step: loads
/// and a prescribed vertex changed after it, in the fast region and in
/// the slow one, are recomputed where they act, to the bit, and the
/// correction stays far below whole passes.
/// With `defer`, the far rows are finished after each step.
fn multirate_prediction_is_the_plain_step<S: Storage>(defer: bool) {
    let (mut plain, mut prepared) = (multirate_block::<S>(), multirate_block::<S>());
    prepared.defer_far_rows(defer);
    let rest: Vec<Vec3> = plain.model().mesh().positions_m().to_vec();
    let near = |c: Vec3| {
        (0..rest.len())
            .min_by(|&a, &b| rest[a].distance(c).total_cmp(&rest[b].distance(c)))
            .map(VertexId::from)
            .unwrap()
    };
    // Under the refined spot (fast), and a coarse corner far from it (slow).
    let (pressed, far) = (
        near(Vec3::new(0.02, 0.02, 0.02)),
        near(Vec3::new(0.07, 0.0, 0.02)),
    );
    let loaded = near(Vec3::new(0.022, 0.021, 0.02));
    for k in 0..40 {
        prepared.prepare_step();
        let kf = k as f64;
        for sim in [&mut plain, &mut prepared] {
            sim.set_external_force(loaded, Vec3::new(0.0, 0.0, -2e-3 * (0.2 * kf).sin()));
            sim.set_external_force(far, Vec3::new(1e-3 * (0.3 * kf).cos(), 0.0, 0.0));
            if k >= 5 {
                sim.prescribe(pressed, Vec3::new(0.0, 0.0, -2e-5 * kf));
            }
            sim.step();
        }
        prepared.finish_step();
        same(&plain, &prepared, &format!("after step {k}"));
    }
    assert_eq!(prepared.predicted_steps(), 40);
    let full = 40 * (prepared.substeps() * rest.len()) as u64;
    assert!(
        prepared.predicted_rows() * 2 < full,
        "{} rows recomputed against {full} in whole passes",
        prepared.predicted_rows()
    );
}

#[test]
fn a_prepared_multirate_step_is_the_plain_one_to_the_bit() {
    for defer in [false, true] {
        multirate_prediction_is_the_plain_step::<f32>(defer);
        multirate_prediction_is_the_plain_step::<f64>(defer);
    }
}
