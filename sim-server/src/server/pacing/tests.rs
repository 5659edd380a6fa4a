//! The pacing's unit tests.

use super::*;

const MS: u64 = 1_000_000;

/// Simulates a loop of steps costing `cost_ns` that waits for the due
/// time (no poses); `stop_at` = (wall time, length) of a stall. Returns
/// the (start time, step index) of every step until `end_ns`, and the pacing.
fn simulate(
    step_ns: u64,
    cost_ns: u64,
    stall: Option<(u64, u64)>,
    end_ns: u64,
) -> (Vec<(u64, u64)>, Pacing) {
    let mut p = Pacing::new(0, step_ns);
    let mut now = 0;
    let mut steps = 0;
    let mut starts = Vec::new();
    let mut stalled = false;
    while now < end_ns {
        now = now.max(p.due(steps));
        starts.push((now, steps));
        now += cost_ns;
        if let Some((at, len)) = stall
            && !stalled
            && now >= at
        {
            now += len;
            stalled = true;
        }
        steps += 1;
        p.catch_up(steps, now);
    }
    (starts, p)
}

#[test]
fn a_paced_loop_runs_at_the_real_time_rate_and_drops_nothing() {
    let (starts, p) = simulate(MS, MS / 2, None, 1000 * MS);
    assert_eq!(p.stalls(), 0);
    assert_eq!(p.dropped_ns(), 0);
    for (t, k) in starts {
        assert_eq!(t, k * MS);
    }
}

#[test]
fn after_a_stall_the_missed_steps_are_dropped_not_run_fast() {
    // 400 ms stopped at t = 100 ms, 1 ms steps costing 0.6 ms.
    let (starts, p) = simulate(MS, 600_000, Some((100 * MS, 400 * MS)), 1000 * MS);
    assert_eq!(p.stalls(), 1);
    let dropped = p.dropped_ns();
    assert!(
        (399 * MS..=401 * MS).contains(&dropped),
        "dropped {dropped} ns"
    );
    // No two steps after the stall closer than a step: no fast-forward.
    let after: Vec<_> = starts.iter().filter(|(t, _)| *t > 500 * MS).collect();
    for w in after.windows(2) {
        assert!(w[1].0 - w[0].0 >= MS, "steps {:?} and {:?}", w[0], w[1]);
    }
    // Simulated time + dropped time = wall time (to a step).
    let &(t, k) = starts.last().unwrap();
    let lag = t as i64 - (k * MS + dropped) as i64;
    assert!(lag.unsigned_abs() <= MS, "lag {lag} ns");
}

#[test]
fn a_step_or_two_of_lateness_is_caught_up_not_dropped() {
    let mut p = Pacing::new(0, MS);
    // Step 1 ran 1.5 ms long: the next is 1.5 ms late, within 5 ms.
    assert_eq!(p.catch_up(1, 2_500_000), None);
    assert_eq!(p.due(1), MS);
    // 6 ms late: dropped.
    assert_eq!(p.catch_up(2, 8 * MS), Some(6 * MS));
    assert_eq!(p.due(2), 8 * MS);
    assert_eq!(p.due(3), 9 * MS);
}

#[test]
fn the_bound_is_two_steps_or_5_ms_and_the_early_window_two_steps_or_2_ms() {
    let fast = Pacing::new(0, MS);
    assert_eq!(fast.bound_ns, 5 * MS);
    assert_eq!(fast.early_ns, 2 * MS);
    let slow = Pacing::new(0, 33 * MS);
    assert_eq!(slow.bound_ns, 66 * MS);
    assert_eq!(slow.early_ns, 2 * MS);
    assert_eq!(slow.earliest(1), 31 * MS);
}

/// Real time: simulated time (a step each, 1 ms steps) within the
/// early window (two steps) and half a step of the last start.
fn assert_real_time(out: &[(u64, bool, u64)]) {
    let (t, _, _) = *out.last().unwrap();
    let k = out.len() as u64 - 1;
    let lag = t as i64 - (k * MS) as i64;
    assert!(lag.unsigned_abs() <= 5 * MS / 2, "{k} steps by {t} ns");
}

/// A loop of steps costing `cost_ns` with poses every `pose_ns` from
/// `first_ns`, each late by a jitter cycling through `jitter_ns`: the
/// loop waits for the due time or, from the earliest, a pose that has
/// arrived and was not used yet, and takes the newest. Returns, per
/// step, (start, whether it started on a pose, how long the pose it
/// took had waited), the pacing, and the phase after each step.
fn with_poses(
    step_ns: u64,
    cost_ns: u64,
    pose_ns: u64,
    first_ns: u64,
    jitter_ns: &[u64],
    end_ns: u64,
) -> (Vec<(u64, bool, u64)>, Pacing, Vec<i64>) {
    let mut phases = Vec::new();
    let mut p = Pacing::new(0, step_ns);
    let (mut now, mut steps, mut next_pose) = (0, 0u64, 0u64);
    let arrival = |j: u64| first_ns + j * pose_ns + jitter_ns[j as usize % jitter_ns.len()];
    let mut out = Vec::new();
    while now < end_ns {
        let (earliest, due) = (p.earliest(steps), p.due(steps));
        // The newest pose that has arrived by the time the loop looks.
        let waiting = arrival(next_pose).max(now).max(earliest);
        let (start, on_pose) = if waiting < due.max(now) {
            (waiting, true)
        } else {
            (due.max(now), false)
        };
        let mut waited = 0;
        // The loop was waiting in the window when the pose came.
        let on_arrival = on_pose && arrival(next_pose) >= now.max(earliest);
        // The newest pose that arrived by the start is the one taken.
        while arrival(next_pose + 1) <= start {
            next_pose += 1;
        }
        if on_pose {
            p.started_on_pose(steps, start);
            // Read on the device 50 us before it arrives.
            p.observe_pose(next_pose, arrival(next_pose) - 50_000, start, on_arrival);
            waited = start - arrival(next_pose);
        }
        while arrival(next_pose) <= start {
            next_pose += 1;
        }
        out.push((start, on_pose, waited));
        phases.push(p.phase_ns());
        now = start + cost_ns;
        steps += 1;
        p.catch_up(steps, now);
    }
    (out, p, phases)
}

#[test]
fn the_grid_locks_onto_poses_that_arrive_about_when_each_step_falls_due() {
    // Poses 50 us before each step falls due, late by up to 200 us,
    // steps of 150 us: unlocked, every step whose pose is late starts
    // on the clock with the old pose, and the fresh one waits for it.
    let jitter = [0, 100_000, 30_000, 170_000, 60_000, 200_000, 10_000];
    let (out, p, _) = with_poses(MS, 150_000, MS, MS - 50_000, &jitter, 2000 * MS);
    let settled = &out[200..];
    assert!(
        settled
            .iter()
            .all(|(_, on_pose, waited)| *on_pose && *waited == 0),
        "after settling every step starts on its pose at once"
    );
    assert!(p.phase_ns().unsigned_abs() <= MS / 2);
    // Real time: simulated time within the early window (two steps)
    // and half a step of wall time.
    assert_real_time(&out);
    assert_eq!(p.stalls(), 0);
}

#[test]
fn poses_at_another_rate_leave_the_loop_at_the_real_time_rate() {
    for pose_ns in [MS / 2, MS / 3, 3 * MS / 2] {
        let (out, p, _) = with_poses(MS, 200_000, pose_ns, 123_000, &[0, 40_000], 5000 * MS);
        let (t, _, _) = *out.last().unwrap();
        let k = out.len() as u64 - 1;
        let lag = t as i64 - (k * MS) as i64;
        assert!(
            lag.unsigned_abs() <= 5 * MS / 2,
            "poses every {pose_ns} ns: {k} steps by {t} ns"
        );
        assert!(p.phase_ns().unsigned_abs() <= MS / 2);
    }
}

#[test]
fn poses_slightly_slower_than_the_grid_keep_arriving_inside_the_window() {
    // The daemon's poses 0.4% slower than the grid with jitter: the
    // phase follows them and wraps; almost every pose is taken at once.
    let jitter = [0, 60_000, 20_000, 90_000, 40_000];
    let (out, _, _) = with_poses(MS, 150_000, 1_004_000, 300_000, &jitter, 10_000 * MS);
    let settled = &out[500..];
    let on_pose: Vec<_> = settled.iter().filter(|(_, p, _)| *p).collect();
    let waited = on_pose.iter().filter(|(_, _, w)| *w > 100_000).count();
    assert!(
        waited * 100 < on_pose.len(),
        "{waited} of {} poses waited over 0.1 ms",
        on_pose.len()
    );
    assert_real_time(&out);
}

#[test]
fn poses_faster_than_the_steps_hold_the_phase_still() {
    // A 2 or 4 kHz device (omega, Falcon) against 1 ms steps, jittered:
    // several poses to a step, followed by the age of the pose taken.
    // Followed as one pose a step, the first pose in the window always
    // looked early, the phase drifted on and wrapped every few tens of
    // steps (a step lost each time).
    for pose_ns in [MS / 2, MS / 4] {
        let jitter = [0, 60_000, 20_000, 90_000, 40_000];
        let jitter: Vec<u64> = jitter.iter().map(|j| j * pose_ns / MS).collect();
        let (out, p, phases) = with_poses(MS, 150_000, pose_ns, 123_000, &jitter, 3000 * MS);
        let settled = 500..out.len();
        let wraps = phases[settled.clone()]
            .windows(2)
            .filter(|w| (w[1] - w[0]).unsigned_abs() > MS / 4)
            .count();
        assert_eq!(wraps, 0, "poses every {pose_ns} ns: the phase wrapped");
        // Each step takes a pose that waited at most an eighth of a
        // period beyond its jitter (the lock's margin) for the window.
        let max_jitter = jitter.iter().max().unwrap();
        let longest = out[settled.clone()].iter().map(|o| o.2).max();
        assert!(
            out[settled]
                .iter()
                .all(|(_, on_pose, waited)| *on_pose && *waited <= pose_ns / 8 + max_jitter),
            "poses every {pose_ns} ns: longest wait {longest:?}"
        );
        assert_real_time(&out);
        assert_eq!(p.stalls(), 0);
    }
}

#[test]
fn the_pose_period_comes_from_sequence_numbers_and_device_times() {
    let mut p = Pacing::new(0, MS);
    p.observe_pose(10, 5 * MS, 5 * MS, true);
    assert_eq!(p.pose_period_ns, 0, "one pose: no period yet");
    // Two poses in a millisecond (the loop saw every other one).
    p.observe_pose(12, 6 * MS, 6 * MS, true);
    assert_eq!(p.pose_period_ns, MS / 2);
    // The same pose again, then a restarted daemon: no interval.
    p.observe_pose(12, 7 * MS, 7 * MS, true);
    p.observe_pose(3, 8 * MS, 8 * MS, true);
    assert_eq!(p.pose_period_ns, MS / 2);
    // Four in a millisecond: an eighth of the way there.
    p.observe_pose(7, 9 * MS, 9 * MS, true);
    assert_eq!(p.pose_period_ns, (7 * (MS / 2) + MS / 4) / 8);
}

#[test]
fn steps_longer_than_a_millisecond_do_not_follow_the_poses() {
    let mut p = Pacing::new(0, 33 * MS);
    p.started_on_pose(3, p.earliest(3));
    assert_eq!(p.phase_ns(), 0);
    let mut q = Pacing::new(0, MS);
    q.started_on_pose(3, q.earliest(3));
    assert!(
        q.phase_ns() < 0,
        "a pose at the window's start moves the grid earlier"
    );
}
