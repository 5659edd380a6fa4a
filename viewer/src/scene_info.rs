//! What the viewer knows of the scene, all of it from the session's
//! streams (the simulation publishes them once at start and keeps them in
//! history, so a viewer that joins late, or one on another machine, needs
//! no scene file): the tools' geometry (`scene`), the scene's name, the
//! rest positions and the fibres (`rest`), and the surface as built
//! (`surface0`, so that faces made by cuts can be told apart).

use shared::protocol::{MAX_TOOLS, RestHeader, SceneInfo as SceneMsg, TOOL_CAVITRON, TOOL_GRASPER};
use std::collections::HashSet;

/// A fibre to draw: tetrahedron centroid and direction scaled to a length (m).
pub type Fibre = ([f32; 3], [f32; 3]);

/// What a tool is, for drawing and naming it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ToolKind {
    /// Grips, cuts with closed jaws.
    Grasper,
    /// Presses and slides.
    Hook,
    /// Removes tissue at its tip.
    Cavitron,
}

/// One declared tool as the `scene` stream describes it.
#[derive(Clone, Debug, PartialEq)]
pub struct Tool {
    /// The scene's name for it.
    pub name: String,
    /// Its kind.
    pub kind: ToolKind,
    /// The trocar the shaft pivots in (m).
    pub fulcrum_m: [f64; 3],
    /// Shaft length (m).
    pub length_m: f64,
    /// Shaft radius (m).
    pub radius_m: f64,
}

/// The parts of a scene the viewer draws; empty until the streams arrive.
#[derive(Clone, Debug, Default)]
pub struct SceneInfo {
    /// The scene's name (its file, or the embedded liver's); empty until
    /// the `rest` stream arrives.
    pub name: String,
    /// Declared tools, in order (empty until the `scene` stream arrives).
    pub tools: Vec<Tool>,
    /// Whether the `scene` stream's message came (a scene without tools
    /// sends one too).
    pub tools_known: bool,
    /// Vertices of the scene's mesh (0: not known yet).
    pub vertex_count: usize,
    /// Rest positions (m): a picture before the simulation sends a state.
    pub rest_m: Vec<[f32; 3]>,
    /// The uncut surface (empty until `surface0` arrives).
    pub surface: Vec<[u32; 3]>,
    original: HashSet<[u32; 3]>,
    /// One segment per anisotropic tetrahedron, a third of its edge long.
    pub fibres: Vec<Fibre>,
}

fn key(t: [u32; 3]) -> [u32; 3] {
    let mut k = t;
    k.sort_unstable();
    k
}

impl SceneInfo {
    /// Takes the tools of a `scene` message.
    pub fn set_tools(&mut self, m: &SceneMsg) {
        self.tools_known = true;
        self.tools = m.tools[..(m.tool_count as usize).min(MAX_TOOLS)]
            .iter()
            .map(|t| Tool {
                name: t.name().to_string(),
                kind: match t.kind {
                    TOOL_GRASPER => ToolKind::Grasper,
                    TOOL_CAVITRON => ToolKind::Cavitron,
                    _ => ToolKind::Hook,
                },
                fulcrum_m: t.fulcrum_m,
                length_m: t.length_m,
                radius_m: t.radius_m,
            })
            .collect();
    }

    /// Takes a `rest` message: name, rest positions and fibres. A slice
    /// shorter than its header says is refused (the message is ignored,
    /// `false`).
    pub fn set_rest(&mut self, header: &RestHeader, slice: &[[f32; 3]]) -> bool {
        let n = header.vertex_count as usize;
        if header.slice_len() != Some(slice.len()) {
            return false;
        }
        self.name = header.name().to_string();
        self.vertex_count = n;
        self.rest_m = slice[..n].to_vec();
        // A third of the element's edge: short enough not to hide the surface.
        self.fibres = slice[n..]
            .chunks_exact(2)
            .map(|p| (p[0], p[1].map(|x| x / 3.0)))
            .collect();
        true
    }

    /// Takes a `surface0` message: the surface as built.
    pub fn set_original_surface(&mut self, triangles: &[[u32; 3]]) {
        self.surface = triangles.to_vec();
        self.original = triangles.iter().map(|&t| key(t)).collect();
    }

    /// Whether `tri` is a face the scene did not start with (made by a
    /// cut); `false` while the original surface is not known.
    pub fn is_cut_face(&self, tri: [u32; 3]) -> bool {
        !self.original.is_empty() && !self.original.contains(&key(tri))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shared::protocol::{TOOL_HOOK, ToolInfo};

    #[test]
    fn the_streams_fill_tools_rest_fibres_and_the_uncut_surface() {
        let mut info = SceneInfo::default();
        assert!(
            !info.is_cut_face([0, 1, 2]),
            "nothing is cut before surface0"
        );
        let mut msg = SceneMsg {
            tool_count: 2,
            ..SceneMsg::default()
        };
        let mut probe = ToolInfo {
            kind: TOOL_HOOK,
            radius_m: 0.0025,
            ..ToolInfo::default()
        };
        probe.set_name("probe");
        msg.tools[0] = probe;
        msg.tools[1].kind = TOOL_GRASPER;
        info.set_tools(&msg);
        assert_eq!(info.tools.len(), 2);
        assert_eq!(info.tools[0].name, "probe");
        assert_eq!(info.tools[0].kind, ToolKind::Hook);
        assert_eq!(info.tools[1].kind, ToolKind::Grasper);

        let mut header = RestHeader {
            vertex_count: 4,
            fibre_count: 1,
            ..RestHeader::default()
        };
        header.set_name("box.toml");
        let mut slice = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        slice.extend([[0.25, 0.25, 0.25], [0.3, 0.0, 0.0]]);
        assert!(!info.set_rest(&header, &slice[..5]), "short slice refused");
        assert!(info.set_rest(&header, &slice));
        assert_eq!(info.name, "box.toml");
        assert_eq!(info.rest_m.len(), 4);
        assert_eq!(info.fibres.len(), 1);
        assert!((info.fibres[0].1[0] - 0.1).abs() < 1e-7);

        info.set_original_surface(&[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]);
        // The same face listed in another order is still the original one.
        assert!(!info.is_cut_face([2, 1, 0]));
        assert!(info.is_cut_face([0, 1, 4]));
    }
}
