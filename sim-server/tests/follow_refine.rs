//! `[contact] refine_radius_m`: the cells round a tool refined while it is
//! there and coarsened back when it leaves (`sim_server::follow_refine`).
//! A probe presses into a box of 5 mm cells, slides 20 mm and lifts off:
//! the mesh follows it (made again several times), is the scene's own mesh
//! again once the probe has left, the state crosses each new mesh without
//! a jump (shared vertices keep their displacement and velocity), and the
//! force on the slide is the one of a box refined along the whole path at
//! load. Bad keys are refused at their line.

use sim_server::contact::ToolInput;
use sim_server::follow_refine::FollowRefine;
use sim_server::ids::VertexId;
use sim_server::math::Vec3;
use sim_server::prepare::{Prepared, prepare};
use sim_server::scene::{SceneSource, build_scene};
use sim_server::tensor_mass::Explicit;

/// The soft box of the slide measurements (tests/data/box-probe-soft.toml:
/// 60 x 40 x 20 mm of 5 mm cells, E 3 kPa, bottom fixed, a 2.5 mm probe)
/// with `extra` after it.
fn source(extra: &str) -> SceneSource {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/box-probe-soft.toml"
    );
    let base = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    SceneSource {
        name: "follow.toml".into(),
        dir: std::path::PathBuf::from("."),
        text: format!("{base}\n{extra}\n"),
    }
}

/// The probe's tip this step of the path: down to 5 mm deep at x = 20 mm,
/// along x to 40 mm, up and away (1 ms steps).
fn tip(step: usize) -> Vec3 {
    let top = 0.02 + 0.0025;
    let (down, slide, up) = (300, 1000, 300);
    let t = step as f64;
    if step < down {
        Vec3::new(0.02, 0.02, top + 0.002 - 0.007 * t / down as f64)
    } else if step < down + slide {
        let s = (t - down as f64) / slide as f64;
        Vec3::new(0.02 + 0.02 * s, 0.02, top - 0.005)
    } else {
        let s = ((t - (down + slide) as f64) / up as f64).min(1.0);
        Vec3::new(0.04, 0.02, top - 0.005 + 0.04 * s)
    }
}

const STEPS: usize = 1700;

fn press(p: &mut Prepared<Explicit<f64>>, step: usize) -> Vec3 {
    let input = [Some(ToolInput {
        tip_m: tip(step),
        jaw_opening: 1.0,
    })];
    p.tools.update(&mut p.sim, &input);
    p.tools.step(&mut p.sim);
    p.tools.reaction(0, &p.sim).force_n
}

#[test]
fn the_mesh_follows_the_probe_and_coarsens_back_when_it_leaves() {
    let src = source("[contact]\nrefine_radius_m = 0.008\n");
    let mut scene = build_scene(&src, &src.parse().unwrap()).unwrap();
    let base_tets = scene.model.mesh().tet_count();
    let mut follow = FollowRefine::new(&src, &mut scene)
        .unwrap()
        .expect("asked for");
    let mut p = prepare::<f64>(scene, Some(1e-3)).unwrap();
    let mut most = 0;
    let mut forces = Vec::new();
    for step in 0..STEPS {
        forces.push(press(&mut p, step));
        let (u, v): (Vec<Vec3>, Vec<Vec3>) = (0..p.sim.model().vertex_count())
            .map(|k| {
                let k = VertexId::from(k);
                (p.sim.displacement(k), p.sim.velocity(k))
            })
            .unzip();
        let rest: Vec<Vec3> = p.sim.model().mesh().positions_m().to_vec();
        if follow.follow(&mut p, 1e-3, |_| {}).unwrap() {
            // Every vertex of the old mesh the new one keeps moves on with
            // its own displacement and velocity, bit for bit and to
            // round-off of the sub-step.
            let at: std::collections::HashMap<[u64; 3], usize> = (rest.iter().enumerate())
                .map(|(k, x)| (x.to_array().map(f64::to_bits), k))
                .collect();
            let new_rest = p.sim.model().mesh().positions_m();
            let mut shared = 0;
            for (k, x) in new_rest.iter().enumerate() {
                if let Some(&o) = at.get(&x.to_array().map(f64::to_bits)) {
                    let k = VertexId::from(k);
                    assert_eq!(p.sim.displacement(k), u[o]);
                    assert!((p.sim.velocity(k) - v[o]).length() <= 1e-9 * (1.0 + v[o].length()));
                    shared += 1;
                }
            }
            assert!(shared > base_tets / 6, "{shared} vertices shared");
        }
        most = most.max(p.sim.model().mesh().tet_count());
        if (400..1300).contains(&step) {
            // On the slide: a sphere is refined round the material under
            // the tip, every cell touching it of the probe's radius at most.
            let c = follow.centres()[0].expect("the probe touches");
            assert!(
                (c.x - tip(step).x).abs() < 0.25 * 0.008 + 0.002,
                "step {step}: {c}"
            );
            let mesh = p.sim.model().mesh();
            for t in 0..mesh.tet_count() {
                let q = mesh.tet_points(sim_server::ids::TetId::from(t));
                let lo = q.iter().fold(q[0], |a, b| a.min(*b));
                let hi = q.iter().fold(q[0], |a, b| a.max(*b));
                if c.clamp(lo, hi).distance(c) <= 0.008 {
                    let h = sim_server::mesh::refine::cell_size_m(&q);
                    assert!(
                        h <= 0.0025 * (1.0 + 1e-9),
                        "step {step}: cell {h} m at {lo}"
                    );
                }
            }
        }
        assert!(forces[step].is_finite(), "step {step}");
    }
    let r = follow.report().clone();
    // Refined while the probe touched, several times along the slide
    // (20 mm at a quarter of 8 mm between two meshes).
    assert!(most > base_tets, "{most} against {base_tets}");
    assert!(r.rebuilds >= 8, "{r:?}");
    assert_eq!(r.most_tets, most);
    // Gone: the scene's own mesh again.
    assert_eq!(p.sim.model().mesh().tet_count(), base_tets, "{r:?}");
    assert_eq!(r.spheres, 0);
    assert!(r.pinned.is_none() && !r.stopped_at_budget);

    // The same path on the box refined at load along all of it: the force
    // the follower gives on the slide is the one of cells that fine
    // everywhere the probe goes.
    let fixed = source(
        "[[refine]]\nselect = { box_m = [[0.012, 0.012, 0.0], [0.048, 0.028, 0.021]] }\ncell_m = 0.0025\n",
    );
    let mut q = prepare::<f64>(
        build_scene(&fixed, &fixed.parse().unwrap()).unwrap(),
        Some(1e-3),
    )
    .unwrap();
    let reference: Vec<Vec3> = (0..STEPS).map(|step| press(&mut q, step)).collect();
    let slide = 500..1300;
    let mean = |f: &[Vec3]| f.iter().map(|x| x.z).sum::<f64>() / f.len() as f64;
    let (a, b) = (
        mean(&forces[slide.clone()]),
        mean(&reference[slide.clone()]),
    );
    assert!(b > 0.01, "reference {b} N");
    assert!(
        (a - b).abs() < 0.05 * b,
        "slide mean {a} N against {b} N refined at load"
    );
    // No snap where the mesh changes: the largest step-to-step change on
    // the slide is not larger than the reference's by more than half.
    let jump = |f: &[Vec3]| {
        (f[slide.clone()].windows(2))
            .map(|w| (w[1] - w[0]).length())
            .fold(0.0, f64::max)
    };
    let (ja, jb) = (jump(&forces), jump(&reference));
    assert!(
        ja <= 1.5 * jb + 1e-4,
        "largest change {ja} N against {jb} N"
    );
}

#[test]
fn the_keys_are_checked_at_their_line() {
    let refused_src = |src: SceneSource, says: &str| {
        let e = build_scene(&src, &src.parse().unwrap())
            .err()
            .map(|e| e.to_string());
        let e = e.unwrap_or_else(|| panic!("{} was accepted", src.text));
        assert!(e.contains(says), "{e}");
        assert!(e.starts_with("follow.toml:"), "{e}");
    };
    let refused = |extra: &str, says: &str| refused_src(source(extra), says);
    refused("[contact]\nrefine_radius_m = -0.01\n", "refine_radius_m");
    refused(
        "[contact]\nrefine_cell_m = 0.001\n",
        "give refine_radius_m too",
    );
    refused(
        "[contact]\nrefine_radius_m = 0.01\nlaw = \"projection\"\n",
        "penalty law",
    );
    let mut implicit = source("[contact]\nrefine_radius_m = 0.01\n");
    implicit.text = implicit
        .text
        .replace("[simulation]", "[simulation]\nbackend = \"implicit\"");
    refused_src(implicit, "tensor-mass backend");
    refused(
        "[contact]\nrefine_radius_m = 0.01\nrefine_max_tets = 0\n",
        "refine_max_tets",
    );
    // Asked for nothing: nothing kept.
    let src = source("");
    let mut scene = build_scene(&src, &src.parse().unwrap()).unwrap();
    assert!(FollowRefine::new(&src, &mut scene).unwrap().is_none());
}

/// A budget below what the sphere needs: the mesh is refined as far as it
/// allows, conforming, and the report says so.
#[test]
fn a_budget_stops_the_refinement_and_is_reported() {
    let src = source("[contact]\nrefine_radius_m = 0.01\nrefine_max_tets = 3000\n");
    let mut scene = build_scene(&src, &src.parse().unwrap()).unwrap();
    let mut follow = FollowRefine::new(&src, &mut scene).unwrap().unwrap();
    let mut p = prepare::<f64>(scene, Some(1e-3)).unwrap();
    for step in 0..400 {
        press(&mut p, step);
        follow.follow(&mut p, 1e-3, |_| {}).unwrap();
    }
    let r = follow.report();
    assert!(r.stopped_at_budget, "{r:?}");
    assert!(r.most_tets <= 3000 && r.rebuilds >= 1, "{r:?}");
}
