//! What the viewer takes from the scene file (the same one the simulation
//! runs): the tools' geometry, the original surface (so faces made by cuts
//! can be told apart) and the fibre directions.

use sim_server::ids::TetId;
use sim_server::mesh::TetMesh;
use sim_server::scene::{SceneError, SceneSource, ToolDecl, build_scene};
use std::collections::HashSet;
use std::path::Path;

/// A fibre to draw: tetrahedron centroid and direction scaled to a length (m).
pub type Fibre = ([f32; 3], [f32; 3]);

/// The parts of a scene the viewer draws.
pub struct SceneInfo {
    /// The scene's name (file or embedded).
    pub name: String,
    /// Declared tools, in order.
    pub tools: Vec<ToolDecl>,
    /// Vertices of the scene's mesh.
    pub vertex_count: usize,
    /// Rest positions (m): a picture before the simulation sends any.
    pub rest_m: Vec<[f32; 3]>,
    /// The uncut surface.
    pub surface: Vec<[u32; 3]>,
    original: HashSet<[u32; 3]>,
    /// One segment per anisotropic tetrahedron.
    pub fibres: Vec<Fibre>,
}

fn key(t: [u32; 3]) -> [u32; 3] {
    let mut k = t;
    k.sort_unstable();
    k
}

impl SceneInfo {
    /// Reads and builds the scene at `path` (`None`: the embedded liver).
    pub fn load(path: Option<&Path>) -> Result<Self, SceneError> {
        let src = match path {
            Some(p) => SceneSource::read(p)?,
            None => SceneSource::embedded(),
        };
        let spec = src.parse()?;
        let built = build_scene(&src, &spec)?;
        let model = &built.model;
        let mesh: &TetMesh = model.mesh();
        let surface: Vec<[u32; 3]> = model
            .topology()
            .surface_triangles(mesh)
            .map(|t| t.map(|v| v.0))
            .collect();
        let rest_m: Vec<[f32; 3]> = mesh
            .positions_m()
            .iter()
            .map(|p| p.as_vec3().to_array())
            .collect();
        let mut fibres = Vec::new();
        for (t, tet) in mesh.tets().iter().enumerate() {
            let f = model.materials().fiber(TetId::from(t));
            if f == sim_server::math::Vec3::ZERO {
                continue;
            }
            let c = tet
                .iter()
                .map(|v| mesh.positions_m()[v.idx()])
                .sum::<sim_server::math::Vec3>()
                / 4.0;
            // Short enough not to hide the surface: a third of the cell.
            let edge =
                (mesh.positions_m()[tet[0].idx()] - mesh.positions_m()[tet[1].idx()]).length();
            fibres.push((
                c.as_vec3().to_array(),
                (f * edge / 3.0).as_vec3().to_array(),
            ));
        }
        Ok(Self {
            name: src.name.clone(),
            tools: built.tools.clone(),
            vertex_count: mesh.vertex_count(),
            rest_m,
            original: surface.iter().map(|&t| key(t)).collect(),
            surface,
            fibres,
        })
    }

    /// Whether `tri` is a face the scene did not start with (made by a cut).
    pub fn is_cut_face(&self, tri: [u32; 3]) -> bool {
        !self.original.contains(&key(tri))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_embedded_liver_has_tools_an_uncut_surface_and_fibres() {
        let info = SceneInfo::load(None).unwrap();
        assert!(info.tools.len() >= 2);
        assert!(!info.surface.is_empty());
        assert!(info.surface.iter().all(|&t| !info.is_cut_face(t)));
        // The same face listed in another order is still the original one.
        let [a, b, c] = info.surface[0];
        assert!(!info.is_cut_face([c, a, b]));
        // Faces inside the organ count as cut faces once exposed.
        let src = SceneSource::embedded();
        let built = build_scene(&src, &src.parse().unwrap()).unwrap();
        let mesh = built.model.mesh();
        let inner = mesh
            .tets()
            .iter()
            .flat_map(|t| sim_server::mesh::TET_FACES.map(|f| f.map(|l| t[l].0)))
            .find(|f| !info.surface.iter().any(|s| key(*s) == key(*f)))
            .unwrap();
        assert!(info.is_cut_face(inner));
        assert_eq!(info.rest_m.len(), info.vertex_count);
        assert!(
            !info.fibres.is_empty(),
            "the liver's vessels are anisotropic"
        );
    }
}
