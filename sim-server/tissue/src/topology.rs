//! Topology that changes with cutting: which tetrahedra are alive, the edges
//! and how many live tetrahedra use each edge and vertex, face neighbours, and
//! the current surface (faces with a live tetrahedron on one side only).

use crate::ids::{EdgeId, TetId, VertexId};
use crate::mesh::{TET_EDGES, TET_FACES, TetMesh};

const NONE: u32 = u32::MAX;

/// Edges, adjacency counts and the live surface of a mesh under cutting.
#[derive(Clone, Debug)]
pub struct Topology {
    /// Edge vertex pairs (a < b), sorted by (a, b): the order of the stiffness
    /// kernel's rows.
    edges: Vec<[VertexId; 2]>,
    tet_edges: Vec<[EdgeId; 6]>,
    /// Neighbour across face k of each tetrahedron (NONE on the boundary).
    neighbours: Vec<[u32; 4]>,
    alive: Vec<bool>,
    edge_tets: Vec<u32>,
    vertex_tets: Vec<u32>,
    surface: Vec<(TetId, u8)>,
    /// Position of each (tet, face) in `surface`, NONE if not on the surface.
    surface_slot: Vec<[u32; 4]>,
    /// The first face (by vertex ids) that more than two tetrahedra share,
    /// if any: see [`Topology::overshared_face`].
    overshared: Option<OversharedFace>,
}

/// A face of a volume mesh that more than two tetrahedra share: the mesh
/// overlaps itself there (a duplicated or folded element), which no
/// neighbour relation (and so no cut) can represent.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OversharedFace {
    /// The face's vertices, ascending.
    pub vertices: [VertexId; 3],
    /// The tetrahedra that share it (at least three).
    pub tets: Vec<TetId>,
}

/// A surface triangle, oriented with its normal out of the tissue.
pub type Triangle = [VertexId; 3];

impl Topology {
    /// Builds edges, face neighbours and the surface of `mesh`, all tetrahedra alive.
    pub fn new(mesh: &TetMesh) -> Self {
        let tets = mesh.tets();
        // Edges: sort (a, b, tet, local) and number the distinct pairs.
        let mut pairs: Vec<(u32, u32, u32, u8)> = Vec::with_capacity(tets.len() * 6);
        for (t, tet) in tets.iter().enumerate() {
            for (l, [i, j]) in TET_EDGES.iter().enumerate() {
                let (a, b) = (tet[*i].0.min(tet[*j].0), tet[*i].0.max(tet[*j].0));
                pairs.push((a, b, t as u32, l as u8));
            }
        }
        pairs.sort_unstable();
        let mut edges = Vec::new();
        let mut tet_edges = vec![[EdgeId(0); 6]; tets.len()];
        let mut edge_tets = Vec::new();
        for (k, &(a, b, t, l)) in pairs.iter().enumerate() {
            if k == 0 || (pairs[k - 1].0, pairs[k - 1].1) != (a, b) {
                edges.push([VertexId(a), VertexId(b)]);
                edge_tets.push(0);
            }
            let e = edges.len() - 1;
            tet_edges[t as usize][l as usize] = EdgeId::from(e);
            edge_tets[e] += 1;
        }
        // Faces: sort by their vertex set; pairs of equal keys are neighbours.
        let mut faces: Vec<([u32; 3], u32, u8)> = Vec::with_capacity(tets.len() * 4);
        for (t, tet) in tets.iter().enumerate() {
            for (k, f) in TET_FACES.iter().enumerate() {
                let mut key = f.map(|l| tet[l].0);
                key.sort_unstable();
                faces.push((key, t as u32, k as u8));
            }
        }
        faces.sort_unstable();
        let mut neighbours = vec![[NONE; 4]; tets.len()];
        for w in faces.windows(2) {
            if w[0].0 == w[1].0 {
                neighbours[w[0].1 as usize][w[0].2 as usize] = w[1].1;
                neighbours[w[1].1 as usize][w[1].2 as usize] = w[0].1;
            }
        }
        // A face in three or more tetrahedra gets one-sided links above:
        // found here, refused by the model (a cut there would break them).
        let overshared = faces
            .chunk_by(|a, b| a.0 == b.0)
            .find(|run| run.len() > 2)
            .map(|run| OversharedFace {
                vertices: run[0].0.map(VertexId),
                tets: run.iter().map(|f| TetId(f.1)).collect(),
            });
        let mut vertex_tets = vec![0u32; mesh.vertex_count()];
        for tet in tets {
            for v in tet {
                vertex_tets[v.idx()] += 1;
            }
        }
        let mut topo = Self {
            edges,
            tet_edges,
            neighbours,
            alive: vec![true; tets.len()],
            edge_tets,
            vertex_tets,
            surface: Vec::new(),
            surface_slot: vec![[NONE; 4]; tets.len()],
            overshared,
        };
        for t in 0..tets.len() {
            for k in 0..4 {
                if topo.neighbours[t][k] == NONE {
                    topo.surface_insert(TetId::from(t), k);
                }
            }
        }
        topo
    }

    /// The first face more than two tetrahedra share (`None` in a valid
    /// volume mesh). [`crate::tensor_mass::ElasticModel::new`] refuses such
    /// a mesh.
    pub fn overshared_face(&self) -> Option<&OversharedFace> {
        self.overshared.as_ref()
    }

    fn surface_insert(&mut self, t: TetId, k: usize) {
        debug_assert_eq!(self.surface_slot[t.idx()][k], NONE);
        self.surface_slot[t.idx()][k] = self.surface.len() as u32;
        self.surface.push((t, k as u8));
    }

    fn surface_remove(&mut self, t: TetId, k: usize) {
        let slot = self.surface_slot[t.idx()][k];
        debug_assert_ne!(slot, NONE);
        self.surface_slot[t.idx()][k] = NONE;
        self.surface.swap_remove(slot as usize);
        if let Some(&(moved, mk)) = self.surface.get(slot as usize) {
            self.surface_slot[moved.idx()][mk as usize] = slot;
        }
    }

    /// Which face of `n` is shared with `t`.
    fn shared_face(&self, n: u32, t: TetId) -> usize {
        self.neighbours[n as usize]
            .iter()
            .position(|&x| x == t.0)
            .expect("neighbour relation is symmetric")
    }

    /// Marks `t` dead: updates the counts and the surface (its surface faces
    /// disappear, faces it shared with live neighbours appear). Returns the
    /// vertices (`vertices`, those of `t`) and edges whose count dropped to
    /// zero in `orphans`. `t` must be alive.
    pub(crate) fn remove(&mut self, t: TetId, vertices: [VertexId; 4], orphans: &mut Orphans) {
        debug_assert!(self.alive[t.idx()]);
        self.alive[t.idx()] = false;
        for k in 0..4 {
            let n = self.neighbours[t.idx()][k];
            if n != NONE && self.alive[n as usize] {
                let nk = self.shared_face(n, t);
                self.surface_insert(TetId(n), nk);
            } else {
                self.surface_remove(t, k);
            }
        }
        orphans.clear();
        for e in self.tet_edges[t.idx()] {
            self.edge_tets[e.idx()] -= 1;
            if self.edge_tets[e.idx()] == 0 {
                orphans.edges.push(e);
            }
        }
        for v in vertices {
            self.vertex_tets[v.idx()] -= 1;
            if self.vertex_tets[v.idx()] == 0 {
                orphans.vertices.push(v);
            }
        }
    }

    /// Revives `t` (the inverse of [`Topology::remove`]). `t` must be dead.
    pub(crate) fn revive(&mut self, t: TetId, vertices: [VertexId; 4]) {
        debug_assert!(!self.alive[t.idx()]);
        self.alive[t.idx()] = true;
        for k in 0..4 {
            let n = self.neighbours[t.idx()][k];
            if n != NONE && self.alive[n as usize] {
                let nk = self.shared_face(n, t);
                self.surface_remove(TetId(n), nk);
            } else {
                self.surface_insert(t, k);
            }
        }
        for e in self.tet_edges[t.idx()] {
            self.edge_tets[e.idx()] += 1;
        }
        for v in vertices {
            self.vertex_tets[v.idx()] += 1;
        }
    }

    /// Edge vertex pairs (a < b), sorted.
    pub fn edges(&self) -> &[[VertexId; 2]] {
        &self.edges
    }

    /// The six edges of tetrahedron `t`, in [`TET_EDGES`] order.
    pub fn tet_edges(&self, t: TetId) -> [EdgeId; 6] {
        self.tet_edges[t.idx()]
    }

    /// Whether `t` is alive.
    pub fn is_alive(&self, t: TetId) -> bool {
        self.alive[t.idx()]
    }

    /// Per tetrahedron, whether it is alive.
    pub fn alive(&self) -> &[bool] {
        &self.alive
    }

    /// Number of live tetrahedra.
    pub fn alive_count(&self) -> usize {
        self.alive.iter().filter(|a| **a).count()
    }

    /// Number of live tetrahedra using edge `e`.
    pub fn edge_tet_count(&self, e: EdgeId) -> u32 {
        self.edge_tets[e.idx()]
    }

    /// Number of live tetrahedra using vertex `v` (0 for an orphan).
    pub fn vertex_tet_count(&self, v: VertexId) -> u32 {
        self.vertex_tets[v.idx()]
    }

    /// Number of surface triangles.
    pub fn surface_len(&self) -> usize {
        self.surface.len()
    }

    /// Whether face `k` (index into [`TET_FACES`]) of `t` is on the surface.
    pub fn is_surface_face(&self, t: TetId, k: usize) -> bool {
        self.surface_slot[t.idx()][k] != NONE
    }

    /// The current surface faces as (tetrahedron, local face index into
    /// [`TET_FACES`]).
    pub fn surface_faces(&self) -> impl Iterator<Item = (TetId, usize)> + '_ {
        self.surface.iter().map(|&(t, k)| (t, k as usize))
    }

    /// The current surface triangles, oriented outwards, given the mesh.
    pub fn surface_triangles<'a>(
        &'a self,
        mesh: &'a TetMesh,
    ) -> impl Iterator<Item = Triangle> + 'a {
        self.surface.iter().map(move |&(t, k)| {
            let tet = mesh.tets()[t.idx()];
            TET_FACES[k as usize].map(|l| tet[l])
        })
    }
}

/// Vertices and edges left without any live tetrahedron by a removal.
#[derive(Clone, Debug, Default)]
pub struct Orphans {
    /// Orphaned vertices.
    pub vertices: Vec<VertexId>,
    /// Orphaned edges.
    pub edges: Vec<EdgeId>,
}

impl Orphans {
    fn clear(&mut self) {
        self.vertices.clear();
        self.edges.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Real, Vec3};
    use crate::mesh::{BoxSpec, CellSize};

    /// Divergence theorem: the signed volume enclosed by the surface equals the
    /// volume of the live tetrahedra (so the surface is closed and outward).
    fn enclosed_volume(topo: &Topology, mesh: &TetMesh) -> Real {
        topo.surface_triangles(mesh)
            .map(|[a, b, c]| {
                let p = mesh.positions_m();
                p[a.idx()].dot(p[b.idx()].cross(p[c.idx()])) / 6.0
            })
            .sum()
    }

    fn live_volume(topo: &Topology, mesh: &TetMesh) -> Real {
        (0..mesh.tet_count())
            .map(TetId::from)
            .filter(|t| topo.is_alive(*t))
            .map(|t| mesh.tet_volume_m3(t))
            .sum()
    }

    /// Three tetrahedra on the face (0, 1, 2): below it, above it, and a
    /// third above it overlapping the second.
    fn overshared_mesh() -> TetMesh {
        let p = |x: Real, y: Real, z: Real| Vec3::new(x, y, z) * 0.01;
        TetMesh::new(
            vec![
                p(0.0, 0.0, 0.0),
                p(1.0, 0.0, 0.0),
                p(0.0, 1.0, 0.0),
                p(0.0, 0.0, 1.0),
                p(0.0, 0.0, -1.0),
                p(0.2, 0.2, 0.5),
            ],
            vec![[0, 1, 2, 3], [0, 2, 1, 4], [0, 1, 2, 5]],
        )
        .unwrap()
    }

    #[test]
    fn a_face_in_three_tetrahedra_is_found_and_the_model_refuses_it() {
        let mesh = overshared_mesh();
        let face = Topology::new(&mesh).overshared_face().cloned();
        assert_eq!(
            face,
            Some(OversharedFace {
                vertices: [VertexId(0), VertexId(1), VertexId(2)],
                tets: vec![TetId(0), TetId(1), TetId(2)],
            })
        );
        let tissue = crate::material::Material::isotropic(3000.0, 0.4, 1000.0, 5.0).unwrap();
        let materials = crate::material_map::TetMaterials::uniform(tissue, mesh.tet_count());
        let err = crate::tensor_mass::ElasticModel::new(mesh, materials).unwrap_err();
        assert!(
            err.to_string()
                .contains("shared by 3 tetrahedra ([0, 1, 2])"),
            "{err}"
        );
        // Two of them are a valid mesh (the face joins two).
        let two = TetMesh::new(
            overshared_mesh().positions_m().to_vec(),
            vec![[0, 1, 2, 3], [0, 2, 1, 4]],
        )
        .unwrap();
        assert_eq!(Topology::new(&two).overshared_face(), None);
    }

    #[test]
    fn surface_stays_closed_through_cuts_and_revivals() {
        let mesh = BoxSpec::new(Vec3::new(0.03, 0.02, 0.02), CellSize::EdgeM(0.01))
            .generate()
            .unwrap();
        let mut topo = Topology::new(&mesh);
        // 3x2x2 cells: 2 * (6 + 6 + 4) squares, 2 triangles each.
        assert_eq!(topo.surface_len(), 2 * 2 * (6 + 6 + 4));
        assert!((enclosed_volume(&topo, &mesh) - 0.03 * 0.02 * 0.02).abs() < 1e-15);
        let mut orphans = Orphans::default();
        let order: Vec<TetId> = (0..mesh.tet_count()).step_by(5).map(TetId::from).collect();
        for &t in &order {
            topo.remove(t, mesh.tets()[t.idx()], &mut orphans);
            let (a, b) = (enclosed_volume(&topo, &mesh), live_volume(&topo, &mesh));
            assert!((a - b).abs() < 1e-15, "after removing {t:?}: {a} vs {b}");
        }
        for &t in order.iter().rev() {
            topo.revive(t, mesh.tets()[t.idx()]);
        }
        let fresh = Topology::new(&mesh);
        assert_eq!(topo.surface_len(), fresh.surface_len());
        assert_eq!(topo.edge_tets, fresh.edge_tets);
        assert_eq!(topo.vertex_tets, fresh.vertex_tets);
    }

    #[test]
    fn removing_everything_orphans_everything() {
        let mesh = BoxSpec::new(Vec3::splat(0.02), CellSize::EdgeM(0.01))
            .generate()
            .unwrap();
        let mut topo = Topology::new(&mesh);
        let mut orphans = Orphans::default();
        let (mut v, mut e) = (0, 0);
        for t in 0..mesh.tet_count() {
            topo.remove(TetId::from(t), mesh.tets()[t], &mut orphans);
            v += orphans.vertices.len();
            e += orphans.edges.len();
        }
        assert_eq!(v, mesh.vertex_count());
        assert_eq!(e, topo.edges().len());
        assert_eq!(topo.surface_len(), 0);
    }
}
