//! Driving a tool from the viewer when no haptic daemon is in the session:
//! the viewer then publishes the tool pose itself, and stops as soon as
//! another pose publisher (a daemon) appears, so two sources never fight.

use crate::session::Session;
use iceoryx2::port::publisher::Publisher;
use shared::monotonic_ns;
use shared::protocol::{MAX_TOOLS, PROTOCOL_VERSION, PoseMsg, TOOL_PRESENT};
use shared::services::{self, Ipc};

/// Jaw opening while gripping (below the grip threshold, above cutting).
pub const JAW_GRIP: f64 = 0.3;
/// Jaw opening when cutting.
pub const JAW_CUT: f64 = 0.05;

/// The pose the viewer publishes for one tool.
pub struct Driver {
    publisher: Option<Publisher<Ipc, PoseMsg, ()>>,
    seq: u64,
    /// Which tool the mouse drives.
    pub tool: usize,
    /// Tools in the scene.
    pub tool_count: usize,
    /// Tip position (m).
    pub tip_m: [f64; 3],
    /// Jaw opening, 0 closed to 1 open.
    pub jaw_opening: f64,
}

impl Driver {
    /// Drives tool 0 of `tool_count`, tip at `tip_m`, not publishing yet.
    pub fn new(tool_count: usize, tip_m: [f64; 3]) -> Self {
        Self {
            publisher: None,
            // Pose seq starts at 1: a force sample's pose_seq 0 means "no pose".
            seq: 1,
            tool: 0,
            tool_count: tool_count.min(MAX_TOOLS),
            tip_m,
            jaw_opening: 1.0,
        }
    }

    /// Whether the viewer is the session's pose source.
    pub fn active(&self) -> bool {
        self.publisher.is_some()
    }

    /// Takes the pose stream when nobody publishes on it, gives it up when
    /// someone else does, and publishes the current pose while active.
    pub fn update(&mut self, session: &Session) {
        let ours = usize::from(self.publisher.is_some());
        let others = session.pose_publishers().saturating_sub(ours);
        if others > 0 {
            self.publisher = None;
            return;
        }
        if self.publisher.is_none() {
            let Some(service) = session.pose_port() else {
                return;
            };
            self.publisher = services::publisher(service).ok();
        }
        let Some(p) = &self.publisher else { return };
        let mut msg = PoseMsg {
            version: PROTOCOL_VERSION,
            tool_count: self.tool_count as u32,
            seq: self.seq,
            t_ns: monotonic_ns(),
            ..PoseMsg::default()
        };
        if self.tool < self.tool_count {
            let t = &mut msg.tools[self.tool];
            t.tip_m = self.tip_m;
            t.jaw_opening = self.jaw_opening;
            t.flags = TOOL_PRESENT;
        }
        if p.send_copy(msg).is_ok() {
            self.seq += 1;
        }
    }
}
