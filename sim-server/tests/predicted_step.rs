//! The step computed ahead without the tools and finished locally once
//! the tools are known (`Explicit::prepare_step`, as the live loop calls
//! it while it waits for a pose) is the plain step to the bit, in contact:
//! pressing, sliding and withdrawing under the penalty law with implicit
//! and explicit springs, with friction, and gripping, lifting and cutting
//! with the grasper.

mod common;

use common::{TOP_M, scene, scene_block};
use sim_server::contact::ToolInput;
use sim_server::prelude::*;
use sim_server::prepare::Prepared;

/// The tool's path: above the block, down 3 mm between vertices, 8 mm
/// along x, back up; the jaws as `jaw(k)` says.
fn path(k: usize) -> Vec3 {
    let t = k as f64;
    let start = Vec3::new(0.0175, 0.0075, TOP_M + 0.0025 + 0.002);
    let down = Vec3::new(0.0, 0.0, -0.005);
    match k {
        0..150 => start + down * (t / 150.0),
        150..550 => start + down + Vec3::new(0.00002 * (t - 150.0), 0.0, 0.0),
        _ => start + down + Vec3::new(0.008, 0.0, 0.00002 * (t - 550.0)),
    }
}

/// Steps `plain` and `prepared` side by side over `steps` steps, the
/// prepared one preparing before each pose; every state and force equal
/// (the forces read before [`Explicit::finish_step`], the states after).
fn lockstep(
    plain: Prepared<Explicit<f64>>,
    prepared: Prepared<Explicit<f64>>,
    steps: usize,
    tip: impl Fn(usize) -> Vec3,
    jaw: impl Fn(usize) -> f64,
) -> (Prepared<Explicit<f64>>, f64) {
    let (p, peak, _) = lockstep_counting(plain, prepared, steps, tip, jaw);
    (p, peak)
}

/// [`lockstep`], also counting the steps whose state before
/// [`Explicit::finish_step`] was not yet the plain one's (rows deferred).
fn lockstep_counting(
    mut plain: Prepared<Explicit<f64>>,
    mut prepared: Prepared<Explicit<f64>>,
    steps: usize,
    tip: impl Fn(usize) -> Vec3,
    jaw: impl Fn(usize) -> f64,
) -> (Prepared<Explicit<f64>>, f64, usize) {
    let mut peak: f64 = 0.0;
    let mut unfinished = 0;
    for k in 0..steps {
        prepared.sim.prepare_step();
        let input = [Some(ToolInput {
            tip_m: tip(k),
            jaw_opening: jaw(k),
        })];
        let mut forces = [Vec3::ZERO; 2];
        for (p, f) in [&mut plain, &mut prepared].into_iter().zip(&mut forces) {
            p.tools.update(&mut p.sim, &input);
            p.tools.step(&mut p.sim);
            *f = p.tools.reaction(0, &p.sim).force_n;
        }
        assert_eq!(forces[0], forces[1], "force at step {k}");
        let bits = |p: &Prepared<Explicit<f64>>| -> Vec<u64> {
            p.sim
                .displacements()
                .iter()
                .flatten()
                .map(|x| x.to_bits())
                .collect()
        };
        if bits(&plain) != bits(&prepared) {
            unfinished += 1;
        }
        prepared.sim.finish_step();
        assert!(bits(&plain) == bits(&prepared), "state at step {k}");
        peak = peak.max(forces[0].length());
    }
    assert_eq!(plain.sim.predicted_steps(), 0);
    (prepared, peak, unfinished)
}

/// A 160 x 80 x 20 mm block refined to 2.5 mm within 6 mm of its top's
/// centre, multirate: the refined cells' vertices (and the contact's)
/// sub-stepped, the rest at a longer step.
fn refined_block() -> Prepared<Explicit<f64>> {
    let extra = "[[refine]]\nselect = { sphere_m = [0.084, 0.04, 0.02, 0.006] }\ncell_m = 0.0025\n\n\
                 [simulation]\nmultirate = true\n";
    scene_block([0.16, 0.08, 0.02], "hook", extra, 1e-3)
}

/// `local`: the correction must stay well below full passes (with
/// implicit springs the block keeps its few sub-steps).
fn press_slide_withdraw(extra: &str, local: bool) -> (u64, u64) {
    let (p, peak) = lockstep(
        scene("hook", extra),
        scene("hook", extra),
        700,
        path,
        |_| 1.0,
    );
    assert!(peak > 0.05, "the tool must press: {peak} N");
    predicted_rows(&p, 650, local)
}

/// Checks that more than `at_least` of the 700 steps were predicted and,
/// when `local`, that the correction stayed local (far fewer rows than
/// full passes); the rows recomputed and those of full passes.
fn predicted_rows(p: &Prepared<Explicit<f64>>, at_least: u64, local: bool) -> (u64, u64) {
    let steps = p.sim.predicted_steps();
    assert!(steps > at_least, "{steps} of 700 steps predicted");
    let full = steps * (p.sim.substeps() * p.sim.model().vertex_count()) as u64;
    let rows = p.sim.predicted_rows();
    assert!(
        !local || rows * 3 < full,
        "{rows} rows recomputed against {full} in full passes"
    );
    (rows, full)
}

#[test]
fn a_predicted_step_in_contact_is_the_plain_step_to_the_bit() {
    press_slide_withdraw("", true);
}

#[test]
fn the_same_with_explicit_springs_and_with_friction() {
    // Explicit springs sub-step more: the rows reach the whole block,
    // and the rest of such a step runs whole passes.
    let (rows, full) = press_slide_withdraw("[contact]\nsprings = \"explicit\"\n", false);
    assert!(
        rows * 2 > full,
        "the whole passes must be exercised: {rows} of {full}"
    );
    press_slide_withdraw("friction_static = 0.6\nfriction_dynamic = 0.4\n", true);
}

#[test]
fn the_same_with_multirate_stepping_on_a_refined_block() {
    // A 160 x 80 x 20 mm block refined to 2.5 mm round the path: the
    // refined cells' vertices (and the contact's) are sub-stepped, the
    // rest keeps a longer step; the prediction is that multirate step.
    let make = refined_block;
    let first = make();
    let report = first.sim.multirate().expect("multirate asked for");
    assert!(report.engaged, "{report:?}");
    assert!(report.coarse_substeps < report.fine_substeps, "{report:?}");
    let shift = Vec3::new(0.0625, 0.0325, 0.0);
    let (p, peak) = lockstep(first, make(), 700, |k| path(k) + shift, |_| 1.0);
    assert!(peak > 0.05, "the tool must press: {peak} N");
    predicted_rows(&p, 600, true);
}

#[test]
fn the_far_rows_left_until_the_force_is_out_change_neither_force_nor_state() {
    // The hook on the plain block, and on the refined multirate block:
    // each step's force is read before the far rows are recomputed.
    let shift = Vec3::new(0.0625, 0.0325, 0.0);
    type Sim = Prepared<Explicit<f64>>;
    let cases: [(Sim, Sim, Vec3); 2] = [
        (scene("hook", ""), scene("hook", ""), Vec3::ZERO),
        (refined_block(), refined_block(), shift),
    ];
    for (plain, mut prepared, shift) in cases {
        prepared.sim.defer_far_rows(true);
        let (p, peak, unfinished) =
            lockstep_counting(plain, prepared, 700, |k| path(k) + shift, |_| 1.0);
        assert!(peak > 0.05, "the tool must press: {peak} N");
        assert!(p.sim.predicted_steps() > 600);
        // Rows were left for after the force in most contact steps.
        assert!(unfinished > 300, "{unfinished} of 700 steps left rows");
        // And most steps found their rows kept from the step before (the
        // lockstep above checks that they are the right ones).
        let reused = p.sim.predicted_steps_reusing_rows();
        assert!(reused > 300, "{reused} of 700 steps reused their rows");
    }
}

#[test]
fn gripping_lifting_and_cutting_after_a_prediction_change_nothing() {
    // Down 2 mm, close the jaws (grip), lift 3 mm, close below 0.1 (cut).
    let tip = |k: usize| {
        let base = Vec3::new(0.0175, 0.0075, TOP_M + 0.0025 - 0.002);
        match k {
            0..300 => base,
            _ => base + Vec3::new(0.0, 0.0, 0.003 * ((k - 300) as f64 / 200.0).min(1.0)),
        }
    };
    let jaw = |k: usize| match k {
        0..300 => 1.0,
        300..600 => 0.3,
        _ => 0.05,
    };
    // Also with the far rows left until the force is out: the grip's
    // force reads the elastic force at its vertices, one ring further.
    for defer in [false, true] {
        let mut prepared = scene("grasper", "");
        prepared.sim.defer_far_rows(defer);
        let (p, _) = lockstep(scene("grasper", ""), prepared, 620, tip, jaw);
        assert!(p.sim.model().topology().alive_count() < p.sim.model().mesh().tet_count());
        // The cut's step too: its elements' rows are recomputed, not the step.
        assert_eq!(p.sim.predicted_steps(), 620);
        // Held, lifted and cut on rows kept from step to step: the cut's
        // step found new ones, and the steps after it again.
        let reused = p.sim.predicted_steps_reusing_rows();
        assert!(reused > 500, "{reused} of 620 steps reused their rows");
    }
}
