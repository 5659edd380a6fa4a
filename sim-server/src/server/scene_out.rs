//! What a client without the scene file needs, published once at start
//! and kept in the services' history for clients that join later: the
//! declared tools and the organ's rest bounding box (`scene`), the rest
//! positions, fibres and scene name (`rest`), and the surface as built
//! (`surface0`, so a viewer tells the faces cuts made). A viewer, a
//! recorder or a client on another machine (through a bridge) then needs
//! no files.

use super::outputs::{send_slice, surface_into};
use super::{RunError, publish_err};
use shared::SessionName;
use shared::protocol::{
    MAX_TOOLS, PROTOCOL_VERSION, RestHeader, SceneInfo, TOOL_CAVITRON, TOOL_GRASPER, TOOL_HOOK,
    TopologyHeader,
};
use shared::services::{self, IpcNode, ScenePublisher, SlicePublisher, UpdateConnections};
use sim_server::backend::Backend;
use sim_server::contact::Tools;
use sim_server::ids::TetId;
use sim_server::math::Vec3;
use sim_server::scene::spec::ToolKind;
use sim_server::tensor_mass::ElasticModel;

/// The declared tools and the organ's rest bounding box (the `scene`
/// stream).
pub fn scene_info<B: Backend>(tools: &Tools, sim: &B) -> SceneInfo {
    let mesh = sim.model().mesh();
    let (lo, hi) = mesh.bounds_m();
    let mut info = SceneInfo {
        version: PROTOCOL_VERSION,
        tool_count: tools.len().min(MAX_TOOLS) as u32,
        vertex_count: mesh.vertex_count() as u32,
        tet_count: mesh.tet_count() as u32,
        bounds_min_m: lo.to_array(),
        bounds_max_m: hi.to_array(),
        ..SceneInfo::default()
    };
    for (out, t) in info.tools.iter_mut().zip(tools.iter()) {
        let d = t.decl();
        out.set_name(&d.name);
        out.kind = match d.kind {
            ToolKind::Grasper => TOOL_GRASPER,
            ToolKind::Hook => TOOL_HOOK,
            ToolKind::Cavitron => TOOL_CAVITRON,
        };
        out.fulcrum_m = d.fulcrum_m;
        out.length_m = d.length_m;
        out.radius_m = d.radius_m;
        out.tip_length_m = d.tip_length_m;
    }
    info
}

/// The `rest` slice of `model` ([`RestHeader`]): the rest positions, then
/// per anisotropic tetrahedron its centroid and its fibre scaled to its
/// first edge; and the number of fibres.
pub fn rest_slice(model: &ElasticModel) -> (Vec<[f32; 3]>, usize) {
    let mesh = model.mesh();
    let p = mesh.positions_m();
    let f32s = |v: Vec3| v.as_vec3().to_array();
    let mut out: Vec<[f32; 3]> = p.iter().map(|x| f32s(*x)).collect();
    let mut fibres = 0;
    for (t, tet) in mesh.tets().iter().enumerate() {
        let f = model.materials().fiber(TetId::from(t));
        if f == Vec3::ZERO {
            continue;
        }
        let centroid = tet.iter().map(|v| p[v.idx()]).sum::<Vec3>() / 4.0;
        let edge = (p[tet[0].idx()] - p[tet[1].idx()]).length();
        out.push(f32s(centroid));
        out.push(f32s(f * edge));
        fibres += 1;
    }
    (out, fibres)
}

/// The three once-published streams' publishers (kept alive: a client
/// that joins later gets their history when they update connections).
pub struct SceneOut {
    scene: ScenePublisher,
    rest: SlicePublisher<[f32; 3], RestHeader>,
    surface0: SlicePublisher<[u32; 3], TopologyHeader>,
}

impl SceneOut {
    /// Opens the `scene`, `rest` and `surface0` streams of `session` and
    /// publishes `sim`'s scene (named `scene_name`) on them.
    pub fn publish<B: Backend>(
        node: &IpcNode,
        session: &SessionName,
        tools: &Tools,
        sim: &B,
        scene_name: &str,
    ) -> Result<Self, RunError> {
        let model = sim.model();
        let (slice, _) = rest_slice(model);
        let mut tris = Vec::new();
        surface_into(model, &mut tris);
        let out = Self {
            scene: services::publisher(&services::scene_service(node, session)?)?,
            rest: services::slice_publisher(&services::rest_service(node, session)?, slice.len())?,
            surface0: services::slice_publisher(
                &services::surface0_service(node, session)?,
                tris.len(),
            )?,
        };
        out.send(tools, sim, scene_name)?;
        Ok(out)
    }

    /// Publishes `sim`'s scene (named `scene_name`): at start, and again
    /// when the mesh has been made again round the tools (the streams keep
    /// the newest, so a client joining later gets the mesh that runs).
    pub fn send<B: Backend>(
        &self,
        tools: &Tools,
        sim: &B,
        scene_name: &str,
    ) -> Result<(), RunError> {
        let model = sim.model();
        self.scene
            .send_copy(scene_info(tools, sim))
            .map_err(|e| publish_err("scene info")(format!("{e:?}")))?;
        let (slice, fibre_count) = rest_slice(model);
        let mut header = RestHeader {
            vertex_count: model.vertex_count() as u32,
            fibre_count: fibre_count as u32,
            ..RestHeader::default()
        };
        header.set_name(scene_name);
        send_slice(&self.rest, header, &slice, "rest positions")?;
        let mut tris = Vec::new();
        surface_into(model, &mut tris);
        let header = TopologyHeader {
            version: PROTOCOL_VERSION,
            triangle_count: tris.len() as u32,
            topology_version: 1,
        };
        send_slice(&self.surface0, header, &tris, "original surface")
    }

    /// Delivers the history to clients that joined since (iceoryx2 sends
    /// it when the publisher updates its connections).
    pub fn refresh(&self) {
        let _ = self.scene.update_connections();
        let _ = self.rest.update_connections();
        let _ = self.surface0.update_connections();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sim_server::scene::{SceneSource, build_scene};

    /// The liver's rest slice: every vertex where the mesh has it, then one
    /// unit-direction fibre per anisotropic tetrahedron scaled to its edge,
    /// centred in it.
    #[test]
    fn the_rest_slice_holds_the_positions_then_the_fibres() {
        let src = SceneSource::embedded();
        let built = build_scene(&src, &src.parse().unwrap()).unwrap();
        let model = &built.model;
        let (slice, fibres) = rest_slice(model);
        let n = model.vertex_count();
        assert!(fibres > 0, "the liver's vessels are anisotropic");
        assert_eq!(slice.len(), n + 2 * fibres);
        let p = model.mesh().positions_m();
        assert_eq!(slice[n - 1], p[n - 1].as_vec3().to_array());
        let (lo, hi) = model.mesh().bounds_m();
        for pair in slice[n..].chunks_exact(2) {
            let c = Vec3::from_array(pair[0].map(f64::from));
            assert!(c.cmpge(lo).all() && c.cmple(hi).all(), "{c}");
            let d = Vec3::from_array(pair[1].map(f64::from)).length();
            assert!(d > 1e-4 && d < 0.05, "{d}");
        }
    }
}
