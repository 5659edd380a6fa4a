//! The thread that sets contact problems up for `local-problem`: it takes
//! the newest `local-contact` message, inverts its compliance
//! ([`LocalProblem::set_from_wire`], a dense factorisation of up to 72 x 72)
//! and hands the problem to the RT thread through a triple buffer. Its own
//! thread, at normal priority, so that neither the RT thread nor the I/O
//! thread (which carries the poses to the simulation) waits for it.

use crate::daemon::Shared;
use crate::extrapolate::local_problem::LocalProblem;
use shared::SessionName;
use shared::protocol::PROTOCOL_VERSION;
use shared::services::{self, ServiceError};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// How long the thread sleeps when no problem came (the simulation sends
/// one about every 4 ms).
const POLL: Duration = Duration::from_millis(1);

/// Runs until the RT thread is done: each new problem in `session` set up
/// into `input` and published (counted in `shared`; one of another
/// protocol version or malformed is refused and counted).
pub fn run_local_setup(
    shared: Arc<Shared>,
    session: SessionName,
    mut input: triple_buffer::Input<LocalProblem>,
) -> Result<(), ServiceError> {
    let node = services::node("haptic-daemon-local")?;
    let sub = services::subscriber_with_buffer(
        &services::local_contact_service(&node, &session)?,
        services::FORCE_BUFFER_LATEST,
    )?;
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
        let ok =
            msg.version == PROTOCOL_VERSION && input.input_buffer_mut().set_from_wire(&msg).is_ok();
        drop(msg);
        if ok {
            input.publish();
            shared.local_problems.fetch_add(1, Ordering::Relaxed);
        } else {
            shared
                .local_problems_refused
                .fetch_add(1, Ordering::Relaxed);
        }
    }
    Ok(())
}
