//! Coulomb friction on the penalty contact, through a scene: static
//! friction holds tissue the tool dragged, a slide is resisted, the contact
//! stays passive, the state survives the re-selection of contact points,
//! and bad coefficients are scene errors at their line.

mod common;

use common::{TOP_M, scene, settle, step};
use sim_server::prelude::*;

const MU: &str = "friction_static = 0.6\nfriction_dynamic = 0.4\n";

/// Pressed 4 mm between vertices, then moved along x by `shift_m` over
/// `steps` steps and held `hold` steps; the forces of the move and the
/// last one.
fn press_and_shift(
    extra: &str,
    depth_m: f64,
    shift_m: f64,
    steps: usize,
    hold: usize,
) -> (Vec3, Vec<Vec3>, Vec3) {
    let mut p = scene("hook", extra);
    let at = |x: f64| Vec3::new(x, 0.0075, TOP_M + 0.0025 - depth_m);
    settle(&mut p, at(0.0175) + Vec3::Z * 0.006, 300);
    for k in 0..=200 {
        step(
            &mut p,
            at(0.0175) + Vec3::Z * 0.006 * (1.0 - k as f64 / 200.0),
            1.0,
        );
    }
    let before = settle(&mut p, at(0.0175), 300);
    let moved: Vec<Vec3> = (1..=steps)
        .map(|k| step(&mut p, at(0.0175 + shift_m * k as f64 / steps as f64), 1.0))
        .collect();
    let held = settle(&mut p, at(0.0175 + shift_m), hold);
    (before, moved, held)
}

/// The mean over the second half of a slide of -F_x / F_z (the drag over
/// the load).
fn drag_ratio(moved: &[Vec3]) -> f64 {
    let half = &moved[moved.len() / 2..];
    half.iter().map(|f| -f.x / f.z).sum::<f64>() / half.len() as f64
}

#[test]
fn a_slide_is_resisted_in_proportion_to_the_dynamic_coefficient() {
    // 1.5 mm deep, 8 mm at 10 mm/s: the surface under the tip is nearly
    // flat, so the drag over the load is close to mu_d (the tilted normals
    // of the pit the tip drags add a few hundredths either way).
    let slide = |extra: &str| drag_ratio(&press_and_shift(extra, 0.0015, 0.008, 800, 0).1);
    let free = slide("");
    let rough = slide(MU);
    let smooth = slide("friction_static = 0.2\n");
    assert!(free.abs() < 0.1, "frictionless drag {free}");
    assert!((rough - 0.4).abs() < 0.1, "mu_d 0.4: drag {rough}");
    assert!((smooth - 0.2).abs() < 0.07, "mu 0.2: drag {smooth}");
}

#[test]
fn static_friction_holds_what_the_tool_dragged() {
    // Half a millimetre sideways, then still for half a second: the stuck
    // points keep the dragged tissue's pull (no creep), where frictionless
    // contact lets it slide back.
    let (before, moved, held) = press_and_shift(MU, 0.0015, 0.0005, 100, 500);
    let pull = held.x - before.x;
    assert!(pull < -0.01, "the tissue pulls back on the tool: {pull}");
    let end = moved.last().unwrap().x;
    assert!(
        (held.x - end).abs() < 0.1 * pull.abs(),
        "held {held}, end of move {end}"
    );
    let (before, _, held) = press_and_shift("", 0.0015, 0.0005, 100, 500);
    let free = held.x - before.x;
    assert!(
        free.abs() < 0.3 * pull.abs(),
        "frictionless {free}, with friction {pull}"
    );
}

#[test]
fn a_press_slide_retract_with_friction_gives_the_hand_no_energy() {
    // The work the contact does on the hand over a whole cycle (force on
    // the tool along the tool's path): never positive, and friction takes
    // more out than the frictionless contact.
    let work = |extra: &str| {
        let mut p = scene("hook", extra);
        let path = |k: usize| {
            let s = k as f64 / 600.0;
            let (x, depth) = match k {
                0..=200 => (0.0175, 0.002 * s * 3.0),
                201..=400 => (0.0175 + 0.006 * (s * 3.0 - 1.0), 0.002),
                _ => (0.0235, 0.002 * (3.0 - s * 3.0)),
            };
            Vec3::new(x, 0.0075, TOP_M + 0.0025 - depth)
        };
        settle(&mut p, path(0) + Vec3::Z * 0.004, 300);
        let mut prev = (path(0), step(&mut p, path(0), 1.0));
        let mut w = 0.0;
        for k in 1..=660 {
            let x = path(k.min(600));
            let f = step(&mut p, x, 1.0);
            w += 0.5 * (f + prev.1).dot(x - prev.0);
            prev = (x, f);
        }
        w
    };
    let (free, rough) = (work(""), work(MU));
    assert!(
        free <= 0.0 && rough <= 0.0,
        "work on the hand: {free} J, {rough} J with friction"
    );
    assert!(
        rough < free,
        "friction dissipates: {rough} J against {free} J"
    );
}

#[test]
fn friction_survives_fresh_selections_of_the_contact_points() {
    // The friction state is carried by the points' identity: replaying a
    // selection or selecting afresh every step gives the same forces.
    let run = |reuse: bool| {
        let mut p = scene("hook", MU);
        p.tools.set_point_reuse(reuse);
        let at = |k: usize| {
            Vec3::new(
                0.0175 + 4e-6 * k as f64,
                0.0075,
                TOP_M + 0.0025 - 0.0015 * (k.min(300) as f64 / 300.0),
            )
        };
        (0..900)
            .map(|k| step(&mut p, at(k), 1.0))
            .collect::<Vec<_>>()
    };
    let (kept, fresh) = (run(true), run(false));
    let peak = kept.iter().map(|f| f.length()).fold(0.0, f64::max);
    assert!(peak > 0.05);
    for (k, (a, b)) in kept.iter().zip(&fresh).enumerate() {
        assert!((*a - *b).length() <= 1e-12 * peak, "step {k}: {a} vs {b}");
    }
}

#[test]
fn bad_friction_is_a_scene_error_at_its_line_and_projection_refuses_it() {
    let err = |extra: &str| {
        let text = format!(
            "[mesh]\ngenerate = {{ shape = \"box\", size_m = [0.04, 0.02, 0.02], cell_m = 0.005 }}\n[material]\nyoung_pa = 5000.0\npoisson = 0.45\ndensity_kg_m3 = 1000.0\n[[tool]]\nname = \"probe\"\nkind = \"hook\"\nfulcrum_m = [0.02, 0.01, 0.15]\nlength_m = 0.3\nradius_m = 0.0025\ntip_length_m = 0.01\n{extra}"
        );
        let src = sim_server::scene::SceneSource {
            name: "rough.toml".into(),
            dir: std::path::PathBuf::from("."),
            text,
        };
        match sim_server::scene::build_scene(&src, &src.parse().unwrap()) {
            Err(e) => e.to_string(),
            Ok(built) => match sim_server::prepare::prepare::<f64>(built, None) {
                Err(e) => e.to_string(),
                Ok(_) => String::new(),
            },
        }
    };
    let negative = err("friction_static = -0.1\n");
    assert!(
        negative.contains("rough.toml:14") && negative.contains("friction_static"),
        "{negative}"
    );
    let order = err("friction_static = 0.2\nfriction_dynamic = 0.5\n");
    assert!(
        order.contains("rough.toml:15") && order.contains("exceeds friction_static"),
        "{order}"
    );
    assert_eq!(err("friction_static = 0.5\nfriction_dynamic = 0.2\n"), "");
    let projection = err("friction_static = 0.5\n[contact]\nlaw = \"projection\"\n");
    assert!(
        projection.contains("projection") && projection.contains("friction"),
        "{projection}"
    );
}
