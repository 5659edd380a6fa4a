use super::*;
use crate::extrapolate::ForceSample;
use crate::math::{add, scale};

const K_P: f64 = 300.0;
const R: f64 = 0.005;
const C: f64 = 0.01; // m/N per vertex

/// A triangle in z = 0 under a ball (a capsule of zero length) whose
/// bottom is `depth` below it at the centroid; the vertices on independent
/// springs of compliance C; one point at the centroid.
fn press(depth: f64) -> (LocalProblem, V3) {
    let x = [[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]];
    let c = [0.01 / 3.0, 0.01 / 3.0, 0.0];
    let centre = [c[0], c[1], R - depth];
    let ball = Capsule {
        a_m: centre,
        b_m: centre,
        radius_m: R,
        onset_m: 0.02 * R,
    };
    let point = Point {
        slots: [0, 1, 2],
        weights: [1.0 / 3.0; 3],
        part: 0,
        stiffness_n_per_m: K_P,
    };
    let mut w = vec![0.0; 81];
    for i in 0..9 {
        w[i * 9 + i] = C;
    }
    let mut p = LocalProblem::new();
    p.set(centre, &[ball], &x, &[point], &w).unwrap();
    (p, centre)
}

#[test]
fn at_the_samples_pose_nothing_changes() {
    let (mut p, centre) = press(0.001);
    let (df, touching) = p.solve(centre).unwrap();
    assert!(touching);
    assert!(norm(df) < 1e-12, "{df:?}");
}

#[test]
fn pressing_further_meets_the_spring_in_series_with_the_tissue() {
    // Past the onset the point's spring is linear: pressing dz further
    // adds k dz with 1/k = 1/k_p + sum w^2 C (the tissue's compliance at
    // the point), the vertices taking the point's force by its weights.
    let (mut p, centre) = press(0.001);
    let dz = 2e-4;
    let (df, _) = p.solve([centre[0], centre[1], centre[2] - dz]).unwrap();
    let k = 1.0 / (1.0 / K_P + C / 3.0);
    assert!((df[2] - k * dz).abs() < 1e-9 * k, "{df:?} vs {}", k * dz);
    assert!(df[0].abs() < 1e-12 && df[1].abs() < 1e-12);
}

#[test]
fn withdrawing_past_the_surface_releases_everything() {
    let (mut p, centre) = press(0.001);
    let f0 = p.tool_force0_n;
    let (df, touching) = p.solve([centre[0], centre[1], centre[2] + 0.01]).unwrap();
    assert!(!touching);
    assert!(norm(add(df, f0)) < 1e-12, "{df:?} {f0:?}");
}

#[test]
fn the_forces_are_minus_the_gradient_of_the_energy() {
    let (p, _) = press(0.0005);
    let n = 9;
    let delta: Vec<f64> = (0..n).map(|i| 1e-5 * ((i * 7 % 5) as f64 - 2.0)).collect();
    let dx = [3e-4, -1e-4, -2e-4];
    let mut f = vec![0.0; n];
    p.evaluate(&delta, dx, &mut f, None);
    for i in 0..n {
        let h = 1e-9;
        let mut plus = delta.clone();
        plus[i] += h;
        let mut minus = delta.clone();
        minus[i] -= h;
        let mut scratch = vec![0.0; n];
        let ep = p.evaluate(&plus, dx, &mut scratch, None).0;
        let em = p.evaluate(&minus, dx, &mut scratch, None).0;
        let fd = -(ep - em) / (2.0 * h);
        assert!(
            (fd - f[i]).abs() < 1e-6 * f[i].abs().max(1e-3),
            "{i}: {fd} vs {}",
            f[i]
        );
    }
}

#[test]
fn the_hessian_is_the_derivative_of_the_forces() {
    let (p, _) = press(0.0005);
    let n = 9;
    let delta = vec![0.0; n];
    let dx = [2e-4, 1e-4, -3e-4];
    let mut h = vec![0.0; n * n];
    let mut f = vec![0.0; n];
    p.evaluate(
        &delta,
        dx,
        &mut f,
        Some(Block {
            h: &mut h,
            springs_only: false,
            slot: &[0, 1, 2],
            size: 9,
        }),
    );
    for j in 0..n {
        let e = 1e-8;
        let mut plus = delta.clone();
        plus[j] += e;
        let mut minus = delta.clone();
        minus[j] -= e;
        let (mut fp, mut fm) = (vec![0.0; n], vec![0.0; n]);
        p.evaluate(&plus, dx, &mut fp, None);
        p.evaluate(&minus, dx, &mut fm, None);
        for i in 0..n {
            let fd = -(fp[i] - fm[i]) / (2.0 * e);
            assert!(
                (fd - h[i * n + j]).abs() < 1e-4 * K_P,
                "{i},{j}: {fd} vs {}",
                h[i * n + j]
            );
        }
    }
}

#[test]
fn sliding_off_the_edge_of_the_triangle_loses_the_contact_smoothly() {
    // Moving sideways off the only triangle: the force falls to zero
    // without a jump between neighbouring positions.
    let (mut p, centre) = press(0.001);
    let mut last: Option<V3> = None;
    for i in 0..200 {
        let x = centre[0] + i as f64 * 1e-4;
        let (df, _) = p.solve([x, centre[1], centre[2]]).unwrap();
        let f = add(df, p.tool_force0_n);
        if let Some(l) = last {
            assert!(norm(sub(f, l)) < 0.05, "jump at {x}: {l:?} -> {f:?}");
        }
        last = Some(f);
    }
    assert!(norm(last.unwrap()) < 1e-12);
}

#[test]
fn bad_problems_are_refused() {
    let mut p = LocalProblem::new();
    let ball = Capsule {
        a_m: ZERO,
        b_m: ZERO,
        radius_m: R,
        onset_m: 1e-4,
    };
    let x = [[0.0; 3]; 3];
    let pt = Point {
        slots: [0, 1, 3],
        weights: [1.0 / 3.0; 3],
        part: 0,
        stiffness_n_per_m: 1.0,
    };
    let w: Vec<f64> = (0..81)
        .map(|i| if i % 10 == 0 { 1.0 } else { 0.0 })
        .collect();
    assert!(matches!(
        p.set(ZERO, &[ball], &x, &[pt], &w),
        Err(LocalProblemError::Malformed(_))
    ));
    let pt = Point {
        slots: [0, 1, 2],
        ..pt
    };
    assert_eq!(
        p.set(ZERO, &[ball], &x, &[pt], &w[..80]),
        Err(LocalProblemError::Malformed("compliance size"))
    );
    let mut bad = w.clone();
    bad[0] = -1.0;
    assert_eq!(
        p.set(ZERO, &[ball], &x, &[pt], &bad),
        Err(LocalProblemError::NotDefinite)
    );
    assert!(!p.is_ready());
    assert!(p.solve(ZERO).is_none());
    assert!(p.set(ZERO, &[ball], &x, &[pt], &w).is_ok());
    assert!(p.solve([f64::NAN, 0.0, 0.0]).is_none());
}

/// A sample in contact, without a stiffness.
fn sample_at(seq: u64, t_ns: u64, position_m: V3, force_n: V3) -> ForceSample {
    ForceSample {
        in_contact: true,
        catching_up: false,
        ..super::super::tests::sample(seq, t_ns, position_m, force_n)
    }
}

#[test]
fn render_uses_a_problem_only_with_the_samples_it_describes() {
    let (mut p, centre) = press(0.001);
    p.seq = 10;
    p.t_ns = 1_000_000_000;
    let f = [0.0, 0.0, 0.5];
    // The sample it was taken with: the sample's force at its pose.
    let own = sample_at(10, p.t_ns, centre, f);
    let at = p.render(&own, own.t_ns, centre, f64::INFINITY).unwrap();
    assert!(norm(sub(at, f)) < 1e-12, "{at:?}");
    // A later sample 1 mm deeper: its force, plus the change from there
    // (20 ms later: a tool moving 1 mm in 2 ms is too fast for a problem).
    let deeper = [centre[0], centre[1], centre[2] - 0.001];
    let later = sample_at(12, p.t_ns + 20_000_000, deeper, [0.0, 0.0, 0.7]);
    let same = p.render(&later, later.t_ns, deeper, f64::INFINITY).unwrap();
    assert!(norm(sub(same, later.force_n)) < 1e-9, "{same:?}");
    // An older problem than the sample (a restarted simulation), or one
    // from long before it: none.
    assert!(
        p.render(
            &sample_at(9, p.t_ns, centre, f),
            p.t_ns,
            centre,
            f64::INFINITY
        )
        .is_none()
    );
    let stale = sample_at(500, p.t_ns + MAX_AGE_NS + 1, centre, f);
    assert!(
        p.render(&stale, stale.t_ns, centre, f64::INFINITY)
            .is_none()
    );
    // Withdrawn: zero, not the sample's force.
    let up = [centre[0], centre[1], centre[2] + 0.01];
    assert_eq!(
        p.render(&own, own.t_ns, up, f64::INFINITY).unwrap(),
        [0.0; 3]
    );
    // Capped: 1 mm deeper changes the force by at most cap x 1 mm, along
    // the uncapped change.
    let free = p.render(&own, own.t_ns, deeper, f64::INFINITY).unwrap();
    let capped = p.render(&own, own.t_ns, deeper, 50.0).unwrap();
    let (df, dc) = (sub(free, f), sub(capped, f));
    assert!(norm(df) > 0.05 + 1e-6, "{df:?}");
    assert!((norm(dc) - 0.05).abs() < 1e-12, "{dc:?}");
    assert!(norm(sub(scale(df, 0.05 / norm(df)), dc)) < 1e-12);
}

#[test]
fn render_leaves_a_tool_too_fast_for_the_problem_to_the_fallback() {
    let (mut p, centre) = press(0.001);
    p.seq = 10;
    p.t_ns = 1_000_000_000;
    let f = [0.0, 0.0, 0.5];
    let ms = 1_000_000;
    // Slowly (1 mm in 10 ms, 0.1 m/s) the problem renders; 1 mm in a
    // millisecond (1 m/s, past MAX_TOOL_SPEED_M_S) it does not, and again
    // once the tool goes slowly.
    let (mut t, mut x) = (p.t_ns, 0.0);
    for (dt_ns, dx, renders) in [
        (10 * ms, 0.001, true),
        (ms, 0.001, false),
        (10 * ms, 0.0005, true),
    ] {
        t += dt_ns;
        x += dx;
        let sample = sample_at(10, p.t_ns, centre, f);
        let r = p.render(
            &sample,
            t,
            [centre[0] - x, centre[1], centre[2]],
            f64::INFINITY,
        );
        assert_eq!(r.is_some(), renders, "{dx} m in {dt_ns} ns");
    }
}

#[test]
fn a_clone_keeps_the_problem_and_its_capacity() {
    let (p, centre) = press(0.001);
    let mut q = p.clone();
    assert!(q.s.capacity() >= 9 * MAX_VERTICES * MAX_VERTICES);
    assert!(q.points.capacity() >= MAX_POINTS);
    // Copied into a problem made before (as the triple buffer does): every
    // buffer the RT thread fills keeps its full capacity.
    let mut r = LocalProblem::new();
    r.clone_from(&p);
    assert!(r.selection.active.capacity() >= MAX_POINTS);
    assert!(r.inertia.vel.capacity() >= 3 * MAX_VERTICES);
    assert!(r.scratch.gt.capacity() >= 9 * MAX_VERTICES * MAX_VERTICES);
    assert!(q.selection.active.capacity() >= MAX_POINTS);
    let (mut p, _) = (p, ());
    let down = [centre[0], centre[1], centre[2] - 2e-4];
    assert_eq!(p.solve(down), q.solve(down));
}

#[test]
fn in_contact_the_change_is_held_to_the_contacts_own_stiffness() {
    let (mut p, centre) = press(0.001);
    let deeper = [centre[0], centre[1], centre[2] - 0.001];
    let mut own = sample_at(0, 0, centre, [0.0, 0.0, 0.5]);
    // No stiffness published: the problem's own change (stiffer than
    // 15 N/m over this millimetre).
    let free = sub(
        p.render(&own, own.t_ns, deeper, f64::INFINITY).unwrap(),
        own.force_n,
    );
    assert!(norm(free) > 0.02, "{free:?}");
    // A contact stiffness of 10 N/m: at most 1.5 x 10 N/m x 1 mm.
    own.stiffness_n_per_m = [[10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 10.0]];
    let held = sub(
        p.render(&own, own.t_ns, deeper, f64::INFINITY).unwrap(),
        own.force_n,
    );
    assert!(
        (norm(held) - CHANGE_OF_STIFFNESS * 10.0 * 0.001).abs() < 1e-12,
        "{held:?}"
    );
    // Not in contact (an onset): not held.
    own.in_contact = false;
    let onset = sub(
        p.render(&own, own.t_ns, deeper, f64::INFINITY).unwrap(),
        own.force_n,
    );
    assert!((norm(onset) - norm(free)).abs() < 1e-12);
}

#[test]
fn a_smaller_problem_after_a_larger_one_solves() {
    // The touched-vertex scratch of a 6-vertex problem must not leak
    // into a 3-vertex one set up in the same buffers.
    let (mut small, centre) = press(0.001);
    let x: Vec<V3> = (0..6)
        .map(|i| [0.004 * (i % 3) as f64, 0.004 * (i / 3) as f64, 0.0])
        .collect();
    let point = |slots: [u16; 3]| Point {
        slots,
        weights: [1.0 / 3.0; 3],
        part: 0,
        stiffness_n_per_m: K_P,
    };
    let ball = Capsule {
        a_m: [0.004, 0.002, R - 0.001],
        b_m: [0.004, 0.002, R - 0.001],
        radius_m: R,
        onset_m: 0.02 * R,
    };
    let mut w = vec![0.0; 18 * 18];
    for i in 0..18 {
        w[i * 18 + i] = C;
    }
    let mut p = LocalProblem::new();
    p.set(
        ball.a_m,
        &[ball],
        &x,
        &[point([0, 1, 3]), point([1, 4, 5]), point([1, 2, 5])],
        &w,
    )
    .unwrap();
    assert!(p.solve([0.004, 0.002, R - 0.0012]).unwrap().1);
    // A clone made now, and the same buffers set up again with the
    // 3-vertex problem (as the triple buffer reuses them).
    let mut copy = LocalProblem::new();
    copy.clone_from(&p);
    let down = [centre[0], centre[1], centre[2] - 1e-4];
    for q in [&mut p, &mut copy] {
        q.set(
            small.tool_m,
            &small.parts[..1],
            &small.x,
            &small.points,
            &small.w,
        )
        .unwrap();
        assert!(q.solve(down).unwrap().1);
    }
    assert_eq!(p.solve(down), small.solve(down));
}

#[test]
fn the_push_through_and_the_full_factorisation_take_the_same_step() {
    // Two triangles side by side (4 vertices), a coupled compliance; the
    // ball pressed into the first: T = its 3 vertices of V's 4.
    let x = [
        [0.0, 0.0, 0.0],
        [0.01, 0.0, 0.0],
        [0.0, 0.01, 0.0],
        [0.01, 0.01, 0.0],
    ];
    let c = [0.01 / 3.0, 0.01 / 3.0, 0.0];
    let centre = [c[0], c[1], R - 0.001];
    let ball = Capsule {
        a_m: centre,
        b_m: centre,
        radius_m: R,
        onset_m: 0.02 * R,
    };
    let points = [
        Point {
            slots: [0, 1, 2],
            weights: [1.0 / 3.0; 3],
            part: 0,
            stiffness_n_per_m: K_P,
        },
        Point {
            slots: [1, 3, 2],
            weights: [1.0 / 3.0; 3],
            part: 0,
            stiffness_n_per_m: K_P,
        },
    ];
    let n = 12;
    let mut w = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            let coupling = 0.2 * ((i * 7 + j * 7) % 5) as f64 / 5.0;
            w[i * n + j] = C * (if i == j { 1.0 } else { 0.0 } + 0.1 * coupling);
        }
    }
    let mut p = LocalProblem::new();
    p.set(centre, &[ball], &x, &points, &w).unwrap();
    // The tool 0.3 mm deeper and aside: only the first point touches.
    let dx = [2e-4, 0.0, -3e-4];
    p.select(dx, 1.0);
    let mut forces = vec![0.0; n];
    let delta = p.delta.clone();
    p.evaluate(&delta, dx, &mut forces, None);
    p.scratch.grad = (0..n).map(|i| p.f0_eff[i] - forces[i]).collect();
    for springs_only in [false, true] {
        let t = p.prepare_step(dx, &mut forces, springs_only);
        assert_eq!(t, 9, "the first triangle's vertices");
        assert!(p.pushed_through_step(t));
        let (step, sstep) = (p.scratch.step.clone(), p.scratch.sstep.clone());
        p.prepare_step(dx, &mut forces, springs_only);
        assert!(p.full_step(t));
        let size = step.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(size > 1e-6, "{step:?}");
        for i in 0..n {
            assert!(
                (step[i] - p.scratch.step[i]).abs() < 1e-9 * size,
                "{step:?} {:?}",
                p.scratch.step
            );
            let ss = sstep.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(
                (sstep[i] - p.scratch.sstep[i]).abs() < 1e-9 * ss,
                "{sstep:?} {:?}",
                p.scratch.sstep
            );
        }
    }
}

#[test]
fn a_spent_time_budget_stops_the_iterations_and_a_generous_one_changes_nothing() {
    let (mut free, centre) = press(0.001);
    let (mut spent, _) = press(0.001);
    let (mut generous, _) = press(0.001);
    spent.set_time_budget(Some(std::time::Duration::ZERO));
    generous.set_time_budget(Some(std::time::Duration::from_secs(10)));
    let down = [centre[0], centre[1], centre[2] - 2e-4];
    let solved = free.solve(down).unwrap().0;
    assert_eq!(generous.solve(down).unwrap().0, solved);
    // No iteration: the vertices where they were, the point's spring
    // alone pressed further (stiffer than in series with the tissue).
    let unsolved = spent.solve(down).unwrap().0;
    assert!(unsolved[2] > solved[2] * 1.5, "{unsolved:?} vs {solved:?}");
    // Given time again, it goes on from there to the same answer.
    spent.set_time_budget(None);
    let resumed = spent.solve(down).unwrap().0;
    assert!(
        norm(sub(resumed, solved)) < 1e-9,
        "{resumed:?} vs {solved:?}"
    );
}

mod inertia;
