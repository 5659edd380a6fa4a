//! The problem with the tissue's inertia: time steps, re-basing, catch-up.

use super::*;

/// The press problem with inertia: G such that the condensed mass is
/// `m` kg per dof (M = S G S with S = I / C: G = m C^2 I), damping `c`.
fn with_inertia(m: f64, c: f64, first_s: f64) -> (LocalProblem, V3) {
    let (mut p, centre) = press(0.001);
    let mut g = vec![0.0; 81];
    for i in 0..9 {
        g[i * 9 + i] = m * C * C;
    }
    p.set_inertia(&g, c, &[[0.0; 3]; 3], first_s, 1e-3).unwrap();
    (p, centre)
}

#[test]
fn with_a_vanishing_mass_the_inertia_changes_nothing() {
    let (mut quasi, centre) = press(0.001);
    let (mut light, _) = with_inertia(1e-12, 0.0, 0.03);
    let down = [centre[0], centre[1], centre[2] - 2e-4];
    for _ in 0..3 {
        let (a, b) = (quasi.solve(down).unwrap(), light.solve(down).unwrap());
        assert!(norm(sub(a.0, b.0)) < 1e-9, "{a:?} {b:?}");
    }
}

#[test]
fn inertia_stiffens_a_sudden_press_then_settles_to_the_static_force() {
    // 10 g per dof, damped at 50 /s: pressed 0.2 mm deeper at once, the
    // tissue cannot give way in the first millisecond (more force than the
    // quasi-static answer), then it settles to it.
    let (mut quasi, centre) = press(0.001);
    let (mut heavy, _) = with_inertia(0.01, 50.0, 1e-3);
    let down = [centre[0], centre[1], centre[2] - 2e-4];
    let settled = quasi.solve(down).unwrap().0;
    let first = heavy.solve(down).unwrap().0;
    assert!(first[2] > settled[2] * 1.2, "{first:?} vs {settled:?}");
    let mut last = first;
    for _ in 0..3000 {
        last = heavy.solve(down).unwrap().0;
    }
    // Settled to the solver's tolerance (1e-4 N of imbalance per vertex
    // stops the iterations).
    assert!(norm(sub(last, settled)) < 5e-4, "{last:?} vs {settled:?}");
    // The first step may span the sample's age: a long first step is
    // nearer the settled force than a 1 ms one.
    let (mut aged, _) = with_inertia(0.01, 50.0, 0.05);
    let long = aged.solve(down).unwrap().0;
    assert!((long[2] - settled[2]).abs() < (first[2] - settled[2]).abs());
}

#[test]
fn inertia_re_bases_a_newer_sample_on_the_problems_own_history() {
    // Pressed 0.2 mm deeper and held: the problem's force changes over its
    // ticks (the tissue gives way). A newer sample at 2.5 ms whose force is where the problem was
    // then continues the same rendering; one 0.1 N stronger renders 0.1 N
    // more; one older than the ticks kept says nothing.
    let (mut p, centre) = with_inertia(0.01, 10.0, 1e-3);
    let down = [centre[0], centre[1], centre[2] - 2e-4];
    let f = [0.0, 0.0, 0.5];
    p.seq = 4;
    let ms = 1_000_000;
    let own = sample_at(4, 0, centre, f);
    let mut twin = p.clone();
    let mut rendered = Vec::new();
    for k in 1..=3 {
        rendered.push(p.render(&own, k * ms, down, f64::INFINITY).unwrap());
        twin.render(&own, k * ms, down, f64::INFINITY).unwrap();
    }
    assert!(
        (rendered[2][2] - rendered[0][2]).abs() > 1e-3,
        "{rendered:?}"
    );
    let mid = add(scale(rendered[1], 0.5), scale(rendered[2], 0.5));
    let newer = sample_at(5, 5 * ms / 2, centre, mid);
    let going_on = p.render(&own, 4 * ms, down, f64::INFINITY).unwrap();
    let re_based = twin.render(&newer, 4 * ms, down, f64::INFINITY).unwrap();
    assert!(
        norm(sub(going_on, re_based)) < 1e-9,
        "{going_on:?} {re_based:?}"
    );
    let stronger = sample_at(6, 5 * ms / 2, centre, add(mid, [0.0, 0.0, 0.1]));
    let more = twin.render(&stronger, 5 * ms, down, f64::INFINITY).unwrap();
    let same = p.render(&own, 5 * ms, down, f64::INFINITY).unwrap();
    assert!(norm(sub(more, add(same, [0.0, 0.0, 0.1]))) < 1e-9);
    // Before every tick kept (the ring is full): nothing.
    for k in 6..6 + super::HISTORY as u64 {
        p.render(&own, k * ms, down, f64::INFINITY).unwrap();
    }
    let ancient = sample_at(7, 3 * ms, centre, f);
    assert!(p.render(&ancient, 300 * ms, down, f64::INFINITY).is_none());
}

#[test]
fn inertia_checks_its_input() {
    let (mut q, _) = press(0.001);
    assert!(
        q.set_inertia(&[0.0; 80], 0.0, &[[0.0; 3]; 3], 0.03, 1e-3)
            .is_err()
    );
    assert!(
        q.set_inertia(&[0.0; 81], 0.0, &[[0.0; 3]; 2], 0.03, 1e-3)
            .is_err()
    );
    assert!(
        q.set_inertia(&[0.0; 81], 0.0, &[[0.0; 3]; 3], 0.0, 1e-3)
            .is_err()
    );
    assert!(
        q.set_inertia(&[f64::NAN; 81], 0.0, &[[0.0; 3]; 3], 0.03, 1e-3)
            .is_err()
    );
}

#[test]
fn with_inertia_a_step_without_a_single_iteration_is_not_committed() {
    // A render whose time budget is spent before the first iteration falls
    // back (None) and leaves the state as it was; given time, the same
    // step is then taken as by a problem that never ran out.
    let (mut p, centre) = with_inertia(0.01, 10.0, 1e-3);
    let mut twin = p.clone();
    let down = [centre[0], centre[1], centre[2] - 2e-4];
    let (vel, delta) = (p.inertia.vel.clone(), p.delta.clone());
    p.set_time_budget(Some(std::time::Duration::ZERO));
    assert!(p.solve(down).is_none());
    assert_eq!((&p.inertia.vel, &p.delta), (&vel, &delta));
    p.set_time_budget(None);
    let (a, b) = (p.solve(down).unwrap().0, twin.solve(down).unwrap().0);
    assert!(norm(sub(a, b)) < 1e-12, "{a:?} vs {b:?}");
}

#[test]
fn catching_up_through_the_hands_positions_equals_rendering_them() {
    // The set-up thread's catch-up steps and the RT thread's renders are
    // the same time steps: a problem caught up through five ticks renders
    // the sixth as one that rendered all six.
    let (mut caught, centre) = with_inertia(0.01, 10.0, 1e-3);
    let mut rendered = caught.clone();
    caught.seq = 4;
    rendered.seq = 4;
    let own = sample_at(4, 0, centre, [0.0, 0.0, 0.5]);
    let ms = 1_000_000;
    let path = |k: u64| {
        [
            centre[0] + 1e-4 * k as f64,
            centre[1],
            centre[2] - 3e-5 * k as f64,
        ]
    };
    for k in 1..=5 {
        assert!(caught.catch_up(k * ms, path(k)));
        rendered
            .render(&own, k * ms, path(k), f64::INFINITY)
            .unwrap();
    }
    let a = caught.render(&own, 6 * ms, path(6), f64::INFINITY).unwrap();
    let b = rendered
        .render(&own, 6 * ms, path(6), f64::INFINITY)
        .unwrap();
    assert!(norm(sub(a, b)) < 1e-12, "{a:?} vs {b:?}");
    // A newer sample re-bases on the caught-up ticks as on rendered ones.
    let newer = sample_at(5, 3 * ms, centre, [0.0, 0.0, 0.6]);
    let (a, b) = (
        caught
            .render(&newer, 7 * ms, path(7), f64::INFINITY)
            .unwrap(),
        rendered
            .render(&newer, 7 * ms, path(7), f64::INFINITY)
            .unwrap(),
    );
    assert!(norm(sub(a, b)) < 1e-12, "{a:?} vs {b:?}");
    // Without inertia there is nothing to catch up.
    let (mut quasi, _) = press(0.001);
    assert!(!quasi.catch_up(ms, centre));
}
