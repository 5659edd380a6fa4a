//! Multirate stepping (`tensor_mass/explicit/multirate.rs`): on a block
//! refined in one corner the refined cells' vertices are sub-stepped at
//! their short step and the rest at a longer one; the motion equals one
//! step for all to within the interpolation's error, the energy of an
//! undamped block stays bounded, contact-free rigid motion stays force
//! free, and what cannot be partitioned is refused with the reason.

use tissue::mesh::refine;
use tissue::prelude::*;
use tissue::tensor_mass::{DtPolicy, MultirateError};

/// An 80 x 40 x 20 mm block of 5 mm cells refined to 2.5 mm within 4 mm
/// of a point on its top face: the few refined cells set the step.
fn refined_block(damping: f64) -> ElasticModel {
    let coarse = BoxSpec::new(Vec3::new(0.08, 0.04, 0.02), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let centre = Vec3::new(0.02, 0.02, 0.02);
    let refined = refine::refine(&coarse, 200_000, |_, p| {
        let c = (p[0] + p[1] + p[2] + p[3]) * 0.25;
        (c.distance(centre) < 0.004).then_some(0.0025)
    })
    .unwrap();
    let mesh = refined.mesh;
    let tissue = Material::isotropic(5000.0, 0.45, 1000.0, damping).unwrap();
    let materials = TetMaterials::uniform(tissue, mesh.tet_count());
    ElasticModel::new(mesh, materials).unwrap()
}

/// The block with its bottom fixed, stepping at 2 ms.
fn sim(model: &ElasticModel, multirate: bool) -> Explicit<f64> {
    let mut sim = Explicit::<f64>::new(model.clone(), ExplicitConfig::new(2e-3)).unwrap();
    for (v, p) in model.mesh().positions_m().iter().enumerate() {
        if p.z < 1e-9 {
            sim.fix(VertexId::from(v));
        }
    }
    if multirate {
        let report = sim.set_multirate(true).unwrap().unwrap();
        assert!(report.engaged, "{report:?}");
    }
    sim
}

/// A smooth bending of the block (m), zero at its fixed bottom.
fn bent(model: &ElasticModel) -> Vec<Vec3> {
    model
        .mesh()
        .positions_m()
        .iter()
        .map(|p| Vec3::new(0.05 * p.z * p.z / 0.02, 0.0, -0.02 * p.z * p.x))
        .collect()
}

fn max_norm(u: &[Vec3]) -> f64 {
    u.iter().map(|d| d.length()).fold(0.0, f64::max)
}

fn displacements(sim: &Explicit<f64>, n: usize) -> Vec<Vec3> {
    (0..n)
        .map(|v| sim.displacement(VertexId::from(v)))
        .collect()
}

#[test]
fn the_refined_vertices_are_sub_stepped_and_the_rest_keeps_a_longer_step() {
    let model = refined_block(30.0);
    let uniform = sim(&model, false);
    let mut multi = sim(&model, false);
    let report = multi.set_multirate(true).unwrap().unwrap();
    assert!(report.engaged, "{report:?}");
    // The fine count is one step for all's, rounded to a whole multiple
    // of a coarse count that is smaller.
    assert!(report.coarse_substeps < report.fine_substeps, "{report:?}");
    assert_eq!(report.fine_substeps % report.coarse_substeps, 0);
    assert!(report.fine_substeps >= uniform.substeps(), "{report:?}");
    assert!(
        report.fine_substeps < uniform.substeps() + report.coarse_substeps,
        "{report:?} against {}",
        uniform.substeps()
    );
    // Few of the vertices are fast: the refined corner and a ring round it.
    assert!(report.fast_vertices * 2 < report.vertices, "{report:?}");
    assert!(report.interface_vertices > 0);
    // Off again: one step for all.
    multi.set_multirate(false).unwrap();
    assert_eq!(multi.substeps(), uniform.substeps());
    assert_eq!(multi.multirate(), None);
}

/// The largest distance between the two integrations over the sampled
/// steps of a release from the bent state, each sub-stepped `factor`
/// times finer than stability needs, and the swing.
fn multirate_against_uniform(model: &ElasticModel, factor: usize) -> (f64, f64) {
    let n = model.mesh().vertex_count();
    let start = bent(model);
    let mut runs = Vec::new();
    for multirate in [false, true] {
        let mut s = sim(model, multirate);
        s.set_substep_factor(factor);
        s.set_state(&start, &start);
        let mut path = Vec::new();
        for step in 0..150 {
            s.step();
            if step % 10 == 9 {
                path.push(displacements(&s, n));
            }
        }
        runs.push(path);
    }
    // It did move (the comparison is not of two resting blocks).
    let moved = runs[0][0]
        .iter()
        .zip(&start)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f64::max);
    assert!(moved > 0.1 * max_norm(&start));
    let worst = runs[0]
        .iter()
        .zip(&runs[1])
        .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| x.distance(*y)))
        .fold(0.0, f64::max);
    (worst, max_norm(&start))
}

#[test]
fn the_motion_converges_to_one_step_for_all() {
    let model = refined_block(30.0);
    // The slow vertices step at a longer step than one step for all's,
    // so the two differ by central differences' own second-order error at
    // that step and by the interpolation of the slow neighbours: a few per
    // cent of the swing, converging faster than first order as every step
    // is halved (measured: 1.30% of the swing, then 0.37x of it).
    let (coarse, swing) = multirate_against_uniform(&model, 1);
    let (fine, _) = multirate_against_uniform(&model, 2);
    assert!(
        coarse < 0.03 * swing,
        "{coarse:e} m apart, swing {swing:e} m"
    );
    assert!(
        fine < 0.5 * coarse,
        "halving the steps took the difference from {coarse:e} to {fine:e} m"
    );
}

#[test]
fn an_undamped_block_keeps_its_energy() {
    let model = refined_block(0.0);
    let start = bent(&model);
    let mut s = sim(&model, true);
    s.set_state(&start, &start);
    let e0 = s.energy_j();
    assert!(e0 > 0.0);
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for step in 0..3000 {
        s.step();
        if step % 5 == 0 {
            let e = s.energy_j();
            lo = lo.min(e);
            hi = hi.max(e);
        }
    }
    // Central differences keep a nearby energy, not this one exactly: the
    // measured one oscillates by a few per cent and must not drift.
    assert!(
        hi < 1.1 * e0 && lo > 0.8 * e0,
        "energy {lo:e} .. {hi:e} J from {e0:e} J over 3000 steps"
    );
}

#[test]
fn a_rigid_translation_stays_force_free() {
    let model = refined_block(30.0);
    let mut s = Explicit::<f64>::new(model.clone(), ExplicitConfig::new(2e-3)).unwrap();
    assert!(s.set_multirate(true).unwrap().unwrap().engaged);
    let shift = vec![Vec3::new(1e-3, -2e-3, 5e-4); model.mesh().vertex_count()];
    s.set_state(&shift, &shift);
    for _ in 0..50 {
        s.step();
    }
    let n = model.mesh().vertex_count();
    for (v, d) in displacements(&s, n).iter().enumerate() {
        assert!(d.distance(shift[v]) < 1e-12, "vertex {v} moved to {d:?}");
    }
}

#[test]
fn a_uniform_mesh_does_not_engage_and_an_unchecked_step_is_refused() {
    let coarse = BoxSpec::new(Vec3::new(0.04, 0.02, 0.02), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let tissue = Material::isotropic(5000.0, 0.45, 1000.0, 30.0).unwrap();
    let materials = TetMaterials::uniform(tissue, coarse.tet_count());
    let model = ElasticModel::new(coarse, materials).unwrap();
    let mut s = Explicit::<f64>::new(model.clone(), ExplicitConfig::new(2e-3)).unwrap();
    let before = s.substeps();
    let report = s.set_multirate(true).unwrap().unwrap();
    assert!(!report.engaged, "{report:?}");
    assert_eq!(s.substeps(), before);
    let mut unchecked = Explicit::<f64>::new(
        model,
        ExplicitConfig {
            policy: DtPolicy::Unchecked,
            ..ExplicitConfig::new(2e-3)
        },
    )
    .unwrap();
    let err = unchecked.set_multirate(true).unwrap_err();
    assert_eq!(err, MultirateError::Unchecked);
    assert!(err.to_string().contains("substep"), "{err}");
}
