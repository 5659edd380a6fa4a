//! A penalty tool pressed far past what the linear model holds: the tissue
//! wraps the tip and, around 11 mm into the 2 cm block, slips past it. The
//! tool's tip must never end up inside the tissue (it would be pushed in,
//! not out, and pulled in on the way back): the proxy is held outside
//! (`contact/surface/crossing.rs`). Checked independently of that code, by
//! the parity of the surface crossings of a ray from the tip's centre.

mod common;

use sim_server::contact::ToolInput;
use sim_server::prelude::*;

use common::{TOP_M, scene};

/// How many surface triangles (current positions) the ray from `from`
/// along `dir` (any length beyond the body) crosses.
fn crossings(p: &sim_server::prepare::Prepared<Explicit<f64>>, from: Vec3, dir: Vec3) -> usize {
    let model = p.sim.model();
    let mut n = 0;
    for tri in model.topology().surface_triangles(model.mesh()) {
        let x = tri.map(|v| p.sim.position(v));
        let (e1, e2) = (x[1] - x[0], x[2] - x[0]);
        let h = dir.cross(e2);
        let det = e1.dot(h);
        if det.abs() < 1e-18 {
            continue;
        }
        let s = from - x[0];
        let u = s.dot(h) / det;
        let q = s.cross(e1);
        let v = dir.dot(q) / det;
        let t = e2.dot(q) / det;
        if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0 {
            n += 1;
        }
    }
    n
}

#[test]
fn a_probe_pressed_past_what_the_linear_model_holds_never_ends_inside_the_tissue() {
    let mut p = scene("hook", "");
    // Straight down on a vertex, 20 mm (the whole block) in 2 s, then back.
    let at = |z: f64| Vec3::new(0.02, 0.01, z);
    let (top, bottom) = (TOP_M + 0.001, 0.0);
    let mut held = 0;
    let mut pulled: f64 = 0.0;
    let mut inside = 0;
    let mut deepest_force: f64 = 0.0;
    for k in 0..3000 {
        let z = if k < 2000 {
            top + (bottom - top) * k as f64 / 2000.0
        } else {
            bottom + (top - bottom) * (k - 2000) as f64 / 1000.0
        };
        let input = [Some(ToolInput {
            tip_m: at(z),
            jaw_opening: 1.0,
        })];
        held += usize::from(p.tools.update(&mut p.sim, &input)[0].held_outside);
        // Where each step starts: the tool placed against the tissue as the
        // last step left it (a slip during a step is caught at the next).
        let tip = p.tools.tool(0).pose().unwrap().end_m;
        // A ray up and a little aside (never exactly through an edge).
        if crossings(&p, tip, Vec3::new(0.013, 0.007, 1.0)) % 2 == 1 {
            inside += 1;
        }
        p.tools.step(&mut p.sim);
        let f = p.tools.reaction(0, &p.sim).force_n;
        pulled = pulled.min(f.z);
        deepest_force = deepest_force.max(f.z);
    }
    assert!(deepest_force > 0.3, "pressed: at most {deepest_force} N");
    assert_eq!(
        inside, 0,
        "the tip's centre was inside the tissue {inside} steps"
    );
    // Before the proxy was held outside: -0.52 N on the way back.
    assert!(
        pulled > -0.05,
        "the tissue pulled the tool in with {pulled} N"
    );
    // The case is the extreme one: the surface did stop the tip.
    assert!(held > 0, "the tissue never slipped past the tip");
}
