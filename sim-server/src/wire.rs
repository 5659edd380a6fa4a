//! The force sample on the wire: a step's tool reports and reactions into
//! the protocol's `ForceMsg` (the only conversion from the simulation's
//! [`Reaction`] to the wire: the server and hapbench both use it), and the
//! contact problem around a tool into `LocalContactMsg`.

use crate::backend::Backend;
use crate::contact::penalty::field::ONSET_OF_RADIUS;
use crate::contact::{ContactReport, LocalContact, LocalSpec, Reaction, Tools};
use crate::math::Vec3;
use shared::protocol::{
    CATCHING_UP, CONTACT, CUTTING, ForceMsg, GRIPPING, LOCAL_MAX_PARTS, LOCAL_MAX_POINTS,
    LOCAL_MAX_VERTICES, LocalContactMsg, LocalPart, LocalPoint, MAX_TOOLS, PROTOCOL_VERSION,
    ToolForce,
};

/// Each tool's protocol flags from its report of the step.
pub fn tool_flags(reports: &[ContactReport]) -> [u32; MAX_TOOLS] {
    let mut flags = [0u32; MAX_TOOLS];
    for (f, r) in flags.iter_mut().zip(reports) {
        *f = (u32::from(r.contact) * CONTACT)
            | (u32::from(r.gripping) * GRIPPING)
            | (u32::from(r.tets_removed > 0) * CUTTING)
            | (u32::from(r.catching_up) * CATCHING_UP);
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

/// Tool `tool`'s contact problem after a step as the wire carries it (the
/// `local-contact` stream), taken at the step whose force message has
/// `seq`, `t_ns`; `lc` within the message's capacity (as
/// [`local_contact_into`] asks for it).
pub fn local_contact_msg(
    lc: &LocalContact,
    tool: u32,
    seq: u64,
    t_ns: u64,
    out: &mut LocalContactMsg,
) {
    let nv = lc.vertices.len().min(LOCAL_MAX_VERTICES);
    let np = lc.points.len().min(LOCAL_MAX_POINTS);
    let nc = lc.parts.len().min(LOCAL_MAX_PARTS);
    out.version = PROTOCOL_VERSION;
    out.tool = tool;
    out.seq = seq;
    out.t_ns = t_ns;
    out.tool_position_m = lc.tool_position_m.to_array();
    out.part_count = nc as u32;
    out.vertex_count = nv as u32;
    out.point_count = np as u32;
    for (o, p) in out.parts.iter_mut().zip(&lc.parts[..nc]) {
        *o = LocalPart {
            a_m: p.segment.a_m.to_array(),
            b_m: p.segment.b_m.to_array(),
            radius_m: p.radius_m,
            onset_m: ONSET_OF_RADIUS * p.radius_m,
        };
    }
    for (o, x) in out.positions_m.iter_mut().zip(&lc.positions_m[..nv]) {
        *o = x.to_array();
    }
    for (o, p) in out.points.iter_mut().zip(&lc.points[..np]) {
        *o = LocalPoint {
            weights: p.weights,
            stiffness_n_per_m: p.stiffness_n_per_m,
            slots: p.slots,
            part: p.part as u16,
        };
    }
    let n = 3 * nv;
    if lc.compliance_m_per_n.len() == n * n {
        out.compliance_m_per_n[..n * n].copy_from_slice(&lc.compliance_m_per_n);
    } else {
        // Without a compliance (never published so): nothing to solve.
        out.vertex_count = 0;
        out.point_count = 0;
    }
    let inertia = lc.column_mass.len() == n * n && lc.velocities_m_per_s.len() == nv && nv > 0;
    out.inertia = u32::from(inertia);
    if inertia {
        out.column_mass[..n * n].copy_from_slice(&lc.column_mass);
        for (o, v) in out
            .velocities_m_per_s
            .iter_mut()
            .zip(&lc.velocities_m_per_s)
        {
            *o = v.to_array();
        }
        out.damping_per_s = lc.damping_per_s;
    } else {
        out.damping_per_s = 0.0;
    }
}

/// How far beyond a step's reach the contact problem sent to the haptic
/// loop reaches (m): what a hand moving at 50 mm/s covers in the ~60 ms a
/// 30 Hz sample is old when the next one arrives. Measured (`hapbench
/// extrapolation`, box paths): 2 mm loses the tool off the sampled
/// surface in slides, 3 and 4 mm give the same errors.
pub const LOCAL_MARGIN_M: f64 = 3e-3;

/// At least this much simulated time between two contact problems (s):
/// each 30-60 Hz sample gets its own, a faster simulation one every few
/// samples (the daemon re-bases each newer sample on the problem it has).
/// Sampling, the compliance, the column mass and the daemon's set-up cost
/// some milliseconds of CPU a problem, which at the stiffness solver's
/// ~4 ms pace took a 2-core machine's spare time and the daemon's tick
/// deadlines with it (measured: `hapbench latency`, docs/results/latency.md).
pub const LOCAL_EVERY_S: f64 = 0.008;

/// The contact problem of tool `tool` the wire can carry: points
/// [`LOCAL_MARGIN_M`] beyond the step's reach, within the message's
/// capacity, with the tissue's inertia when the backend has any
/// (`dynamic`; a static one's problems are quasi-static, as it is), at
/// most one every [`LOCAL_EVERY_S`].
pub fn local_spec(tool: usize, dynamic: bool) -> LocalSpec {
    LocalSpec {
        tool,
        margin_m: LOCAL_MARGIN_M,
        max_vertices: LOCAL_MAX_VERTICES,
        max_points: LOCAL_MAX_POINTS,
        inertia: dynamic,
        every_s: LOCAL_EVERY_S,
    }
}

/// Tool `tool`'s contact problem after the last step into `lc`, now, as
/// the wire can carry it (with the inertia of a dynamic backend); false
/// when there is none (see [`Tools::local_contact`]).
pub fn local_contact_into<B: Backend>(
    tools: &mut Tools,
    sim: &B,
    tool: usize,
    lc: &mut LocalContact,
) -> bool {
    tools.local_contact(sim, local_spec(tool, sim.capabilities().dynamic), lc)
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
