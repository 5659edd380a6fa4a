//! Shared fixtures for the physics-law tests.
#![allow(dead_code)]

use sim_server::contact::{StiffnessSolves, ToolInput};
use sim_server::prelude::*;
use sim_server::prepare::{Prepared, prepare};
use sim_server::scene::{SceneSource, build_scene};
use std::path::PathBuf;

// The core's fixtures, shared with its own tests (not every test file uses them).
#[allow(unused_imports)]
pub use tissue::test_support::*;

/// Top face of the penalty-contact block of [`scene`] (m).
pub const TOP_M: f64 = 0.02;

/// A 4 x 2 x 2 cm block on 5 mm cells, bottom fixed, one tool of `kind`
/// (radius 2.5 mm) entering from above; `extra` appended to the scene.
pub fn scene(kind: &str, extra: &str) -> Prepared<Explicit<f64>> {
    scene_stepped(kind, extra, 1e-3)
}

/// [`scene`] stepped `dt_s` at a time.
pub fn scene_stepped(kind: &str, extra: &str, dt_s: f64) -> Prepared<Explicit<f64>> {
    scene_block([0.04, 0.02, 0.02], kind, extra, dt_s)
}

/// [`scene_stepped`] on a block of `size_m` (its top at [`TOP_M`] when
/// the height is 2 cm), the tool's fulcrum above its centre.
pub fn scene_block(
    size_m: [f64; 3],
    kind: &str,
    extra: &str,
    dt_s: f64,
) -> Prepared<Explicit<f64>> {
    let [x, y, z] = size_m;
    let (fx, fy, fz) = (x / 2.0, y / 2.0, z + 0.13);
    let (bx, by) = (x + 0.001, y + 0.001);
    let text = format!(
        r#"
[mesh]
generate = {{ shape = "box", size_m = [{x}, {y}, {z}], cell_m = 0.005 }}

[material]
young_pa = 5000.0
poisson = 0.45
density_kg_m3 = 1000.0
damping_per_s = 40.0

[[fixed]]
name = "bottom"
select = {{ box_m = [[-0.001, -0.001, -0.001], [{bx}, {by}, 0.0001]] }}

[[tool]]
name = "tool"
kind = "{kind}"
fulcrum_m = [{fx}, {fy}, {fz}]
length_m = 0.3
radius_m = 0.0025
tip_length_m = 0.01
{extra}
"#
    );
    let src = SceneSource {
        name: "<block>".into(),
        dir: PathBuf::from("."),
        text,
    };
    let built = build_scene(&src, &src.parse().unwrap()).unwrap();
    let mut p = prepare::<f64>(built, Some(dt_s)).unwrap();
    // The stiffness exact at every step, whatever the threads' timing.
    p.tools.set_stiffness_solves(StiffnessSolves::Inline);
    p
}

/// One step with the tool tip at `tip` (jaws `jaw`); the force on it.
pub fn step(p: &mut Prepared<Explicit<f64>>, tip: Vec3, jaw: f64) -> Vec3 {
    let input = [Some(ToolInput {
        tip_m: tip,
        jaw_opening: jaw,
    })];
    p.tools.update(&mut p.sim, &input);
    p.tools.step(&mut p.sim);
    p.tools.reaction(0, &p.sim).force_n
}

/// Holds the tool at `tip` for `steps` steps; the last force.
pub fn settle(p: &mut Prepared<Explicit<f64>>, tip: Vec3, steps: usize) -> Vec3 {
    let mut f = Vec3::ZERO;
    for _ in 0..steps {
        f = step(p, tip, 1.0);
    }
    f
}
