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
/// The state times of this many recent steps are kept, to stamp a problem
/// with its own step's (the worker hands it over a few steps on).
const STEP_TIMES: usize = 64;

/// The stream's publisher and whether problems are being made.
pub struct LocalOut {
    factory: services::LocalContactService,
    publisher: LocalContactPublisher,
    wanted: bool,
    checked_ns: u64,
    /// The time of each step's state (see [`LocalOut::after_sample`]), by
    /// its force message's `seq` modulo [`STEP_TIMES`].
    state_times_ns: [u64; STEP_TIMES],
    /// `seq` of the newest force message.
    last_seq: u64,
    /// Whether the backend has inertia (its problems carry it; a static
    /// backend's are quasi-static).
    dynamic: bool,
    /// Problems published.
    pub published: u64,
    /// Problems that could not be published, or were too old to be (a
    /// stalled stiffness worker).
    pub dropped: u64,
}

impl LocalOut {
    /// Opens the stream in `session`.
    pub fn new(node: &IpcNode, session: &SessionName, dynamic: bool) -> Result<Self, RunError> {
        let factory = services::local_contact_service(node, session)?;
        let publisher = services::publisher(&factory)?;
        Ok(Self {
            factory,
            publisher,
            dynamic,
            wanted: false,
            checked_ns: 0,
            state_times_ns: [0; STEP_TIMES],
            last_seq: 0,
            published: 0,
            dropped: 0,
        })
    }

    /// Whether problems are being made (someone listens).
    pub fn wanted(&self) -> bool {
        self.wanted
    }

    /// After a step whose force message had `seq` and `now_ns` (its `t_ns`),
    /// its state being that of `state_ns` (the device time of the pose the
    /// step used: the step held the tool there, so its state is the
    /// tissue's answer to the hand where it was then, a whole period
    /// before the sample for a simulation whose step takes its period):
    /// asks the tools for problems while someone listens, and publishes a
    /// finished one ([`LocalOut::publish_ready`]).
    pub fn after_sample(&mut self, tools: &mut Tools, seq: u64, now_ns: u64, state_ns: u64) {
        self.state_times_ns[seq as usize % STEP_TIMES] = state_ns.min(now_ns);
        self.last_seq = seq;
        if now_ns.saturating_sub(self.checked_ns) >= CHECK_EVERY_NS {
            self.checked_ns = now_ns;
            let wanted = !tools.is_empty() && services::subscriber_count(&self.factory) > 0;
            if wanted != self.wanted {
                self.wanted = wanted;
                tools.set_local_contact(wanted.then(|| local_spec(0, self.dynamic)));
            }
        }
        self.publish_ready(tools);
    }

    /// Publishes the newest finished problem, if any (after a step, and
    /// between steps as soon as the stiffness worker has it: the run loop
    /// looks while it waits), stamped with the `seq` of the step it was
    /// taken at and that step's state time. A problem that cannot be
    /// published is dropped and counted (the daemon falls back to
    /// `local-normal` without it); it never stops the simulation.
    pub fn publish_ready(&mut self, tools: &mut Tools) {
        let Some(lc) = tools.take_local_contact() else {
            return;
        };
        // Steps and messages advance together: the step it was taken at
        // is this many messages back.
        let seq = self.last_seq;
        let back = tools.steps().saturating_sub(lc.step);
        let taken_seq = seq.saturating_sub(back);
        // Older than the times kept (a stalled worker): its state is long
        // gone and its time unknown; dropped (counted), never sent as new.
        if back as usize >= STEP_TIMES || back > seq {
            tools.recycle_local_contact(lc);
            self.dropped += 1;
            return;
        }
        let taken_ns = self.state_times_ns[taken_seq as usize % STEP_TIMES];
        let sent = match self.publisher.loan() {
            Ok(mut sample) => {
                let msg: &mut LocalContactMsg = sample.payload_mut();
                local_contact_msg(&lc, 0, taken_seq, taken_ns, msg);
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
