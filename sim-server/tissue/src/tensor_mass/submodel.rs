//! A part of a model as a model of its own: some of its tetrahedra, their
//! vertices renumbered compactly (in the parent's order, which keeps its
//! locality), their materials and fibres, and the parent's capsule on the
//! faces of the part that lie on the parent's surface (not on the faces
//! where the part meets the rest). The hybrid backend splits a body this
//! way.

use super::model::{ElasticModel, ModelError};
use crate::ids::{TetId, VertexId};
use crate::membrane::MembraneModel;
use crate::mesh::{MeshError, TetMesh};
use thiserror::Error;

/// Why a part could not be made.
#[derive(Debug, Error, PartialEq)]
pub enum SubmodelError {
    /// The part has no tetrahedra.
    #[error("the part has no tetrahedra")]
    Empty,
    /// A tetrahedron is not in the parent, or is cut away.
    #[error("tetrahedron {0} is not a live tetrahedron of the model")]
    NotLive(u32),
    /// The part's mesh was refused.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// The part's model was refused.
    #[error(transparent)]
    Model(#[from] ModelError),
}

/// A part and how its numbering maps to the parent's.
#[derive(Clone, Debug)]
pub struct Submodel {
    /// The part as a model.
    pub model: ElasticModel,
    /// Parent vertex of each local vertex (increasing).
    pub vertices: Vec<VertexId>,
    /// Parent tetrahedron of each local tetrahedron (as given).
    pub tets: Vec<TetId>,
}

impl ElasticModel {
    /// The tetrahedra `tets` as a model of their own. A parent membrane is
    /// carried over on the part's faces that are on the parent's surface,
    /// in `membrane` model when given (else the parent's).
    pub fn submodel(
        &self,
        tets: &[TetId],
        membrane: Option<MembraneModel>,
    ) -> Result<Submodel, SubmodelError> {
        if tets.is_empty() {
            return Err(SubmodelError::Empty);
        }
        let n = self.vertex_count();
        let mut local = vec![u32::MAX; n];
        for t in tets {
            if t.idx() >= self.mesh().tet_count() || !self.topology().is_alive(*t) {
                return Err(SubmodelError::NotLive(t.0));
            }
            for v in self.mesh().tets()[t.idx()] {
                local[v.idx()] = 0;
            }
        }
        let mut vertices = Vec::new();
        for (v, l) in local.iter_mut().enumerate() {
            if *l == 0 {
                *l = vertices.len() as u32;
                vertices.push(VertexId::from(v));
            }
        }
        let positions = vertices
            .iter()
            .map(|v| self.mesh().positions_m()[v.idx()])
            .collect();
        let cells = tets
            .iter()
            .map(|t| self.mesh().tets()[t.idx()].map(|v| local[v.idx()]))
            .collect();
        let mesh = TetMesh::new(positions, cells)?;
        let materials = self.materials().subset(tets);
        let mut model = ElasticModel::new(mesh, materials)?;
        if let Some(m) = self.membrane() {
            let parent = self.topology();
            model = model.with_membrane_on(
                m.alpha_n_per_m2(),
                membrane.unwrap_or(m.model()),
                |t, k| parent.is_surface_face(tets[t.idx()], k),
            )?;
        }
        Ok(Submodel {
            model,
            vertices,
            tets: tets.to_vec(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::Material;
    use crate::material_map::TetMaterials;
    use crate::math::{Mat3, Vec3};
    use crate::mesh::{BoxSpec, CellSize};

    fn parent() -> ElasticModel {
        let mesh = BoxSpec::new(Vec3::new(0.03, 0.02, 0.02), CellSize::EdgeM(0.01))
            .generate()
            .unwrap();
        let tissue = Material::isotropic(5000.0, 0.45, 1000.0, 5.0).unwrap();
        let n = mesh.tet_count();
        ElasticModel::new(mesh, TetMaterials::uniform(tissue, n))
            .unwrap()
            .with_membrane(800.0, MembraneModel::Linear)
            .unwrap()
    }

    /// The two parts' tensors, masses and membranes add up to the parent's.
    #[test]
    fn two_parts_add_up_to_the_whole() {
        let m = parent();
        let (a, b): (Vec<TetId>, Vec<TetId>) = (0..m.mesh().tet_count())
            .map(TetId::from)
            .partition(|t| m.mesh().tet_points(*t)[0].x < 0.015);
        assert!(!a.is_empty() && !b.is_empty());
        let n = m.vertex_count();
        let mut vk = vec![Mat3::ZERO; n];
        let mut mass = vec![0.0; n];
        let mut ek = std::collections::HashMap::new();
        for part in [&a, &b] {
            let s = m.submodel(part, None).unwrap();
            let g = &s.vertices;
            for (l, k) in s.model.vertex_tensors().iter().enumerate() {
                vk[g[l].idx()] += *k;
                mass[g[l].idx()] += s.model.masses_kg()[l];
            }
            for ([x, y], k) in s
                .model
                .topology()
                .edges()
                .iter()
                .zip(s.model.edge_tensors())
            {
                *ek.entry((g[x.idx()], g[y.idx()])).or_insert(Mat3::ZERO) += *k;
            }
        }
        for v in 0..n {
            assert!((vk[v] - m.vertex_tensors()[v]).abs_diff_eq(Mat3::ZERO, 1e-9));
            assert!((mass[v] - m.masses_kg()[v]).abs() < 1e-15);
        }
        for ([x, y], k) in m.topology().edges().iter().zip(m.edge_tensors()) {
            let got = ek.get(&(*x, *y)).copied().unwrap_or(Mat3::ZERO);
            assert!((got - *k).abs_diff_eq(Mat3::ZERO, 1e-9), "edge {x:?}-{y:?}");
        }
    }

    #[test]
    fn an_empty_or_dead_part_is_refused() {
        let mut m = parent();
        assert_eq!(m.submodel(&[], None).unwrap_err(), SubmodelError::Empty);
        m.remove_tet(TetId(3)).unwrap();
        assert_eq!(
            m.submodel(&[TetId(2), TetId(3)], None).unwrap_err(),
            SubmodelError::NotLive(3)
        );
    }
}
