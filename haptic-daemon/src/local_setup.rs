//! The thread that sets contact problems up for `local-problem`: it takes
//! the newest `local-contact` message, inverts its compliance
//! ([`LocalProblem::set_from_wire`], a dense factorisation of up to 72 x 72)
//! and, when the message carries the tissue's inertia, condenses the mass
//! and inverts the two implicit-step matrices (the first step's, which
//! spans the problem's age when the RT thread first renders it, and a
//! tick's: [`LocalProblem::set_inertia_from_wire`]), then hands the problem
//! to the RT thread through a triple buffer. Its own thread, at the lowest
//! normal priority, so that neither the RT thread nor the I/O thread
//! (which carries the poses to the simulation) waits for it: a few
//! milliseconds of dense algebra a problem, which at normal priority
//! shared a core with an RT thread without SCHED_FIFO and made its ticks
//! late (measured with `hapbench latency`, README).

use crate::daemon::Shared;
use crate::extrapolate::local_problem::LocalProblem;
use shared::protocol::PROTOCOL_VERSION;
use shared::services::{self, ServiceError};
use shared::{SessionName, monotonic_ns};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// How long the thread sleeps when no problem came (the simulation sends
/// one about every 4 ms).
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

/// The first implicit step of a problem with inertia (s): from its step's
/// time `taken_ns` to the RT thread's first render of it, expected half a
/// tick after `now_ns` (the RT thread takes a new problem at its next
/// tick); at least a tick.
pub fn first_step_s(taken_ns: u64, now_ns: u64, tick_ns: u64) -> f64 {
    (now_ns.saturating_sub(taken_ns) + tick_ns / 2).max(tick_ns) as f64 * 1e-9
}

/// Runs until the RT thread is done: each new problem in `session` set up
/// into `input` as `setup` says and published (counted in `shared`; one of
/// another protocol version or malformed is refused and counted).
pub fn run_local_setup(
    shared: Arc<Shared>,
    session: SessionName,
    setup: LocalSetup,
    mut input: triple_buffer::Input<LocalProblem>,
) -> Result<(), ServiceError> {
    // Best effort: without it the set-up only competes more.
    let _ = crate::rt::lowest_priority();
    let node = services::node("haptic-daemon-local")?;
    let sub = services::subscriber_with_buffer(
        &services::local_contact_service(&node, &session)?,
        services::FORCE_BUFFER_LATEST,
    )?;
    // How long the last problem's inertia took to set up (ns).
    let mut inertia_setup_ns = 0;
    while !shared.flags.rt_done.load(Ordering::Acquire) {
        let mut newest = None;
        while let Ok(Some(sample)) = sub.receive() {
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
        problem.set_time_budget(Some(Duration::from_nanos(
            (setup.tick_ns as f64 * RENDER_SHARE_OF_TICK) as u64,
        )));
        let mut ok = msg.version == PROTOCOL_VERSION && problem.set_from_wire(&msg).is_ok();
        let mut inertial = false;
        if ok && setup.inertia {
            let tick_s = setup.tick_ns as f64 * 1e-9;
            // The RT thread first renders it after this set-up: counted
            // with the last one's duration.
            let t0 = monotonic_ns();
            let first_s = first_step_s(msg.t_ns, t0 + inertia_setup_ns, setup.tick_ns);
            match problem.set_inertia_from_wire(&msg, first_s, tick_s) {
                Ok(with) => inertial = with,
                Err(_) => ok = false,
            }
            inertia_setup_ns = monotonic_ns().saturating_sub(t0);
        }
        drop(msg);
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
