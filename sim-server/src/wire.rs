//! The force sample on the wire: a step's tool reports and reactions into
//! the protocol's `ForceMsg` (the only conversion from the simulation's
//! [`Reaction`] to the wire: the server and hapbench both use it).

use crate::backend::Backend;
use crate::contact::{ContactReport, Reaction, Tools};
use crate::math::Vec3;
use shared::protocol::{CONTACT, CUTTING, ForceMsg, GRIPPING, MAX_TOOLS, ToolForce};

/// Each tool's protocol flags from its report of the step.
pub fn tool_flags(reports: &[ContactReport]) -> [u32; MAX_TOOLS] {
    let mut flags = [0u32; MAX_TOOLS];
    for (f, r) in flags.iter_mut().zip(reports) {
        *f = (u32::from(r.contact) * CONTACT)
            | (u32::from(r.gripping) * GRIPPING)
            | (u32::from(r.tets_removed > 0) * CUTTING);
    }
    flags
}

/// The force sample of a step: each tool's reaction, contact stiffness, the
/// position the step used and the pose it came from. `header` holds the
/// message's counters and times; the tools are filled in.
pub fn force_sample<B: Backend>(
    mut header: ForceMsg,
    tools: &Tools,
    sim: &B,
    pose_seq: u64,
    flags: &[u32; MAX_TOOLS],
) -> ForceMsg {
    header.tool_count = tools.len() as u32;
    for (i, c) in tools.iter().enumerate() {
        let out = &mut header.tools[i];
        if c.pose().is_none() {
            // No pose (withdrawn, let go): nothing in contact, whatever a
            // stiffness worker last computed for it.
            out.pose_seq = pose_seq;
            continue;
        }
        // The position this step used: the tool end after clamping to its
        // length.
        let position_m = c.pose().map_or(Vec3::ZERO, |p| p.end_m);
        *out = tool_force(&tools.reaction(i, sim), position_m, pose_seq, flags[i]);
    }
    header
}

/// One tool's reaction as the wire carries it.
pub fn tool_force(r: &Reaction, position_m: Vec3, pose_seq: u64, flags: u32) -> ToolForce {
    ToolForce {
        position_m: position_m.to_array(),
        force_n: r.force_n.to_array(),
        stiffness_n_per_m: r.stiffness_rows(),
        pose_seq,
        flags,
        reserved: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_become_the_protocol_flags() {
        let reports = [
            ContactReport {
                contact: true,
                tets_removed: 3,
                ..ContactReport::default()
            },
            ContactReport {
                gripping: true,
                ..ContactReport::default()
            },
            ContactReport::default(),
        ];
        assert_eq!(tool_flags(&reports), [CONTACT | CUTTING, GRIPPING, 0, 0]);
    }
}
