//! The penalty contact on the precomputed (static) backend: the same
//! static forces as the explicit backend settled, a probe over a cell's
//! centre feels the tissue (the projection law misses it), the law is the
//! scene's choice there (penalty by default), and friction is refused.

use sim_server::backend::{Backend, Precomputed};
use sim_server::contact::{ContactError, ContactLaw, StiffnessSolves, ToolInput};
use sim_server::prelude::*;
use sim_server::prepare::{PrepareError, Prepared, prepare, prepare_with};
use sim_server::scene::{BuiltScene, SceneSource, build_scene};
use std::path::PathBuf;

/// A 24 x 24 x 20 mm block on `cell_m` cells, bottom fixed, a 2.5 mm probe
/// over (x, y); `extra` appended.
fn block(cell_m: f64, x: f64, y: f64, extra: &str) -> BuiltScene {
    probe_block(cell_m, x, y, 0.0025, extra)
}

/// [`block`] with a probe of radius `radius_m`.
fn probe_block(cell_m: f64, x: f64, y: f64, radius_m: f64, extra: &str) -> BuiltScene {
    let text = format!(
        r#"
[mesh]
generate = {{ shape = "box", size_m = [0.024, 0.024, 0.02], cell_m = {cell_m} }}
[material]
young_pa = 5000.0
poisson = 0.45
density_kg_m3 = 1000.0
damping_per_s = 40.0
[[fixed]]
name = "bottom"
select = {{ box_m = [[-0.001, -0.001, -0.001], [0.025, 0.025, 0.0001]] }}
[[tool]]
name = "probe"
kind = "hook"
fulcrum_m = [{x}, {y}, 0.15]
length_m = 0.3
radius_m = {radius_m}
tip_length_m = 0.01
{extra}
"#
    );
    let src = SceneSource {
        name: "<block>".into(),
        dir: PathBuf::from("."),
        text,
    };
    build_scene(&src, &src.parse().unwrap()).unwrap()
}

fn precomputed(
    scene: BuiltScene,
) -> Result<Prepared<Precomputed>, PrepareError<sim_server::backend::PrecomputedError>> {
    let fixed = scene.fixed.clone();
    prepare_with(scene, Some(1e-3), |model, _, dt_s| {
        Precomputed::new(model, &fixed, dt_s, None, |_, _| {})
    })
}

/// Presses the probe at (x, y) to each of `depths_m` below the top at
/// 10 mm/s and holds 1.5 s there; the force at the end of each hold.
fn press<B: Backend>(p: &mut Prepared<B>, x: f64, y: f64, depths_m: &[f64]) -> Vec<Vec3> {
    let top = 0.02 + 0.0025;
    let mut at = |d: f64| {
        let input = [Some(ToolInput {
            tip_m: Vec3::new(x, y, top - d),
            jaw_opening: 1.0,
        })];
        p.tools.update(&mut p.sim, &input);
        p.tools.step(&mut p.sim);
        p.tools.reaction(0, &p.sim).force_n
    };
    for _ in 0..300 {
        at(-0.002);
    }
    let mut depth: f64 = 0.0;
    depths_m
        .iter()
        .map(|&target| {
            while (target - depth).abs() > 1e-12 {
                depth += (target - depth).clamp(-1e-5, 1e-5);
                at(depth);
            }
            let mut f = Vec3::ZERO;
            for _ in 0..1500 {
                f = at(depth);
            }
            f
        })
        .collect()
}

#[test]
fn the_static_penalty_contact_settles_where_the_explicit_one_does() {
    let penalty = "[contact]\nlaw = \"penalty\"\n";
    let depths = [0.001, 0.002, 0.004];
    let mut dynamic = prepare::<f64>(block(0.0025, 0.012, 0.012, penalty), Some(1e-3)).unwrap();
    let settled = press(&mut dynamic, 0.012, 0.012, &depths);
    let mut p = precomputed(block(0.0025, 0.012, 0.012, penalty)).unwrap();
    assert_eq!(p.tools.law(), ContactLaw::Penalty);
    let solved = press(&mut p, 0.012, 0.012, &depths);
    // Held still, the contact solve converges at once from the last step's
    // forces, within the limit (the run summary's solve_* keys).
    let report = p.sim.linear_solve().expect("the contact solve's report");
    assert!(
        (1..=2).contains(&report.iterations) && !report.capped,
        "{report:?}"
    );
    for ((a, b), d) in settled.iter().zip(&solved).zip(depths) {
        assert!(a.z > 0.01, "{a} at {d}");
        assert!(
            (*a - *b).length() < 2e-3 * a.length(),
            "{d} m: explicit settled {a} N, precomputed {b} N"
        );
    }
}

/// The top vertices in a ring 3.5-5.5 mm round the probe's axis, held
/// where they are (as a grip beside the probe holds tissue).
fn hold_a_ring<B: Backend>(p: &mut Prepared<B>) -> usize {
    let ring: Vec<VertexId> = (0..p.sim.model().vertex_count())
        .map(VertexId::from)
        .filter(|v| {
            let x = p.sim.model().mesh().positions_m()[v.idx()];
            let r = ((x.x - 0.012).powi(2) + (x.y - 0.012).powi(2)).sqrt();
            x.z > 0.02 - 1e-9 && (0.0035..0.0055).contains(&r)
        })
        .collect();
    for &v in &ring {
        p.sim.prescribe(v, Vec3::ZERO);
    }
    ring.len()
}

#[test]
fn a_static_penalty_contact_beside_held_tissue_settles_where_the_explicit_one_does() {
    let penalty = "[contact]\nlaw = \"penalty\"\n";
    let depths = [0.002];
    let mut dynamic = prepare::<f64>(block(0.0025, 0.012, 0.012, penalty), Some(1e-3)).unwrap();
    let held = hold_a_ring(&mut dynamic);
    assert!(held >= 4, "{held}");
    let settled = press(&mut dynamic, 0.012, 0.012, &depths);
    let mut p = precomputed(block(0.0025, 0.012, 0.012, penalty)).unwrap();
    assert_eq!(hold_a_ring(&mut p), held);
    // On the way in (10 um a step), the solve's iterations: its Jacobian
    // has the holds' coupling, so Newton converges quadratically beside
    // them too.
    let mut iterations = Vec::new();
    for i in 0..=400 {
        let input = [Some(ToolInput {
            tip_m: Vec3::new(0.012, 0.012, 0.0245 - 1e-5 * i as f64),
            jaw_opening: 1.0,
        })];
        p.tools.update(&mut p.sim, &input);
        p.tools.step(&mut p.sim);
        let report = p.sim.linear_solve().expect("the contact solve's report");
        assert!(!report.capped, "step {i}: {report:?}");
        iterations.push(report.iterations);
    }
    let mean = iterations.iter().sum::<usize>() as f64 / iterations.len() as f64;
    // Without the coupling: mean 3.6, at most 9 (with it 2.0 and 4).
    let most = iterations.iter().copied().max().unwrap_or(0);
    assert!(mean < 2.5 && most <= 5, "mean {mean}, at most {most}");
    let solved = press(&mut p, 0.012, 0.012, &depths);
    let (a, b) = (settled[0], solved[0]);
    assert!(a.z > 0.01, "{a}");
    assert!(
        (a - b).length() < 2e-3 * a.length(),
        "explicit settled {a} N, precomputed {b} N"
    );
}

/// The round tip of radius `radius_m` over the block's centre pressed to
/// 3 mm at 20 um a step and held 0.5 s there (twenty of the explicit
/// block's damping times): the force at the end.
fn broad_press<B: Backend>(p: &mut Prepared<B>, radius_m: f64) -> Vec3 {
    let mut at = |d: f64| {
        let input = [Some(ToolInput {
            tip_m: Vec3::new(0.012, 0.012, 0.02 + radius_m - d),
            jaw_opening: 1.0,
        })];
        p.tools.update(&mut p.sim, &input);
        p.tools.step(&mut p.sim);
        p.tools.reaction(0, &p.sim).force_n
    };
    let mut depth: f64 = -0.002;
    while depth < 0.003 - 1e-12 {
        depth += 2e-5;
        at(depth);
    }
    let mut f = Vec3::ZERO;
    for _ in 0..500 {
        f = at(0.003);
    }
    f
}

#[test]
fn a_broad_tool_over_many_vertices_settles_where_the_explicit_one_does() {
    // A 30 mm round tip 3 mm into the top of 2 mm cells: its contact disc
    // (radius sqrt(2 r d), 13 mm) covers most of the top, 65-75 contact
    // vertices, more than the dense Newton system takes: each vertex's own
    // block then.
    let penalty = "[contact]\nlaw = \"penalty\"\n";
    let radius_m = 0.03;
    let scene = || probe_block(0.002, 0.012, 0.012, radius_m, penalty);
    let mut dynamic = prepare::<f64>(scene(), Some(1e-3)).unwrap();
    let top = (dynamic.sim.model().mesh().positions_m().iter())
        .filter(|x| x.z > 0.02 - 1e-9)
        .count();
    assert!(top > 150, "{top} top vertices");
    let settled = broad_press(&mut dynamic, radius_m);
    let mut p = precomputed(scene()).unwrap();
    let solved = broad_press(&mut p, radius_m);
    let report = p.sim.linear_solve().expect("the contact solve's report");
    assert!(!report.capped, "{report:?}");
    assert!(settled.z > 0.1, "{settled}");
    assert!(
        (settled - solved).length() < 5e-3 * settled.length(),
        "explicit settled {settled} N, precomputed {solved} N"
    );
}

#[test]
fn a_probe_over_a_cell_s_centre_feels_the_static_penalty_contact() {
    // 4.8 mm cells: (12, 12) mm is a cell's centre, 3.4 mm from every
    // vertex, beyond the probe's 2.5 mm: the projection law's hit test
    // finds no vertex and the probe goes through. The penalty law is the
    // backend's default (no `law` key).
    let projection = press(
        &mut precomputed(block(
            0.005,
            0.012,
            0.012,
            "[contact]\nlaw = \"projection\"\n",
        ))
        .unwrap(),
        0.012,
        0.012,
        &[0.002],
    );
    let mut p = precomputed(block(0.005, 0.012, 0.012, "")).unwrap();
    assert_eq!(p.tools.law(), ContactLaw::Penalty);
    let penalty = press(&mut p, 0.012, 0.012, &[0.002]);
    assert_eq!(
        projection[0],
        Vec3::ZERO,
        "the projection law: {}",
        projection[0]
    );
    assert!(penalty[0].z > 0.05, "the penalty law: {}", penalty[0]);
}

#[test]
fn friction_is_refused_on_the_static_backend() {
    let scene = block(
        0.005,
        0.012,
        0.012,
        "friction_static = 0.5\n[contact]\nlaw = \"penalty\"\n",
    );
    let err = precomputed(scene).err().expect("refused");
    let PrepareError::Contact(ContactError::FrictionStatic { tool, backend }) = &err else {
        panic!("{err}");
    };
    assert_eq!((tool.as_str(), *backend), ("probe", "precomputed"));
    assert!(err.to_string().contains("static"), "{err}");
}

/// The embedded liver on the precomputed backend under the penalty law,
/// poked 30 mm down over its centre and back in 4 s, one step a
/// millisecond, with a stall on the way out (7 ms of the hand's motion in
/// one step, as after the simulation lost the CPU): per step, the force
/// and whether its contact solve stopped short of the tolerance; and the
/// largest displacement change from before the poke once the tool is out.
fn liver_poke(stall_at_s: f64) -> (Vec<f64>, usize, f64) {
    let text = format!(
        "{}\n[contact]\nlaw = \"penalty\"\n",
        sim_server::scene::DEFAULT_SCENE
    );
    let src = SceneSource {
        name: "<liver>".into(),
        dir: PathBuf::from("."),
        text,
    };
    let mut p = precomputed(build_scene(&src, &src.parse().unwrap()).unwrap()).unwrap();
    assert_eq!(p.tools.law(), ContactLaw::Penalty);
    let z_at = |t: f64| 0.05 - 0.015 * (1.0 - (std::f64::consts::TAU * t / 4.0).cos());
    let step = |p: &mut Prepared<Precomputed>, t: f64| {
        let input = [
            Some(ToolInput {
                tip_m: Vec3::new(0.0, 0.0, z_at(t)),
                jaw_opening: 1.0,
            }),
            None,
        ];
        p.tools.update(&mut p.sim, &input);
        p.tools.step(&mut p.sim);
        let capped = p.sim.linear_solve().is_some_and(|r| r.capped);
        (p.tools.reaction(0, &p.sim).force_n.length(), capped)
    };
    step(&mut p, 0.0);
    let before = p.sim.displacements().to_vec();
    let (mut forces, mut capped) = (Vec::new(), 0);
    let mut ms = 0;
    while ms <= 4000 {
        let (f, c) = step(&mut p, ms as f64 * 1e-3);
        forces.push(f);
        capped += usize::from(c);
        ms += if ms == (stall_at_s * 1e3) as usize {
            7
        } else {
            1
        };
    }
    let moved = (before.iter().zip(p.sim.displacements()))
        .map(|(a, b)| (Vec3::from_array(*a) - Vec3::from_array(*b)).length())
        .fold(0.0, f64::max);
    (forces, capped, moved)
}

#[test]
fn the_static_penalty_contact_on_the_liver_converges_every_step_and_lets_go() {
    for stall_at_s in [2.3, 2.7] {
        let (forces, capped, moved) = liver_poke(stall_at_s);
        let peak = forces.iter().copied().fold(0.0, f64::max);
        let jump = (forces.windows(2))
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "stall at {stall_at_s} s: peak {peak} N, largest step change {jump} N, {capped} capped, moved {moved} m after"
        );
        assert!(peak > 0.5, "{peak}");
        assert_eq!(capped, 0, "steps short of the tolerance");
        assert!(jump < 0.05 * peak, "a step changed the force by {jump} N");
        assert_eq!(*forces.last().unwrap(), 0.0);
        assert!(moved < 1e-9, "the tissue did not come back: {moved} m");
    }
}

/// The contact stiffness published with each sample (the Schur complement
/// over the contact set) is d(reaction)/d(tool position) of this backend
/// too, where the penalty law is now the default: each step is the static
/// equilibrium at the tool's pose, so finite differences of single steps'
/// reactions resolve it. Over a vertex and over a cell's centre.
#[test]
fn the_published_stiffness_matches_finite_differences_of_the_static_reaction() {
    for (x, y) in [(0.0125, 0.0125), (0.01375, 0.01375)] {
        let mut p = precomputed(block(0.0025, x, y, "")).unwrap();
        // On the stepping thread: each step publishes its own stiffness
        // (the worker thread's hands over when it is done, which under
        // load can be never within a test's steps).
        p.tools.set_stiffness_solves(StiffnessSolves::Inline);
        assert_eq!(p.tools.law(), ContactLaw::Penalty);
        press(&mut p, x, y, &[0.002]);
        let tip = Vec3::new(x, y, 0.02 + 0.0025 - 0.002);
        let mut at = |tip_m: Vec3| {
            let input = [Some(ToolInput {
                tip_m,
                jaw_opening: 1.0,
            })];
            let mut reaction = p.tools.reaction(0, &p.sim);
            for _ in 0..20 {
                p.tools.update(&mut p.sim, &input);
                p.tools.step(&mut p.sim);
                reaction = p.tools.reaction(0, &p.sim);
            }
            reaction
        };
        let settled = at(tip);
        let (f0, k) = (settled.force_n, settled.stiffness_n_per_m);
        // Central differences over +-4 um: each static solve is exact to
        // its 10 nm tolerance, which over one-sided 1 um steps was already
        // 2-4% of the derivative (26% at 0.2 um); the contact's own
        // nonlinearity over 4 um stays below that.
        let eps = 4e-6;
        let mut fd = Mat3::ZERO;
        for axis in 0..3 {
            let plus = at(tip + Vec3::AXES[axis] * eps).force_n;
            let minus = at(tip - Vec3::AXES[axis] * eps).force_n;
            *fd.col_mut(axis) = -(plus - minus) / (2.0 * eps);
        }
        let norm = |m: Mat3| m.to_cols_array().iter().map(|x| x * x).sum::<f64>().sqrt();
        let err = norm(k - fd) / norm(fd);
        eprintln!(
            "({x}, {y}): {f0} N, published stiffness {:.2}% off",
            100.0 * err
        );
        assert!(f0.z > 0.01, "({x}, {y}): {f0}");
        assert!(
            err < 0.05,
            "({x}, {y}): published {k} vs finite differences {fd} ({:.1}%)",
            100.0 * err
        );
    }
}
