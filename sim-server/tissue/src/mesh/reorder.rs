//! Vertex reordering for memory locality: reverse Cuthill-McKee. The stiffness
//! kernel walks edges row by row and reads the neighbours' displacements; a
//! small bandwidth keeps those reads in cache.

use super::{TET_EDGES, TetMesh};
use crate::ids::VertexId;
use std::collections::VecDeque;

/// Vertex adjacency in compressed rows (neighbours sorted, no self loops).
fn adjacency(mesh: &TetMesh) -> (Vec<usize>, Vec<u32>) {
    let n = mesh.vertex_count();
    let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(mesh.tet_count() * 12);
    for tet in mesh.tets() {
        for [a, b] in TET_EDGES {
            pairs.push((tet[a].0, tet[b].0));
            pairs.push((tet[b].0, tet[a].0));
        }
    }
    pairs.sort_unstable();
    pairs.dedup();
    let mut start = vec![0usize; n + 1];
    for (a, _) in &pairs {
        start[*a as usize + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    (start, pairs.into_iter().map(|(_, b)| b).collect())
}

/// The reverse Cuthill-McKee order of the mesh's vertices: `order[k]` is the
/// vertex that should become vertex `k` (pass it to [`TetMesh::permuted`]).
/// Each connected piece starts from a vertex of minimum degree; unused
/// vertices go last.
pub fn rcm_order(mesh: &TetMesh) -> Vec<VertexId> {
    let n = mesh.vertex_count();
    let (start, adj) = adjacency(mesh);
    let degree = |v: usize| start[v + 1] - start[v];
    let mut visited = vec![false; n];
    let mut order = Vec::with_capacity(n);
    let mut by_degree: Vec<usize> = (0..n).filter(|&v| degree(v) > 0).collect();
    by_degree.sort_by_key(|&v| degree(v));
    let mut queue = VecDeque::new();
    let mut neighbours = Vec::new();
    for &seed in &by_degree {
        if visited[seed] {
            continue;
        }
        visited[seed] = true;
        queue.push_back(seed);
        while let Some(v) = queue.pop_front() {
            order.push(v);
            neighbours.clear();
            neighbours.extend(
                adj[start[v]..start[v + 1]]
                    .iter()
                    .map(|&w| w as usize)
                    .filter(|&w| !visited[w]),
            );
            neighbours.sort_by_key(|&w| degree(w));
            for &w in &neighbours {
                visited[w] = true;
                queue.push_back(w);
            }
        }
    }
    order.reverse();
    order.extend((0..n).filter(|&v| !visited[v]));
    order.into_iter().map(VertexId::from).collect()
}

/// The largest |i - j| over the mesh's edges.
pub fn bandwidth(mesh: &TetMesh) -> usize {
    mesh.tets()
        .iter()
        .flat_map(|t| TET_EDGES.map(|[a, b]| t[a].0.abs_diff(t[b].0) as usize))
        .max()
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec3;
    use crate::mesh::{BoxSpec, CellSize};

    #[test]
    fn rcm_is_a_permutation_that_does_not_widen_a_box() {
        let mesh = BoxSpec::new(Vec3::new(0.1, 0.05, 0.03), CellSize::EdgeM(0.005))
            .generate()
            .unwrap();
        let order = rcm_order(&mesh);
        let mut seen = vec![false; mesh.vertex_count()];
        for v in &order {
            assert!(!seen[v.idx()]);
            seen[v.idx()] = true;
        }
        let permuted = mesh.permuted(&order);
        assert!(bandwidth(&permuted) <= bandwidth(&mesh));
        let vol = |m: &TetMesh| -> f64 {
            (0..m.tet_count())
                .map(|t| m.tet_volume_m3(crate::ids::TetId(t as u32)))
                .sum()
        };
        assert!((vol(&permuted) - vol(&mesh)).abs() < 1e-15);
    }
}
