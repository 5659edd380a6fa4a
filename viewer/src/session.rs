//! What the viewer reads from a session: the scene (tools, name, rest
//! positions, fibres, the uncut surface: [`SceneInfo`]), the latest mesh
//! state and surface, force samples, haptic telemetry and tool poses. Every stream is opened
//! (or created) at start, so the viewer may come before or after the
//! simulation; a simulation that restarts, or cuts, shows up as a new
//! topology version or vertex count, never as an error.

use crate::scene_info::SceneInfo;
use crate::streams::{JoinError, Streams};
use shared::SessionName;
use shared::protocol::{MAX_TOOLS, PROTOCOL_VERSION};
use shared::remote::Link;
use shared::services;
use std::collections::VecDeque;
use std::sync::Arc;

/// How long (ns) without a mesh frame before the simulation counts as gone.
const SIM_GONE_NS: u64 = 1_000_000_000;
/// Window (ns) of the rates and percentiles in [`Stats`].
const WINDOW_NS: u64 = 1_000_000_000;
/// The most stamps the statistics' window keeps per stream: a second at
/// 65 kHz, above any rate a simulation or haptic loop runs at. Pruning by
/// age alone stops at the first stamp not yet old, so one stamp from far in
/// the future (a faulty or foreign peer) would let the window grow for
/// ever.
const WINDOW_MAX: usize = 1 << 16;

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
    streams: Streams,
    /// The scene as the simulation published it (empty parts until their
    /// streams arrive).
    pub info: SceneInfo,
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
    /// Joins `session` in shared memory (creating its streams if nobody
    /// has yet).
    pub fn join(session: &SessionName) -> Result<Self, JoinError> {
        Ok(Self::with(Streams::shm(session)?))
    }

    /// Joins a session on another host through `link` (`viewer --connect`).
    pub fn join_remote(link: Arc<Link>) -> Result<Self, JoinError> {
        Ok(Self::with(Streams::remote(link)?))
    }

    fn with(streams: Streams) -> Self {
        Self {
            streams,
            info: SceneInfo::default(),
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
        }
    }

    /// The node and the pose stream, to drive a tool from the viewer (on
    /// the simulation's host only: None through zenoh).
    pub fn pose_port(&self) -> Option<&services::PoseService> {
        self.streams.peers.pose_port()
    }

    /// Pose publishers in the session (a daemon, or this viewer driving;
    /// through zenoh unknown, taken as one: the viewer never drives there).
    pub fn pose_publishers(&self) -> usize {
        self.streams.peers.pose_publishers().unwrap_or(1)
    }

    /// Whether a haptic daemon runs in the session (it publishes
    /// telemetry), whether or not a batch has arrived yet (through zenoh:
    /// telemetry within the last second).
    pub fn daemon_present(&self) -> bool {
        self.streams
            .peers
            .daemon_present()
            .unwrap_or(!self.ticks.is_empty())
    }

    /// Whether a simulation sent a mesh frame within the last second (and,
    /// through zenoh, the bridge still reports it).
    pub fn sim_alive(&self, now_ns: u64) -> bool {
        self.last_frame_ns != 0
            && now_ns.saturating_sub(self.last_frame_ns) < SIM_GONE_NS
            && self.streams.peers.remote_sim_alive().unwrap_or(true)
    }

    /// Whether a running simulation's tissue has no surface left: frames
    /// come, of a topology cut down to no triangle.
    pub fn all_cut(&self) -> bool {
        self.frames > 0
            && self.triangles.is_empty()
            && self.topology_version > 0
            && self.topology_version == self.frame_topology_version
    }

    /// Whether the latest positions and triangles belong together (and
    /// can be drawn: some triangles, every index in range).
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
        self.streams.topology.drain(|h, tris| {
            if h.version == PROTOCOL_VERSION && h.triangle_count as usize == tris.len() {
                self.triangles.clear();
                self.triangles.extend_from_slice(tris);
                self.topology_version = h.topology_version;
                changed = true;
            }
        });
        self.streams.mesh.drain(|h, positions| {
            if h.version == PROTOCOL_VERSION && h.vertex_count as usize == positions.len() {
                self.positions_m.clear();
                self.positions_m.extend_from_slice(positions);
                self.frame_topology_version = h.topology_version;
                self.frames += 1;
                // The frame's own stamp (this host's clock; a remote one is
                // mapped on arrival): frames left in the buffer by a
                // simulation that has gone do not look fresh.
                self.last_frame_ns = h.t_ns.max(1);
                changed = true;
            }
        });
        while let Some(s) = self.streams.force.pop() {
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
        while let Some(b) = self.streams.telemetry.pop() {
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
        while let Some(m) = self.streams.scene.pop() {
            if m.version == PROTOCOL_VERSION {
                self.info.set_tools(&m);
                changed = true;
            }
        }
        self.streams.rest.drain(|h, positions| {
            if h.version == PROTOCOL_VERSION {
                changed |= self.info.set_rest(h, positions);
            }
        });
        self.streams.surface0.drain(|h, tris| {
            if h.version == PROTOCOL_VERSION && h.triangle_count as usize == tris.len() {
                self.info.set_original_surface(tris);
                changed = true;
            }
        });
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
        prune(&mut self.force_times, since, |&(t, _)| t);
        prune(&mut self.ticks, since, |&(t, ..)| t);
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

/// Drops the stamps older than `since` from the front of `q`, and the
/// oldest beyond [`WINDOW_MAX`].
fn prune<T>(q: &mut VecDeque<T>, since: u64, t_ns: impl Fn(&T) -> u64) {
    while q.front().is_some_and(|x| t_ns(x) < since) {
        q.pop_front();
    }
    let excess = q.len().saturating_sub(WINDOW_MAX);
    q.drain(..excess);
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
    use super::{WINDOW_MAX, percentiles, prune, rate};
    use std::collections::VecDeque;

    #[test]
    fn a_stamp_from_the_future_does_not_let_the_window_grow() {
        let mut q: VecDeque<(u64, u64)> = VecDeque::new();
        q.push_back((u64::MAX, 0));
        for k in 0..3 * WINDOW_MAX as u64 {
            q.push_back((k, k));
            prune(&mut q, k.saturating_sub(1000), |&(t, _)| t);
            assert!(q.len() <= WINDOW_MAX, "{} stamps kept", q.len());
        }
        // Once the future stamp is pruned, age pruning works again.
        let mut q: VecDeque<(u64, u64)> = (0..10u64).map(|k| (k, k)).collect();
        prune(&mut q, 7, |&(t, _)| t);
        assert_eq!(q.front(), Some(&(7, 7)));
    }

    /// A running simulation cut down to no tetrahedron is told apart from
    /// no simulation at all (a snapshot said "is sim-server run running?").
    #[test]
    fn a_session_cut_down_to_nothing_is_not_a_missing_one() {
        let name = shared::SessionName::new(&format!("allcut{}", std::process::id())).unwrap();
        let mut s = super::Session::join(&name).unwrap();
        assert!(!s.all_cut() && !s.drawable(), "nothing received yet");
        (s.frames, s.topology_version, s.frame_topology_version) = (3, 5, 5);
        assert!(s.all_cut() && !s.drawable());
        s.positions_m = vec![[0.0; 3]; 3];
        s.triangles = vec![[0, 1, 2]];
        assert!(!s.all_cut() && s.drawable());
    }

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
