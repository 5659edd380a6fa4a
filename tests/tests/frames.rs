//! The `--save-frames` recorder's contents, read back by independent
//! readers: each frame's `displacement` and `elastic_force` are the state
//! handed to it and -K u of that state, a cut's tetrahedron is missing from
//! the frames after it, and the series lists the frames with their times.

use sim_server::frames::FrameRecorder;
use sim_server::prelude::*;
use system_tests::{meshio_describe, scratch_dir, vtk_describe};

#[test]
fn recorded_frames_hold_the_state_its_elastic_force_and_the_cuts() {
    let dir = scratch_dir("frames-content");
    let mesh = BoxSpec::new(Vec3::new(0.02, 0.01, 0.01), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let tissue = Material::isotropic(4500.0, 0.45, 1060.0, 5.0).unwrap();
    let materials = TetMaterials::uniform(tissue, mesh.tet_count());
    let mut model = ElasticModel::new(mesh, materials).unwrap();
    let n = model.vertex_count();
    let mut recorder = FrameRecorder::start(&dir, &model, None).unwrap();
    // Two states: a shear, then the same after a cut.
    let u: Vec<[f64; 3]> = model
        .mesh()
        .positions_m()
        .iter()
        .map(|p| [0.1 * p.z, -0.05 * p.x, 0.02 * p.y])
        .collect();
    recorder.offer(0.001, &model, &u);
    let uv: Vec<Vec3> = u.iter().map(|x| Vec3::from_array(*x)).collect();
    let mut f_before = vec![Vec3::ZERO; n];
    model.elastic_forces(&uv, &mut f_before);
    let cut = TetId::from(0);
    model.remove_tet(cut).unwrap();
    recorder.offer(0.002, &model, &u);
    let (counts, error) = recorder.finish();
    assert!(error.is_none(), "{error:?}");
    assert_eq!((counts.saved, counts.dropped), (2, 0));

    // What the frames should hold: |u| and |-K u| at their largest.
    let largest = |v: &[Vec3]| v.iter().map(|x| x.length()).fold(0.0, f64::max);
    let mut f_after = vec![Vec3::ZERO; n];
    model.elastic_forces(&uv, &mut f_after);
    let pvd = std::fs::read_to_string(dir.join("frames.pvd")).unwrap();
    assert!(
        pvd.contains("timestep=\"1e-3\"") && pvd.contains("timestep=\"2e-3\""),
        "{pvd}"
    );
    let (f0, f1) = (dir.join("frame_000000.vtu"), dir.join("frame_000001.vtu"));
    // Vertex 0's values as written, signs included (meshio gives them).
    let by_meshio = meshio_describe(&[&f0, &f1]);
    for (frame, f) in by_meshio.iter().zip([&f_before, &f_after]) {
        let first = |name: &str| -> Vec<f64> {
            frame["point_data"][name]["first"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        assert_eq!(first("displacement"), u[0].to_vec(), "{frame}");
        assert_eq!(first("elastic_force"), f[0].to_array().to_vec(), "{frame}");
    }
    for seen in [by_meshio, vtk_describe(&[&f0, &f1])] {
        let (before, after) = (&seen[0], &seen[1]);
        let tets = model.mesh().tet_count() as u64;
        assert_eq!(before["tetrahedra"], tets, "{before}");
        assert_eq!(after["tetrahedra"], tets - 1, "the cut shows: {after}");
        let u_max = after["point_data"]["displacement"]["max_norm"]
            .as_f64()
            .unwrap();
        assert!(
            (u_max - largest(&uv)).abs() <= 1e-12 * largest(&uv),
            "{after}"
        );
        // -K u of the tensors of the moment: before and after the cut.
        for (frame, f) in [(before, &f_before), (after, &f_after)] {
            let got = frame["point_data"]["elastic_force"]["max_norm"]
                .as_f64()
                .unwrap();
            assert!(
                got > 0.0 && (got - largest(f)).abs() <= 1e-9 * largest(f),
                "{got} vs {}",
                largest(f)
            );
        }
    }
}

/// A run whose elements turn corotational while it runs (`[contact]
/// corotational_radius_m`) records no `elastic_force`: -K u is not the
/// force there. The same recorder without the switch writes it.
#[test]
fn a_recorder_without_forces_writes_no_elastic_force() {
    let mesh = BoxSpec::new(Vec3::new(0.01, 0.01, 0.01), CellSize::EdgeM(0.005))
        .generate()
        .unwrap();
    let tissue = Material::isotropic(4500.0, 0.45, 1060.0, 5.0).unwrap();
    let materials = TetMaterials::uniform(tissue, mesh.tet_count());
    let model = ElasticModel::new(mesh, materials).unwrap();
    let u = vec![[1e-4, 0.0, 0.0]; model.vertex_count()];
    for (name, without) in [("frames-forces", false), ("frames-no-forces", true)] {
        let dir = scratch_dir(name);
        let recorder = FrameRecorder::start(&dir, &model, None).unwrap();
        let mut recorder = if without {
            recorder.without_forces()
        } else {
            recorder
        };
        recorder.offer(0.001, &model, &u);
        let (counts, error) = recorder.finish();
        assert!(error.is_none() && counts.saved == 1, "{error:?}");
        let vtu = std::fs::read(dir.join("frame_000000.vtu")).unwrap();
        let text = String::from_utf8_lossy(&vtu);
        assert_eq!(text.contains("elastic_force"), !without, "{name}");
        assert!(text.contains("displacement"), "{name}");
    }
}
