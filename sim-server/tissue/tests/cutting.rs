//! Cutting laws: removing tetrahedra with the 10 local updates equals
//! rebuilding the model without them, and adding them back restores every
//! tensor; the explicit simulation keeps stepping through cuts.

use tissue::test_support as common;

use common::*;
use std::collections::HashMap;
use tissue::prelude::*;
use tissue::tensor_mass::CutError;

fn assert_same(name: &str, cut: &ElasticModel, fresh: &ElasticModel) {
    let tol = 1e-12 * max_entry(fresh.vertex_tensors()).max(max_entry(cut.vertex_tensors()));
    for (v, (a, b)) in cut
        .vertex_tensors()
        .iter()
        .zip(fresh.vertex_tensors())
        .enumerate()
    {
        let d = tissue::math::max_abs(&(*a - *b));
        assert!(d <= tol, "{name}: vertex {v} tensor differs by {d}");
    }
    let mass_tol = 1e-12 * fresh.masses_kg().iter().fold(0.0f64, |a, m| a.max(*m));
    for (v, (a, b)) in cut.masses_kg().iter().zip(fresh.masses_kg()).enumerate() {
        assert!((a - b).abs() <= mass_tol, "{name}: mass of {v}: {a} vs {b}");
    }
    // Edges: the fresh model only has edges of live tetrahedra; every other
    // edge of the cut model must be exactly zero (orphans are dropped).
    let fresh_edges: HashMap<_, _> = fresh
        .topology()
        .edges()
        .iter()
        .zip(fresh.edge_tensors())
        .collect();
    for (e, k) in cut.topology().edges().iter().zip(cut.edge_tensors()) {
        match fresh_edges.get(e) {
            Some(f) => {
                let d = tissue::math::max_abs(&(*k - **f));
                assert!(d <= tol, "{name}: edge {e:?} differs by {d}");
            }
            None => assert_eq!(*k, Mat3::ZERO, "{name}: orphaned edge {e:?} not zeroed"),
        }
    }
    assert_eq!(
        cut.topology().surface_len(),
        fresh.topology().surface_len(),
        "{name}: surface size"
    );
}

#[test]
fn removing_equals_rebuilding_and_restoring_gives_back_the_tensors() {
    for terms in [Terms::ALL, Terms::STRETCH] {
        let mesh = box_mesh([4, 3, 2], 0.01, 0.1, 2);
        let original = mixed_model(mesh.clone(), terms, 8);
        let mut model = original.clone();
        let mut rng = Rng::new(17);
        let mut removed = Vec::new();
        // Remove a third of the tetrahedra in random order (orphaning corner vertices and edges).
        while removed.len() < mesh.tet_count() / 3 {
            let t = TetId::from(((rng.next() + 0.5) * mesh.tet_count() as f64) as usize);
            if model.topology().is_alive(t) {
                let change = model.remove_tet(t).unwrap();
                assert_eq!(change.vertices, mesh.tets()[t.idx()]);
                removed.push(t);
            }
        }
        assert_eq!(
            model.remove_tet(removed[0]),
            Err(CutError::AlreadyRemoved(removed[0].0))
        );
        let fresh_mesh = mesh.without_tets(&removed).unwrap();
        // Rebuild from scratch with the same per-tetrahedron materials.
        let mut mats = TetMaterials::uniform(iso_material(), fresh_mesh.tet_count());
        let keep: Vec<TetId> = (0..mesh.tet_count())
            .map(TetId::from)
            .filter(|t| !removed.contains(t))
            .collect();
        let mut ids = HashMap::new();
        for (new, old) in keep.iter().enumerate() {
            let m = *original.materials().material(*old);
            let id = *ids
                .entry(format!("{m:?}"))
                .or_insert_with(|| mats.add(m).unwrap());
            mats.assign(TetId::from(new), id).unwrap();
            let f = original.materials().fiber(*old);
            if f != Vec3::ZERO {
                mats.set_fiber(TetId::from(new), f).unwrap();
            }
        }
        let fresh = ElasticModel::new(fresh_mesh, mats).unwrap();
        assert_same(&format!("{terms} after removal"), &model, &fresh);

        for t in removed.iter().rev() {
            model.restore_tet(*t).unwrap();
        }
        assert_eq!(
            model.restore_tet(removed[0]),
            Err(CutError::AlreadyPresent(removed[0].0))
        );
        assert_same(&format!("{terms} after restoring"), &model, &original);
    }
}

#[test]
fn removing_every_tetrahedron_leaves_nothing() {
    let mesh = box_mesh([2, 2, 2], 0.01, 0.0, 0);
    let mut model = ElasticModel::new(
        mesh.clone(),
        TetMaterials::uniform(iso_material(), mesh.tet_count()),
    )
    .unwrap();
    for t in 0..mesh.tet_count() {
        model.remove_tet(TetId::from(t)).unwrap();
    }
    assert!(model.vertex_tensors().iter().all(|k| *k == Mat3::ZERO));
    assert!(model.edge_tensors().iter().all(|k| *k == Mat3::ZERO));
    assert!(model.masses_kg().iter().all(|m| *m == 0.0));
    assert_eq!(model.topology().surface_len(), 0);
    assert_eq!(
        model.remove_tet(TetId(10_000)),
        Err(CutError::NoSuchTet(10_000))
    );
}

#[test]
fn simulation_steps_through_cuts_and_matches_the_model() {
    let mesh = box_mesh([6, 3, 3], 0.01, 0.1, 5);
    let model = mixed_model(mesh.clone(), Terms::ALL, 3);
    let mut sim = Explicit::<f64>::new(
        model,
        ExplicitConfig {
            threads: 2,
            ..ExplicitConfig::new(1e-4)
        },
    )
    .unwrap();
    let p = mesh.positions_m().to_vec();
    for (v, x) in p.iter().enumerate() {
        if x.x < 1e-9 {
            sim.fix(VertexId::from(v));
        } else if x.x > 0.06 - 1e-9 {
            sim.prescribe(VertexId::from(v), Vec3::new(0.0, 0.0, -2e-3));
        }
    }
    let surface0 = sim.model().topology().surface_len();
    let mut rng = Rng::new(1);
    let mut cut = 0;
    for step in 0..3000 {
        sim.step();
        if step % 20 == 0 {
            let t = TetId::from(((rng.next() + 0.5) * mesh.tet_count() as f64) as usize);
            if sim.model().topology().is_alive(t) && sim.remove_tet(t).is_ok() {
                cut += 1;
            }
        }
    }
    assert!(cut > 100);
    assert!(
        sim.model().topology().surface_len() > surface0,
        "cuts must open new faces"
    );
    let u: Vec<f64> = sim.displacements().iter().flatten().copied().collect();
    assert!(
        u.iter().all(|x| x.is_finite() && x.abs() < 0.05),
        "diverged after cutting"
    );
    // The kernel's copy equals the model's tensors after all those local updates.
    let n = sim.model().vertex_count();
    let probe: Vec<[f64; 3]> = (0..n).map(|_| rng.vec3().to_array()).collect();
    let mut ku = vec![[0.0; 3]; n];
    sim.kernel().apply(&probe, &mut ku);
    let mut f = vec![Vec3::ZERO; n];
    let pv: Vec<Vec3> = probe.iter().map(|a| Vec3::from_array(*a)).collect();
    sim.model().elastic_forces(&pv, &mut f);
    for v in 0..n {
        assert!(
            (Vec3::from_array(ku[v]) + f[v]).length()
                < 1e-12 * max_entry(sim.model().vertex_tensors())
        );
    }
}
