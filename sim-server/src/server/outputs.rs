//! The process's hops in and out of a step: the tools' inputs from the
//! pose and the scripts ([`tool_inputs`]), and the viewer's streams with
//! the optional frame recording ([`MeshOut`]), and the start-up line
//! ([`announce`]); the force sample itself is the library's
//! ([`sim_server::wire`]).

use super::{RunError, ToolScript, publish_err};
use shared::protocol::{
    MAX_TOOLS, MeshHeader, PROTOCOL_VERSION, PoseMsg, TOOL_PRESENT, TopologyHeader,
};
use shared::services::{SlicePublisher, UpdateConnections, ZeroCopySend};
use sim_server::backend::Backend;
use sim_server::contact::ToolInput;
use sim_server::frames::FrameRecorder;
use sim_server::math::{Real, Vec3};
use sim_server::tensor_mass::ElasticModel;

/// Each tool's input for the step at simulated time `sim_t_s`: its script
/// if one drives it, else the live pose's entry (none: withdrawn).
pub fn tool_inputs(
    tools: usize,
    scripts: &[ToolScript],
    pose: Option<PoseMsg>,
    sim_t_s: Real,
) -> [Option<ToolInput>; MAX_TOOLS] {
    let mut inputs = [None; MAX_TOOLS];
    for (i, input) in inputs.iter_mut().enumerate().take(tools) {
        *input = if let Some(script) = scripts.iter().find(|s| s.tool == i) {
            let (tip_m, jaw_opening) = script.at(sim_t_s);
            Some(ToolInput { tip_m, jaw_opening })
        } else {
            pose.filter(|p| (i as u32) < p.tool_count && p.tools[i].flags & TOOL_PRESENT != 0)
                .map(|p| ToolInput {
                    tip_m: Vec3::from_array(p.tools[i].tip_m),
                    jaw_opening: p.tools[i].jaw_opening,
                })
        };
    }
    inputs
}

/// The viewer's streams (surface topology when cuts change it, positions
/// at the viewer rate) and the `--save-frames` recorder.
pub struct MeshOut {
    mesh: SlicePublisher<[f32; 3], MeshHeader>,
    topology: SlicePublisher<[u32; 3], TopologyHeader>,
    recorder: Option<FrameRecorder>,
    /// Scratch for the surface triangles.
    tris: Vec<[u32; 3]>,
    rest_m: Vec<Vec3>,
    /// Bumped by every cut; the version last published.
    pub topology_version: u64,
    published_topology: u64,
    /// Frames published.
    pub frames: u64,
}

impl MeshOut {
    /// Over the given publishers, for `sim`'s mesh.
    pub fn new<B: Backend>(
        sim: &B,
        mesh: SlicePublisher<[f32; 3], MeshHeader>,
        topology: SlicePublisher<[u32; 3], TopologyHeader>,
        recorder: Option<FrameRecorder>,
    ) -> Result<Self, RunError> {
        Ok(Self {
            mesh,
            topology,
            recorder,
            tris: Vec::with_capacity(4 * sim.model().mesh().tet_count()),
            rest_m: sim.model().mesh().positions_m().to_vec(),
            topology_version: 1,
            published_topology: 0,
            frames: 0,
        })
    }

    /// Follows `sim` onto another mesh (the refinement round the tools):
    /// its rest positions, and a new topology version so that the next
    /// frame goes out with the new surface first.
    pub fn rebind<B: Backend>(&mut self, sim: &B) {
        self.rest_m.clear();
        self.rest_m
            .extend_from_slice(sim.model().mesh().positions_m());
        self.topology_version += 1;
    }

    /// Publishes the state of `sim` at `now_ns` (simulated `sim_t_s`):
    /// the topology first when it changed (else the kept one reaches
    /// viewers that joined since), then the positions; hands the frame to
    /// the recorder.
    pub fn publish<B: Backend>(
        &mut self,
        sim: &B,
        now_ns: u64,
        sim_t_s: Real,
    ) -> Result<(), RunError> {
        if self.published_topology != self.topology_version {
            surface_into(sim.model(), &mut self.tris);
            let header = TopologyHeader {
                version: PROTOCOL_VERSION,
                triangle_count: self.tris.len() as u32,
                topology_version: self.topology_version,
            };
            send_slice(&self.topology, header, &self.tris, "topology")?;
            self.published_topology = self.topology_version;
        } else {
            // A viewer that joined since gets the kept topology (history
            // is delivered when the publisher updates its connections).
            let _ = self.topology.update_connections();
        }
        let u = sim.displacements();
        let n = self.rest_m.len();
        let mut s = self
            .mesh
            .loan_slice_uninit(n)
            .map_err(|e| publish_err("mesh state")(format!("{e:?}")))?;
        *s.user_header_mut() = MeshHeader {
            version: PROTOCOL_VERSION,
            vertex_count: n as u32,
            frame_seq: self.frames,
            topology_version: self.topology_version,
            t_ns: now_ns,
        };
        let rest = &self.rest_m;
        s.write_from_fn(|i| {
            let p = rest[i] + Vec3::from_array(u[i]);
            [p.x as f32, p.y as f32, p.z as f32]
        })
        .send()
        .map_err(|e| publish_err("mesh state")(format!("{e:?}")))?;
        self.frames += 1;
        if let Some(r) = &mut self.recorder {
            r.offer(sim_t_s, sim.model(), u);
        }
        Ok(())
    }

    /// Stops the recorder (see [`FrameRecorder::finish`]).
    pub fn finish(
        self,
    ) -> Option<(
        sim_server::frames::FrameCounts,
        Option<sim_server::frames::FramesError>,
    )> {
        self.recorder.map(FrameRecorder::finish)
    }
}

/// The model's outward surface triangles as the wire carries them, into
/// `out` (cleared first; its capacity reused).
pub fn surface_into(model: &ElasticModel, out: &mut Vec<[u32; 3]>) {
    out.clear();
    out.extend(
        model
            .topology()
            .surface_triangles(model.mesh())
            .map(|t| t.map(|v| v.0)),
    );
}

/// Sends `data` with `header` on a slice stream (`what` names it in errors).
pub fn send_slice<T, H>(
    publisher: &SlicePublisher<T, H>,
    header: H,
    data: &[T],
    what: &'static str,
) -> Result<(), RunError>
where
    T: std::fmt::Debug + ZeroCopySend + Copy,
    H: std::fmt::Debug + ZeroCopySend + Default,
{
    let mut s = publisher
        .loan_slice_uninit(data.len())
        .map_err(|e| publish_err(what)(format!("{e:?}")))?;
    *s.user_header_mut() = header;
    s.write_from_slice(data)
        .send()
        .map_err(|e| publish_err(what)(format!("{e:?}")))?;
    Ok(())
}

/// The start line: backend, dynamics and where it cuts.
pub(super) fn announce<B: Backend>(sim: &B) {
    let (cut, live) = sim_server::backend::cuttable(sim);
    eprintln!(
        "sim-server: {} backend, {}, cuts {}",
        sim.capabilities().name,
        if sim.capabilities().dynamic {
            "dynamic"
        } else {
            "quasi-static"
        },
        match cut {
            0 => "nowhere".to_string(),
            c if c == live => "anywhere".to_string(),
            c => format!("in {c} of {live} tetrahedra"),
        }
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scripts_drive_their_tools_and_the_pose_the_others_present() {
        let script = ToolScript {
            tool: 1,
            points: vec![(0.0, Vec3::new(1.0, 2.0, 3.0), 0.5)],
        };
        let mut pose = PoseMsg {
            tool_count: 1,
            seq: 7,
            ..PoseMsg::default()
        };
        pose.tools[0].tip_m = [0.1, 0.2, 0.3];
        pose.tools[0].jaw_opening = 0.25;
        pose.tools[0].flags = TOOL_PRESENT;
        let inputs = tool_inputs(3, std::slice::from_ref(&script), Some(pose), 0.0);
        assert_eq!(inputs[0].map(|i| i.tip_m), Some(Vec3::new(0.1, 0.2, 0.3)));
        assert_eq!(inputs[0].map(|i| i.jaw_opening), Some(0.25));
        assert_eq!(inputs[1].map(|i| i.tip_m), Some(Vec3::new(1.0, 2.0, 3.0)));
        // Past the pose's tool_count, and every tool beyond the scene's: none.
        assert!(inputs[2].is_none() && inputs[3].is_none());
        // A tool the pose does not mark present, or no live pose: withdrawn.
        pose.tools[0].flags = 0;
        assert!(tool_inputs(3, &[], Some(pose), 0.0)[0].is_none());
        assert!(tool_inputs(3, &[], None, 0.0)[0].is_none());
    }
}
