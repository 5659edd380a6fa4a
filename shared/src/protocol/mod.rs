//! The payloads that cross process boundaries. Every payload is `#[repr(C)]`,
//! fixed size (`MAX_TOOLS` arrays, no pointers or `Vec`), made of plain
//! `f64`/`u64`/`u32` fields, and starts with the protocol version, so a
//! program in another language can read it from `docs/protocol.md` alone.
//!
//! iceoryx2 also compares the type names (`type_name`, which carry the
//! version) and layouts when a service is opened, so a reader built for
//! another version is refused at open time; [`check_version`] catches a
//! mismatch on each payload as a second line of defence.

use bytemuck::{Pod, Zeroable};
use iceoryx2::prelude::ZeroCopySend;
use thiserror::Error;

/// The protocol version; bumped on any change of a payload or its meaning.
pub const PROTOCOL_VERSION: u32 = 1;

/// Tools per session (fixed so payloads have a fixed size).
pub const MAX_TOOLS: usize = 4;

/// Telemetry ticks per batch.
pub const TELEMETRY_BATCH: usize = 64;

/// A payload of another protocol version.
#[derive(Debug, Error, PartialEq, Eq)]
#[error(
    "protocol version mismatch on {stream}: this program speaks version {expected}, the peer sent {found}; rebuild both from the same release"
)]
pub struct VersionError {
    /// Which stream.
    pub stream: &'static str,
    /// Ours.
    pub expected: u32,
    /// Theirs.
    pub found: u32,
}

/// Checks a payload's version field.
pub fn check_version(stream: &'static str, found: u32) -> Result<(), VersionError> {
    if found == PROTOCOL_VERSION {
        Ok(())
    } else {
        Err(VersionError {
            stream,
            expected: PROTOCOL_VERSION,
            found,
        })
    }
}

/// One tool's pose as the device reads it.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.ToolPose.v1")]
pub struct ToolPose {
    /// Tool tip position (m), scene frame.
    pub tip_m: [f64; 3],
    /// Reserved, written as zeros and never read: a tool's shaft always runs
    /// from the scene's fulcrum (its trocar) to the tip. Kept so the
    /// layout (and protocol version 1) stays as published.
    pub shaft_dir: [f64; 3],
    /// Jaw opening, 0 closed to 1 fully open.
    pub jaw_opening: f64,
    /// Device button bits.
    pub buttons: u32,
    /// Bit 0: this tool is present.
    pub flags: u32,
}

/// `ToolPose::flags`: the tool is present.
pub const TOOL_PRESENT: u32 = 1;

/// Daemon -> sim: the latest device pose of every tool (haptic rate, latest value).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.PoseMsg.v1")]
pub struct PoseMsg {
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Tools in use (<= `MAX_TOOLS`).
    pub tool_count: u32,
    /// Increments by one per message (gaps show losses), starting at 1: a
    /// force sample's `pose_seq` 0 means no pose.
    pub seq: u64,
    /// `CLOCK_MONOTONIC` (ns) when the device was read.
    pub t_ns: u64,
    /// Per tool.
    pub tools: [ToolPose; MAX_TOOLS],
}

/// One tool's share of a simulation step.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.ToolForce.v1")]
pub struct ToolForce {
    /// The tool tip position this step used (m).
    pub position_m: [f64; 3],
    /// Force of the tissue on the tool (N).
    pub force_n: [f64; 3],
    /// Contact stiffness (N/m), row-major: dF = -K dP for a small tool motion dP.
    pub stiffness_n_per_m: [[f64; 3]; 3],
    /// `seq` of the pose this step used; 0: none (no live pose).
    pub pose_seq: u64,
    /// [`CONTACT`], [`GRIPPING`], [`CUTTING`], [`CATCHING_UP`] bits.
    pub flags: u32,
    /// Padding (keeps the layout explicit).
    pub reserved: u32,
}

/// `ToolForce::flags`: the tool touches tissue.
pub const CONTACT: u32 = 1;
/// `ToolForce::flags`: the jaws hold tissue.
pub const GRIPPING: u32 = 2;
/// `ToolForce::flags`: the tool removed tissue this step.
pub const CUTTING: u32 = 4;
/// `ToolForce::flags`: the simulated tool is not at the pose asked for and
/// does not follow the hand one for one this step (it is coming in slowly
/// near the tissue after a let-go or a jump, or the tissue's surface holds
/// it short): the force is the tool's at `position_m`, and a reader must
/// not extrapolate it by the hand's motion from there.
pub const CATCHING_UP: u32 = 8;

/// Sim -> daemon: one message per simulation step.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.ForceMsg.v1")]
pub struct ForceMsg {
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Tools in use.
    pub tool_count: u32,
    /// Increments by one per step.
    pub seq: u64,
    /// `CLOCK_MONOTONIC` (ns) when the step finished.
    pub t_ns: u64,
    /// Simulated time (ns since the simulation started).
    pub sim_time_ns: u64,
    /// Wall-clock period of the last step (ns).
    pub step_period_ns: u64,
    /// Per tool.
    pub tools: [ToolForce; MAX_TOOLS],
}

/// [`LocalContactMsg`]: at most this many vertices.
pub const LOCAL_MAX_VERTICES: usize = 24;
/// [`LocalContactMsg`]: at most this many contact points.
pub const LOCAL_MAX_POINTS: usize = 1024;
/// [`LocalContactMsg`]: at most this many tool parts (tip, shaft).
pub const LOCAL_MAX_PARTS: usize = 2;
/// [`LocalContactMsg::compliance_m_per_n`]: entries (3 x 24 squared).
pub const LOCAL_COMPLIANCE_LEN: usize = 9 * LOCAL_MAX_VERTICES * LOCAL_MAX_VERTICES;

/// A tool part of [`LocalContactMsg`]: a capsule (64 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.LocalPart.v1")]
pub struct LocalPart {
    /// One end of the segment (m).
    pub a_m: [f64; 3],
    /// The other end (m).
    pub b_m: [f64; 3],
    /// Radius (m).
    pub radius_m: f64,
    /// Penetration over which a point's spring force grows quadratically
    /// (m): `k d^2 / (2 d0)` below it, `k (d - d0 / 2)` past it.
    pub onset_m: f64,
}

/// A contact point of [`LocalContactMsg`] (40 bytes): on the triangle of
/// vertices `slots` (indices into the message's vertices) at barycentric
/// `weights`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.LocalPoint.v1")]
pub struct LocalPoint {
    /// Barycentric weights (sum 1).
    pub weights: [f64; 3],
    /// Spring stiffness (N/m).
    pub stiffness_n_per_m: f64,
    /// The triangle's vertices (indices < `vertex_count`).
    pub slots: [u16; 3],
    /// The part it faces (index < `part_count`).
    pub part: u16,
}

/// Sim -> daemon: the contact problem around one tool after a step (the
/// `local-contact` stream; see `docs/protocol.md`): the tool's capsules,
/// the surface points near it with their vertices' positions, and the
/// tissue's compliance at those vertices, for the daemon to solve again at
/// every tick (the `local-problem` extrapolator).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.LocalContactMsg.v2")]
pub struct LocalContactMsg {
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// The tool (index in the scene's tools).
    pub tool: u32,
    /// `seq` of the force message of the step it was taken at.
    pub seq: u64,
    /// The time of its state (`CLOCK_MONOTONIC`, ns): the device time of
    /// the pose that step used (`PoseMsg::t_ns`), or the step's finish (its
    /// force message's `t_ns`) when no pose drove it.
    pub t_ns: u64,
    /// The tool position the step used (m).
    pub tool_position_m: [f64; 3],
    /// Parts used.
    pub part_count: u32,
    /// Vertices used.
    pub vertex_count: u32,
    /// Points used.
    pub point_count: u32,
    /// 1: the tissue's inertia below is given; 0: none (quasi-static).
    pub inertia: u32,
    /// The tool's capsules.
    pub parts: [LocalPart; LOCAL_MAX_PARTS],
    /// The vertices' positions (m).
    pub positions_m: [[f64; 3]; LOCAL_MAX_VERTICES],
    /// The points.
    pub points: [LocalPoint; LOCAL_MAX_POINTS],
    /// The tissue's compliance at the vertices, (K^-1)_VV (m/N), row-major
    /// `3 vertex_count` square (the first `(3 vertex_count)^2` entries).
    pub compliance_m_per_n: [f64; LOCAL_COMPLIANCE_LEN],
    /// With `inertia`: G = C^T M C (m^2 kg / N^2), the tissue's lumped
    /// masses M seen through the static response columns C = K^-1 P_V^T
    /// of the vertices; its mass condensed on them (Guyan) is W^-1 G W^-1.
    /// Laid out as the compliance.
    pub column_mass: [f64; LOCAL_COMPLIANCE_LEN],
    /// With `inertia`: the vertices' velocities at the end of that step
    /// (m/s).
    pub velocities_m_per_s: [[f64; 3]; LOCAL_MAX_VERTICES],
    /// With `inertia`: the tissue's mass-proportional damping (1/s).
    pub damping_per_s: f64,
}

impl Default for LocalContactMsg {
    fn default() -> Self {
        Self {
            version: PROTOCOL_VERSION,
            tool: 0,
            seq: 0,
            t_ns: 0,
            tool_position_m: [0.0; 3],
            part_count: 0,
            vertex_count: 0,
            point_count: 0,
            inertia: 0,
            parts: [LocalPart::default(); LOCAL_MAX_PARTS],
            positions_m: [[0.0; 3]; LOCAL_MAX_VERTICES],
            points: [LocalPoint::default(); LOCAL_MAX_POINTS],
            compliance_m_per_n: [0.0; LOCAL_COMPLIANCE_LEN],
            column_mass: [0.0; LOCAL_COMPLIANCE_LEN],
            velocities_m_per_s: [[0.0; 3]; LOCAL_MAX_VERTICES],
            damping_per_s: 0.0,
        }
    }
}

/// Sim -> viewer: the user header of the mesh-state slice stream (the slice
/// holds `vertex_count` positions as `[f32; 3]` in metres).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.MeshHeader.v1")]
pub struct MeshHeader {
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Vertices in the slice.
    pub vertex_count: u32,
    /// Increments by one per frame.
    pub frame_seq: u64,
    /// Changes whenever the surface changes (cuts); matches `TopologyHeader::topology_version`.
    pub topology_version: u64,
    /// `CLOCK_MONOTONIC` (ns) of the state.
    pub t_ns: u64,
}

/// Sim -> viewer: the user header of the topology slice stream (the slice
/// holds `triangle_count` surface triangles as `[u32; 3]`, outward).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.TopologyHeader.v1")]
pub struct TopologyHeader {
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Triangles in the slice.
    pub triangle_count: u32,
    /// The version these triangles describe.
    pub topology_version: u64,
}

/// One declared tool as [`SceneInfo`] describes it (88 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.ToolInfo.v1")]
pub struct ToolInfo {
    /// The scene's name for the tool, UTF-8, zero-padded (truncated at a
    /// character boundary to 32 bytes).
    pub name: [u8; 32],
    /// [`TOOL_GRASPER`], [`TOOL_HOOK`] or [`TOOL_CAVITRON`].
    pub kind: u32,
    /// Padding (keeps the layout explicit).
    pub reserved: u32,
    /// The trocar the shaft pivots in (m, scene frame).
    pub fulcrum_m: [f64; 3],
    /// Shaft length (m).
    pub length_m: f64,
    /// Shaft radius (m).
    pub radius_m: f64,
    /// Tip length (m).
    pub tip_length_m: f64,
}

/// [`ToolInfo::kind`]: a grasper (grips, cuts with closed jaws).
pub const TOOL_GRASPER: u32 = 0;
/// [`ToolInfo::kind`]: a hook (presses and slides).
pub const TOOL_HOOK: u32 = 1;
/// [`ToolInfo::kind`]: a cavitron (removes tissue at its tip).
pub const TOOL_CAVITRON: u32 = 2;

/// Sim -> clients: what the scene holds that a client without the scene
/// file needs, published once when the simulation starts (history 1: a
/// client that joins later gets it).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.SceneInfo.v1")]
pub struct SceneInfo {
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Declared tools (<= `MAX_TOOLS`), in `[[tool]]` order: the index of
    /// `PoseMsg::tools` and `ForceMsg::tools`.
    pub tool_count: u32,
    /// Vertices of the mesh (the `mesh` stream's slice length).
    pub vertex_count: u32,
    /// Tetrahedra of the mesh at the start.
    pub tet_count: u32,
    /// The organ's rest bounding box, low corner (m).
    pub bounds_min_m: [f64; 3],
    /// The organ's rest bounding box, high corner (m).
    pub bounds_max_m: [f64; 3],
    /// Per tool.
    pub tools: [ToolInfo; MAX_TOOLS],
}

/// The text of a zero-padded UTF-8 field (up to the first zero byte; empty
/// if it is not UTF-8).
fn text_of(field: &[u8]) -> &str {
    let end = field.iter().position(|&b| b == 0).unwrap_or(field.len());
    std::str::from_utf8(&field[..end]).unwrap_or("")
}

/// Stores `text` in a zero-padded field, cut at a character boundary to
/// fit.
fn set_text(field: &mut [u8], text: &str) {
    let mut end = text.len().min(field.len());
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    field.fill(0);
    field[..end].copy_from_slice(&text.as_bytes()[..end]);
}

impl ToolInfo {
    /// The name as text (up to the first zero byte).
    pub fn name(&self) -> &str {
        text_of(&self.name)
    }

    /// Stores `name`, cut to 32 bytes at a character boundary.
    pub fn set_name(&mut self, name: &str) {
        set_text(&mut self.name, name);
    }
}

/// Sim -> clients: the user header of the `rest` slice stream, published
/// once at start (history 1). The slice holds `vertex_count` rest
/// positions (m), then `fibre_count` pairs (the centroid of an anisotropic
/// tetrahedron, its fibre direction scaled to that tetrahedron's first
/// edge length), all `[f32; 3]`: what a viewer without the scene file
/// draws before the first mesh frame and as fibres (80 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.RestHeader.v1")]
pub struct RestHeader {
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Rest positions in the slice (the mesh's vertices, in `mesh` order).
    pub vertex_count: u32,
    /// Fibre pairs after them.
    pub fibre_count: u32,
    /// Padding (keeps the layout explicit).
    pub reserved: u32,
    /// The scene's name (its file, or `<embedded liver>`), UTF-8,
    /// zero-padded (cut at a character boundary to 64 bytes).
    pub name: [u8; 64],
}

impl Default for RestHeader {
    fn default() -> Self {
        Self {
            version: PROTOCOL_VERSION,
            vertex_count: 0,
            fibre_count: 0,
            reserved: 0,
            name: [0; 64],
        }
    }
}

impl RestHeader {
    /// The scene's name as text.
    pub fn name(&self) -> &str {
        text_of(&self.name)
    }

    /// Stores the scene's name, cut to 64 bytes at a character boundary.
    pub fn set_name(&mut self, name: &str) {
        set_text(&mut self.name, name);
    }

    /// The slice length this header describes (`None` if it overflows).
    pub fn slice_len(&self) -> Option<usize> {
        (self.fibre_count as usize)
            .checked_mul(2)?
            .checked_add(self.vertex_count as usize)
    }
}

/// One haptic tick as the daemon saw it.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.TelemetryTick.v1")]
pub struct TelemetryTick {
    /// `CLOCK_MONOTONIC` (ns) of the tick.
    pub t_ns: u64,
    /// Tick number.
    pub seq: u64,
    /// Device position of tool 0 (m).
    pub position_m: [f64; 3],
    /// Force sent to the device (N).
    pub force_n: [f64; 3],
    /// Tick start minus its deadline (ns; negative = early).
    pub lateness_ns: i64,
    /// Age of the force sample used (ns; `u64::MAX` = none).
    pub sample_age_ns: u64,
    /// Extrapolation method index (0 constant, 1 linear-time, 2 linear-position, 3 linear-position-signed, 4 local-model).
    pub method: u32,
    /// Safety state (0 waiting, 1 ramping in, 2 active, 3 ramping down, 4 stopped).
    pub safety_state: u32,
}

/// Daemon -> recorder/bench: telemetry in batches (haptic rate / `TELEMETRY_BATCH`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
#[type_name("hapsim.TelemetryBatch.v1")]
pub struct TelemetryBatch {
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Valid ticks in `ticks`.
    pub count: u32,
    /// Increments by one per batch.
    pub seq: u64,
    /// The ticks.
    pub ticks: [TelemetryTick; TELEMETRY_BATCH],
}

impl Default for TelemetryBatch {
    fn default() -> Self {
        Self {
            version: PROTOCOL_VERSION,
            count: 0,
            seq: 0,
            ticks: [TelemetryTick::default(); TELEMETRY_BATCH],
        }
    }
}

#[cfg(test)]
mod tests;
