//! The `local-contact` stream: the contact problem around tool 0 (the
//! haptic daemon's `local-problem` extrapolator solves it again at every
//! tick). Made only while someone subscribes (looked at once a second):
//! taking the points costs the step a fresh selection around the tool
//! every few milliseconds, and the compliance costs the stiffness
//! worker sparse solves for vertices it has not seen.

use super::RunError;
use shared::SessionName;
use shared::protocol::LocalContactMsg;
use shared::services::{self, IpcNode, LocalContactPublisher};
use sim_server::contact::Tools;
use sim_server::wire::{local_contact_msg, local_spec};

/// How often the subscribers are counted (ns).
const CHECK_EVERY_NS: u64 = 1_000_000_000;

/// The stream's publisher and whether problems are being made.
pub struct LocalOut {
    factory: services::LocalContactService,
    publisher: LocalContactPublisher,
    wanted: bool,
    checked_ns: u64,
    /// Problems published.
    pub published: u64,
    /// Problems that could not be published.
    pub dropped: u64,
}

impl LocalOut {
    /// Opens the stream in `session`.
    pub fn new(node: &IpcNode, session: &SessionName) -> Result<Self, RunError> {
        let factory = services::local_contact_service(node, session)?;
        let publisher = services::publisher(&factory)?;
        Ok(Self {
            factory,
            publisher,
            wanted: false,
            checked_ns: 0,
            published: 0,
            dropped: 0,
        })
    }

    /// After a step whose force message had `seq`, at `now_ns`: asks the
    /// tools for problems while someone listens, and publishes a finished
    /// one (stamped with the `seq` of the step it was taken at). A problem
    /// that cannot be published is dropped and counted (the daemon falls
    /// back to `local-normal` without it); it never stops the simulation.
    pub fn publish(&mut self, tools: &mut Tools, seq: u64, now_ns: u64) {
        if now_ns.saturating_sub(self.checked_ns) >= CHECK_EVERY_NS {
            self.checked_ns = now_ns;
            let wanted = !tools.is_empty() && services::subscriber_count(&self.factory) > 0;
            if wanted != self.wanted {
                self.wanted = wanted;
                tools.set_local_contact(wanted.then(|| local_spec(0)));
            }
        }
        let Some(lc) = tools.take_local_contact() else {
            return;
        };
        // Steps and messages advance together: the step it was taken at
        // is this many messages back.
        let taken_seq = seq.saturating_sub(tools.steps().saturating_sub(lc.step));
        let sent = match self.publisher.loan() {
            Ok(mut sample) => {
                let msg: &mut LocalContactMsg = sample.payload_mut();
                local_contact_msg(&lc, 0, taken_seq, now_ns, msg);
                sample.send().is_ok()
            }
            Err(_) => false,
        };
        tools.recycle_local_contact(lc);
        if sent {
            self.published += 1;
        } else {
            if self.dropped == 0 {
                eprintln!(
                    "sim-server: a contact problem could not be published (dropped and counted)"
                );
            }
            self.dropped += 1;
        }
    }
}
