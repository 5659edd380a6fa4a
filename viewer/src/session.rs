//! What the viewer reads from a session: the scene (tools, name, rest
//! positions, fibres, the uncut surface: [`SceneInfo`]), the latest mesh
//! state and surface, force samples, haptic telemetry and tool poses. Every stream is opened
//! (or created) at start, so the viewer may come before or after the
//! simulation; a simulation that restarts, or cuts, shows up as a new
//! topology version or vertex count, never as an error.

use crate::scene_info::SceneInfo;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use shared::SessionName;
use shared::protocol::{
    ForceMsg, MAX_TOOLS, MeshHeader, PROTOCOL_VERSION, PoseMsg, RestHeader, TelemetryBatch,
    TopologyHeader,
};
use shared::services::{self, Ipc, ServiceError};
use std::collections::VecDeque;

/// How long (ns) without a mesh frame before the simulation counts as gone.
const SIM_GONE_NS: u64 = 1_000_000_000;
/// Window (ns) of the rates and percentiles in [`Stats`].
const WINDOW_NS: u64 = 1_000_000_000;

/// Rates and latencies over the last second, for the overlay.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stats {
    /// Simulation steps per second (force samples received).
    pub sim_hz: f64,
    /// Haptic ticks per second (telemetry).
    pub haptic_hz: f64,
    /// Median age of the force sample the daemon used (us).
    pub sample_age_p50_us: f64,
    /// 99th percentile of that age (us).
    pub sample_age_p99_us: f64,
    /// Median haptic tick lateness (us).
    pub lateness_p50_us: f64,
    /// 99th percentile of the tick lateness (us).
    pub lateness_p99_us: f64,
}

/// One tool as the simulation last reported it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ToolState {
    /// The tool end the step used (m).
    pub position_m: [f64; 3],
    /// Force of the tissue on the tool (N).
    pub force_n: [f64; 3],
    /// `CONTACT | GRIPPING | CUTTING` bits.
    pub flags: u32,
}

/// The latest state of a session.
pub struct Session {
    node: Node<Ipc>,
    mesh: Subscriber<Ipc, [[f32; 3]], MeshHeader>,
    topology: Subscriber<Ipc, [[u32; 3]], TopologyHeader>,
    force: Subscriber<Ipc, ForceMsg, ()>,
    telemetry: Subscriber<Ipc, TelemetryBatch, ()>,
    telemetry_factory: PortFactory<Ipc, TelemetryBatch, ()>,
    scene: services::SceneSubscriber,
    rest: Subscriber<Ipc, [[f32; 3]], RestHeader>,
    surface0: Subscriber<Ipc, [[u32; 3]], TopologyHeader>,
    /// The scene as the simulation published it (empty parts until their
    /// streams arrive).
    pub info: SceneInfo,
    pose_factory: PortFactory<Ipc, PoseMsg, ()>,
    /// Latest vertex positions (m).
    pub positions_m: Vec<[f32; 3]>,
    /// Latest surface triangles, outward.
    pub triangles: Vec<[u32; 3]>,
    /// Version of `triangles` (0: none yet).
    pub topology_version: u64,
    /// Topology version the latest mesh frame refers to.
    pub frame_topology_version: u64,
    /// Mesh frames received.
    pub frames: u64,
    /// `CLOCK_MONOTONIC` (ns) stamp of the newest mesh frame (0: none).
    pub last_frame_ns: u64,
    /// Tools in the latest force sample.
    pub tools: Vec<ToolState>,
    /// Rates and latencies.
    pub stats: Stats,
    /// (t_ns, seq) of the force samples seen in the window.
    force_times: VecDeque<(u64, u64)>,
    /// (t_ns, seq, lateness_ns, sample_age_ns) of the ticks in the window.
    ticks: VecDeque<(u64, u64, i64, u64)>,
    scratch: Vec<f64>,
}

impl Session {
    /// Joins `session` (creating its streams if nobody has yet).
    pub fn join(session: &SessionName) -> Result<Self, ServiceError> {
        let node = services::node("viewer")?;
        let mesh = services::slice_subscriber(&services::mesh_service(&node, session)?)?;
        let topology = services::slice_subscriber(&services::topology_service(&node, session)?)?;
        let force = services::subscriber_with_buffer(
            &services::force_service(&node, session)?,
            services::FORCE_BUFFER_LATEST,
        )?;
        let telemetry_factory = services::telemetry_service(&node, session)?;
        let telemetry = services::subscriber(&telemetry_factory)?;
        let scene = services::subscriber(&services::scene_service(&node, session)?)?;
        let rest = services::slice_subscriber(&services::rest_service(&node, session)?)?;
        let surface0 = services::slice_subscriber(&services::surface0_service(&node, session)?)?;
        let pose_factory = services::pose_service(&node, session)?;
        Ok(Self {
            node,
            mesh,
            topology,
            force,
            telemetry,
            telemetry_factory,
            scene,
            rest,
            surface0,
            info: SceneInfo::default(),
            pose_factory,
            positions_m: Vec::new(),
            triangles: Vec::new(),
            topology_version: 0,
            frame_topology_version: 0,
            frames: 0,
            last_frame_ns: 0,
            tools: Vec::new(),
            stats: Stats::default(),
            force_times: VecDeque::new(),
            ticks: VecDeque::new(),
            scratch: Vec::new(),
        })
    }

    /// The node (to publish poses from the same process).
    pub fn node(&self) -> &Node<Ipc> {
        &self.node
    }

    /// The pose stream (the viewer publishes on it when it drives a tool).
    pub fn pose_service(&self) -> &PortFactory<Ipc, PoseMsg, ()> {
        &self.pose_factory
    }

    /// Pose publishers in the session (a daemon, or this viewer driving).
    pub fn pose_publishers(&self) -> usize {
        self.pose_factory.dynamic_config().number_of_publishers()
    }

    /// Whether a haptic daemon runs in the session (it publishes
    /// telemetry), whether or not a batch has arrived yet.
    pub fn daemon_present(&self) -> bool {
        self.telemetry_factory
            .dynamic_config()
            .number_of_publishers()
            > 0
    }

    /// Whether a simulation sent a mesh frame within the last second.
    pub fn sim_alive(&self, now_ns: u64) -> bool {
        self.last_frame_ns != 0 && now_ns.saturating_sub(self.last_frame_ns) < SIM_GONE_NS
    }

    /// Whether the latest positions and triangles belong together.
    pub fn drawable(&self) -> bool {
        !self.triangles.is_empty()
            && self.topology_version == self.frame_topology_version
            && self
                .triangles
                .iter()
                .flatten()
                .all(|&v| (v as usize) < self.positions_m.len())
    }

    /// Drains every stream; returns whether the mesh or surface changed.
    /// Messages of another protocol version are skipped.
    pub fn poll(&mut self, now_ns: u64) -> bool {
        let mut changed = false;
        while let Ok(Some(s)) = self.topology.receive() {
            let h = *s.user_header();
            if h.version == PROTOCOL_VERSION && h.triangle_count as usize == s.payload().len() {
                self.triangles.clear();
                self.triangles.extend_from_slice(s.payload());
                self.topology_version = h.topology_version;
                changed = true;
            }
        }
        while let Ok(Some(s)) = self.mesh.receive() {
            let h = *s.user_header();
            if h.version == PROTOCOL_VERSION && h.vertex_count as usize == s.payload().len() {
                self.positions_m.clear();
                self.positions_m.extend_from_slice(s.payload());
                self.frame_topology_version = h.topology_version;
                self.frames += 1;
                // The frame's own stamp (same monotonic clock): frames left in
                // the buffer by a simulation that has gone do not look fresh.
                self.last_frame_ns = h.t_ns.max(1);
                changed = true;
            }
        }
        while let Ok(Some(s)) = self.force.receive() {
            if s.version != PROTOCOL_VERSION {
                continue;
            }
            self.force_times.push_back((s.t_ns, s.seq));
            let n = (s.tool_count as usize).min(MAX_TOOLS);
            self.tools.clear();
            self.tools.extend(s.tools[..n].iter().map(|t| ToolState {
                position_m: t.position_m,
                force_n: t.force_n,
                flags: t.flags,
            }));
        }
        changed |= self.poll_scene();
        while let Ok(Some(b)) = self.telemetry.receive() {
            if b.version != PROTOCOL_VERSION {
                continue;
            }
            for t in &b.ticks[..(b.count as usize).min(b.ticks.len())] {
                self.ticks
                    .push_back((t.t_ns, t.seq, t.lateness_ns, t.sample_age_ns));
            }
        }
        self.update_stats(now_ns);
        changed
    }

    /// The once-published scene streams (a simulation that restarts
    /// publishes them again); whether any arrived.
    fn poll_scene(&mut self) -> bool {
        let mut changed = false;
        while let Ok(Some(m)) = self.scene.receive() {
            if m.version == PROTOCOL_VERSION {
                self.info.set_tools(&m);
                changed = true;
            }
        }
        while let Ok(Some(s)) = self.rest.receive() {
            let h = *s.user_header();
            if h.version == PROTOCOL_VERSION {
                changed |= self.info.set_rest(&h, s.payload());
            }
        }
        while let Ok(Some(s)) = self.surface0.receive() {
            let h = *s.user_header();
            if h.version == PROTOCOL_VERSION && h.triangle_count as usize == s.payload().len() {
                self.info.set_original_surface(s.payload());
                changed = true;
            }
        }
        changed
    }

    /// Whether the latest mesh state belongs to the scene the streams
    /// described (same vertex count), so its faces can be checked against
    /// the uncut surface.
    pub fn same_scene(&self) -> bool {
        self.info.vertex_count == self.positions_m.len()
    }

    fn update_stats(&mut self, now_ns: u64) {
        let since = now_ns.saturating_sub(WINDOW_NS);
        while self.force_times.front().is_some_and(|&(t, _)| t < since) {
            self.force_times.pop_front();
        }
        while self.ticks.front().is_some_and(|&(t, ..)| t < since) {
            self.ticks.pop_front();
        }
        // The force stream keeps only the newest samples for a slow reader:
        // rates come from sequence numbers, not from what was received.
        self.stats.sim_hz = rate(
            self.force_times
                .front()
                .zip(self.force_times.back())
                .map(|(a, b)| (a.0, a.1, b.0, b.1)),
        );
        self.stats.haptic_hz = rate(
            self.ticks
                .front()
                .zip(self.ticks.back())
                .map(|(a, b)| (a.0, a.1, b.0, b.1)),
        );
        self.scratch.clear();
        self.scratch.extend(
            self.ticks
                .iter()
                .filter(|t| t.3 != u64::MAX)
                .map(|t| t.3 as f64 * 1e-3),
        );
        (self.stats.sample_age_p50_us, self.stats.sample_age_p99_us) =
            percentiles(&mut self.scratch);
        self.scratch.clear();
        self.scratch
            .extend(self.ticks.iter().map(|t| t.2 as f64 * 1e-3));
        (self.stats.lateness_p50_us, self.stats.lateness_p99_us) = percentiles(&mut self.scratch);
    }
}

/// Events per second between two (t_ns, seq) points (0 without two).
fn rate(span: Option<(u64, u64, u64, u64)>) -> f64 {
    match span {
        Some((t0, s0, t1, s1)) if t1 > t0 && s1 > s0 => {
            (s1 - s0) as f64 / ((t1 - t0) as f64 * 1e-9)
        }
        _ => 0.0,
    }
}

/// (p50, p99) of `x` (0 when empty).
fn percentiles(x: &mut [f64]) -> (f64, f64) {
    if x.is_empty() {
        return (0.0, 0.0);
    }
    x.sort_unstable_by(f64::total_cmp);
    let at = |q: f64| x[((x.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.99))
}

#[cfg(test)]
mod tests {
    use super::{percentiles, rate};

    #[test]
    fn percentiles_of_a_ramp() {
        let mut x: Vec<f64> = (0..=100).map(f64::from).collect();
        x.reverse();
        assert_eq!(percentiles(&mut x), (50.0, 99.0));
        assert_eq!(percentiles(&mut []), (0.0, 0.0));
        // 1000 steps in 0.5 s, whatever was received in between.
        assert_eq!(rate(Some((0, 7, 500_000_000, 1007))), 2000.0);
        assert_eq!(rate(None), 0.0);
    }
}
