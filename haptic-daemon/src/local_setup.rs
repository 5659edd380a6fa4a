//! The thread that sets contact problems up for `local-problem`: it takes
//! the newest `local-contact` message, inverts its compliance
//! ([`LocalProblem::set_from_wire`], a dense factorisation of up to 72 x 72)
//! and, when the message carries the tissue's inertia, condenses the mass,
//! inverts the implicit-step matrices ([`LocalProblem::set_inertia_from_wire`])
//! and steps the problem through the positions the hand took since its
//! state ([`catch_up`]), then hands the problem to the RT thread through a
//! triple buffer. Its own thread, at the lowest
//! normal priority, so that neither the RT thread nor the I/O thread
//! (which carries the poses to the simulation) waits for it: a few
//! milliseconds of dense algebra a problem, which at normal priority
//! shared a core with an RT thread without SCHED_FIFO and made its ticks
//! late (measured with `hapbench latency`, docs/results/latency.md).

use crate::daemon::Shared;
use crate::extrapolate::local_problem::{LocalContactMsg, LocalProblem, LocalProblemError};
use crate::pose_history::PoseHistory;
use crate::transport::{Transport, TransportError};
use shared::SessionName;
use shared::protocol::PROTOCOL_VERSION;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// How long the thread sleeps when no problem came (the simulation sends
/// one at most every 8 ms).
const POLL: Duration = Duration::from_millis(1);

/// How the set-up thread treats the problems.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalSetup {
    /// The RT thread's period (ns): a step of a problem with inertia.
    pub tick_ns: u64,
    /// Use the tissue's inertia when a problem carries it (false: every
    /// problem quasi-static).
    pub inertia: bool,
}

/// The share of a tick the RT thread's render of a problem may take before
/// it stops iterating (the solve goes on at the next tick): the rest of the
/// tick is the device's I/O and the safety filter, tens of microseconds.
pub const RENDER_SHARE_OF_TICK: f64 = 0.3;

/// At most this many of the hand's positions a problem is stepped
/// through before the RT thread takes it (one per tick: 100 ms at 1 kHz,
/// the oldest problem the RT thread uses).
pub const MAX_CATCH_UP: usize = 100;

/// Steps `problem` (with inertia, just set from a message whose state is
/// at `taken_ns`) through the hand's positions since then, as `history`
/// recorded them, up to the newest (looked at again until no new one came,
/// at most three times): the RT thread then goes on from now, a tick a
/// step. The first step spans from `taken_ns` to the first position (at
/// least `tick_s`). `Ok(false)`: the message carries no inertia. A step
/// that fails (contact the problem cannot resolve within its rounds) ends
/// the catch-up there: the RT thread goes on from the state reached.
pub fn catch_up(
    problem: &mut LocalProblem,
    msg: &LocalContactMsg,
    history: &PoseHistory,
    tick_s: f64,
    poses: &mut Vec<(u64, [f64; 3])>,
) -> Result<bool, LocalProblemError> {
    // Positions overwritten while read come back empty: no catch-up.
    history.since(msg.t_ns, MAX_CATCH_UP, poses);
    let first_s = poses.first().map_or(tick_s, |(t, _)| {
        (t.saturating_sub(msg.t_ns) as f64 * 1e-9).max(tick_s)
    });
    if !problem.set_inertia_from_wire(msg, first_s, tick_s)? {
        return Ok(false);
    }
    let mut last_ns = msg.t_ns;
    for _ in 0..3 {
        if poses.is_empty() {
            break;
        }
        for &(t, p) in poses.iter() {
            if !problem.catch_up(t, p) {
                return Ok(true);
            }
            last_ns = t;
        }
        if !history.since(last_ns, MAX_CATCH_UP, poses) {
            break;
        }
    }
    Ok(true)
}

/// Runs until the RT thread is done: each new problem in `session` set up
/// into `input` as `setup` says and published (counted in `shared`; one of
/// another protocol version or malformed is refused and counted).
pub fn run_local_setup(
    shared: Arc<Shared>,
    transport: Transport,
    session: SessionName,
    setup: LocalSetup,
    mut input: triple_buffer::Input<LocalProblem>,
) -> Result<(), TransportError> {
    // Best effort: without it the set-up only competes more.
    let _ = crate::rt::lowest_priority();
    let (mut sub, _node) = transport.local_contact_source(&session)?;
    let mut poses = Vec::with_capacity(MAX_CATCH_UP);
    while !shared.flags.rt_done.load(Ordering::Acquire) {
        let mut newest = None;
        while let Some(sample) = sub.pop() {
            newest = Some(sample);
        }
        let Some(msg) = newest else {
            std::thread::sleep(POLL);
            continue;
        };
        // The device drives tool 0: a problem of another tool is not ours.
        if msg.tool != 0 {
            continue;
        }
        let problem = input.input_buffer_mut();
        // No time budget while it is set up and caught up (this thread's
        // time), the RT thread's once it renders.
        problem.set_time_budget(None);
        let mut ok = msg.version == PROTOCOL_VERSION && problem.set_from_wire(&msg).is_ok();
        let mut inertial = false;
        if ok && setup.inertia {
            let tick_s = setup.tick_ns as f64 * 1e-9;
            match catch_up(problem, &msg, &shared.pose_history, tick_s, &mut poses) {
                Ok(with) => inertial = with,
                Err(_) => ok = false,
            }
        }
        problem.set_time_budget(Some(Duration::from_nanos(
            (setup.tick_ns as f64 * RENDER_SHARE_OF_TICK) as u64,
        )));
        if ok {
            input.publish();
            shared.local_problems.fetch_add(1, Ordering::Relaxed);
            if inertial {
                shared
                    .local_problems_inertial
                    .fetch_add(1, Ordering::Relaxed);
            }
        } else {
            shared
                .local_problems_refused
                .fetch_add(1, Ordering::Relaxed);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extrapolate::local_problem::{Capsule, Point};

    /// A triangle under a ball pressed 1 mm in, with the tissue's inertia.
    fn message(t_ns: u64) -> Box<LocalContactMsg> {
        let mut msg = Box::<LocalContactMsg>::default();
        msg.t_ns = t_ns;
        msg.seq = 3;
        let centre = [0.01 / 3.0, 0.01 / 3.0, 0.004];
        msg.tool_position_m = centre;
        msg.part_count = 1;
        msg.parts[0] = Capsule {
            a_m: centre,
            b_m: centre,
            radius_m: 0.005,
            onset_m: 1e-4,
        };
        msg.vertex_count = 3;
        msg.positions_m[..3].copy_from_slice(&[[0.0; 3], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]]);
        msg.point_count = 1;
        msg.points[0] = Point {
            weights: [1.0 / 3.0; 3],
            stiffness_n_per_m: 300.0,
            slots: [0, 1, 2],
            part: 0,
        };
        for d in 0..9 {
            msg.compliance_m_per_n[d * 9 + d] = 0.01;
            msg.column_mass[d * 9 + d] = 0.01 * 0.01 * 0.01;
        }
        msg.velocities_m_per_s[..3].fill([0.0, 0.0, -0.01]);
        msg.damping_per_s = 10.0;
        msg.inertia = 1;
        msg
    }

    #[test]
    fn a_problem_is_caught_up_through_the_positions_since_its_state() {
        let ms = 1_000_000;
        let msg = message(10 * ms);
        let history = PoseHistory::default();
        let path = |k: u64| {
            [
                0.01 / 3.0 + 1e-4 * k as f64,
                0.01 / 3.0,
                0.004 - 2e-5 * k as f64,
            ]
        };
        // Positions before the state (5 to 7.5 ms) and after it (13 and
        // 13.5 ms: the first step spans 3 ms).
        for k in 0..8u64 {
            history.push(
                5 * ms + k * ms / 2 + if k >= 6 { 5 * ms } else { 0 },
                path(k),
            );
        }
        let mut poses = Vec::new();
        let mut caught = LocalProblem::new();
        caught.set_from_wire(&msg).unwrap();
        assert_eq!(
            catch_up(&mut caught, &msg, &history, 1e-3, &mut poses),
            Ok(true)
        );
        // By hand: the same steps.
        let mut by_hand = LocalProblem::new();
        by_hand.set_from_wire(&msg).unwrap();
        assert_eq!(by_hand.set_inertia_from_wire(&msg, 3e-3, 1e-3), Ok(true));
        for k in 6..8u64 {
            let t = 5 * ms + k * ms / 2 + 5 * ms;
            assert!(by_hand.catch_up(t, path(k)));
        }
        let sample = crate::extrapolate::ForceSample {
            t_ns: msg.t_ns,
            seq: msg.seq,
            position_m: msg.tool_position_m,
            force_n: [0.0, 0.0, 0.3],
            stiffness_n_per_m: [[0.0; 3]; 3],
            in_contact: true,
            catching_up: false,
        };
        // (At 16 ms: the hand's 0.2 mm from 13.5 ms is slow enough for a
        // problem to render.)
        let next = path(9);
        let a = caught
            .render(&sample, 16 * ms, next, f64::INFINITY)
            .unwrap();
        let b = by_hand
            .render(&sample, 16 * ms, next, f64::INFINITY)
            .unwrap();
        assert_eq!(a, b);
        // Without inertia in the message: quasi-static, nothing stepped.
        let mut plain = message(10 * ms);
        plain.inertia = 0;
        let mut quasi = LocalProblem::new();
        quasi.set_from_wire(&plain).unwrap();
        assert_eq!(
            catch_up(&mut quasi, &plain, &history, 1e-3, &mut poses),
            Ok(false)
        );
        assert!(!quasi.has_inertia());
    }
}
