//! Mesh quality and topology checks: dihedral angles, aspect ratios, edge lengths,
//! duplicate and unused vertices, non-manifold pieces, connected components.
//!
//! The explicit integrator's stable step and the conditioning of the static
//! solve are set by the worst element, so the report names it; the topology
//! counts catch meshes that validate element by element but would make the
//! surface extraction, cutting or the viewer misbehave.

use super::{TET_EDGES, TET_FACES, TetMesh};
use crate::ids::TetId;
use crate::math::{Real, Vec3, tet_signed_volume};
use std::collections::HashMap;
use std::fmt;

/// Distance, relative to the bounding-box diagonal, below which two vertices
/// count as duplicates.
pub const DUPLICATE_RELATIVE_DISTANCE: Real = 1e-9;

/// A summary of a mesh's element quality and topology (`sim-server check`).
#[derive(Clone, Debug, PartialEq)]
pub struct QualityReport {
    /// Number of tetrahedra.
    pub tets: usize,
    /// Number of vertices.
    pub vertices: usize,
    /// Vertices referenced by at least one tetrahedron.
    pub used_vertices: usize,
    /// Smallest interior dihedral angle over all tetrahedra (degrees).
    pub min_dihedral_deg: Real,
    /// Largest interior dihedral angle over all tetrahedra (degrees).
    pub max_dihedral_deg: Real,
    /// Largest aspect ratio, see [`aspect_ratio`]: 1 for a regular tetrahedron,
    /// unbounded for a flat one.
    pub max_aspect_ratio: Real,
    /// Mean aspect ratio over the tetrahedra.
    pub mean_aspect_ratio: Real,
    /// Shortest tetrahedron edge (m).
    pub shortest_edge_m: Real,
    /// Longest tetrahedron edge (m).
    pub longest_edge_m: Real,
    /// Smallest tetrahedron volume (m^3).
    pub min_volume_m3: Real,
    /// The tetrahedron with the smallest dihedral angle.
    pub worst_tet: TetId,
    /// Vertices closer than [`DUPLICATE_RELATIVE_DISTANCE`] times the
    /// bounding-box diagonal to another vertex (each such vertex counts).
    pub duplicate_vertices: usize,
    /// Vertices no tetrahedron references.
    pub unused_vertices: usize,
    /// Faces shared by more than two tetrahedra.
    pub non_manifold_faces: usize,
    /// Vertices whose link is not a single disk or sphere (see `vertex_link`).
    pub non_manifold_vertices: usize,
    /// Connected pieces, tetrahedra being connected through shared faces.
    pub components: usize,
}

/// The six interior dihedral angles (degrees) of a tetrahedron, in the order
/// of [`TET_EDGES`]: the angle at edge (a, b) between the two faces that share it.
pub fn dihedral_angles_deg(p: [Vec3; 4]) -> [Real; 6] {
    TET_EDGES.map(|[a, b]| {
        // The two other vertices, projected onto the plane normal to the edge:
        // the angle between the projections is the angle between the faces.
        let [c, d] = other_two(a, b);
        let e = (p[b] - p[a]).normalize_or_zero();
        let u = p[c] - p[a];
        let v = p[d] - p[a];
        let u = u - e * u.dot(e);
        let v = v - e * v.dot(e);
        let cos = u.dot(v) / (u.length() * v.length());
        if cos.is_finite() {
            cos.clamp(-1.0, 1.0).acos().to_degrees()
        } else {
            0.0
        }
    })
}

/// The local vertices of a tetrahedron that are not `a` or `b`.
fn other_two(a: usize, b: usize) -> [usize; 2] {
    let mut out = [0; 2];
    let mut k = 0;
    for i in 0..4 {
        if i != a && i != b {
            out[k] = i;
            k += 1;
        }
    }
    out
}

/// Aspect ratio: longest edge / (2 sqrt(6) inradius), where the inradius is
/// 3 V / (sum of the face areas). The factor makes a regular tetrahedron 1;
/// it grows without bound as the tetrahedron flattens (slivers included,
/// which an edge-ratio measure would miss). Infinite for zero volume.
pub fn aspect_ratio(p: [Vec3; 4]) -> Real {
    let volume = tet_signed_volume(p[0], p[1], p[2], p[3]).abs();
    let area: Real = TET_FACES
        .iter()
        .map(|[a, b, c]| 0.5 * (p[*b] - p[*a]).cross(p[*c] - p[*a]).length())
        .sum();
    let longest = TET_EDGES
        .iter()
        .map(|[a, b]| p[*a].distance(p[*b]))
        .fold(0.0, Real::max);
    let inradius = 3.0 * volume / area;
    if inradius > 0.0 {
        longest / (2.0 * 6.0_f64.sqrt() * inradius)
    } else {
        Real::INFINITY
    }
}

/// Face `k` of `tet` with its vertices sorted: the key that identifies a face
/// independently of which tetrahedron lists it.
pub fn face_key(tet: &[u32; 4], k: usize) -> [u32; 3] {
    let mut f = TET_FACES[k].map(|i| tet[i]);
    f.sort_unstable();
    f
}

/// Every face of every tetrahedron as (sorted face, tetrahedron, local face),
/// sorted so that copies of the same face are adjacent.
pub(crate) fn sorted_faces(tets: &[[u32; 4]]) -> Vec<([u32; 3], u32, u8)> {
    let mut faces: Vec<_> = tets
        .iter()
        .enumerate()
        .flat_map(|(t, tet)| (0..4).map(move |k| (face_key(tet, k), t as u32, k as u8)))
        .collect();
    faces.sort_unstable();
    faces
}

/// Connected pieces of a tetrahedron set, tetrahedra being connected through
/// shared faces: (number of pieces, the piece of each tetrahedron).
pub(crate) fn tet_components(tets: &[[u32; 4]]) -> (usize, Vec<u32>) {
    let mut parent: Vec<u32> = (0..tets.len() as u32).collect();
    let faces = sorted_faces(tets);
    for pair in faces.windows(2) {
        if pair[0].0 == pair[1].0 {
            union(&mut parent, pair[0].1, pair[1].1);
        }
    }
    let mut label = vec![u32::MAX; tets.len()];
    let mut count = 0;
    let mut piece = vec![0u32; tets.len()];
    for (t, slot) in piece.iter_mut().enumerate() {
        let root = find(&mut parent, t as u32) as usize;
        if label[root] == u32::MAX {
            label[root] = count;
            count += 1;
        }
        *slot = label[root];
    }
    (count as usize, piece)
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        // Path halving keeps the trees shallow without recursion.
        parent[x as usize] = parent[parent[x as usize] as usize];
        x = parent[x as usize];
    }
    x
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
}

/// The tetrahedra around each vertex, in compressed rows:
/// `tets[start[v]..start[v + 1]]` are the tetrahedra that use vertex `v`.
pub(crate) struct VertexStars {
    pub(crate) start: Vec<usize>,
    pub(crate) tets: Vec<u32>,
}

impl VertexStars {
    pub(crate) fn new(vertex_count: usize, tets: &[[u32; 4]]) -> Self {
        let mut start = vec![0usize; vertex_count + 1];
        for tet in tets {
            for v in tet {
                start[*v as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            start[v + 1] += start[v];
        }
        let mut fill = start.clone();
        let mut out = vec![0u32; start[vertex_count]];
        for (t, tet) in tets.iter().enumerate() {
            for v in tet {
                out[fill[*v as usize]] = t as u32;
                fill[*v as usize] += 1;
            }
        }
        Self { start, tets: out }
    }

    pub(crate) fn of(&self, v: usize) -> &[u32] {
        &self.tets[self.start[v]..self.start[v + 1]]
    }
}

/// The link of a vertex: the triangles opposite it in the tetrahedra around it.
#[derive(Debug)]
pub(crate) struct Link {
    /// The tetrahedra of the star grouped into fans: tetrahedra whose link
    /// triangles are connected through shared link edges (that is, the
    /// tetrahedra are connected through faces that contain the vertex).
    pub(crate) fans: Vec<Vec<u32>>,
    /// The link is one disk (boundary vertex) or one sphere (interior vertex).
    pub(crate) manifold: bool,
}

/// The link of vertex `v` given the tetrahedra `star` around it.
///
/// The exact test: the link triangles must (1) be connected through shared
/// edges, (2) share each edge between at most two triangles, and (3) have
/// Euler characteristic V - E + F = 2 with no boundary edge (a sphere:
/// interior vertex) or 1 with boundary edges (a disk: surface vertex). With
/// (1) and (2) the link is a connected surface, possibly pinched at vertices;
/// pinching (a non-manifold edge through `v`) lowers the Euler
/// characteristic, and the only connected surfaces with characteristic 2 and
/// no boundary or 1 with boundary are the sphere and the disk. Two tetrahedra
/// touching only at `v` fail (1); a ring of tetrahedra around an edge with a
/// gap closed elsewhere fails (3).
pub(crate) fn vertex_link(v: u32, star: &[u32], tets: &[[u32; 4]]) -> Link {
    let mut edges: Vec<([u32; 2], u32)> = Vec::with_capacity(star.len() * 3);
    let mut link_vertices: Vec<u32> = Vec::with_capacity(star.len() * 3);
    for (i, &t) in star.iter().enumerate() {
        let mut tri = [0u32; 3];
        let mut k = 0;
        for &w in &tets[t as usize] {
            if w != v && k < 3 {
                tri[k] = w;
                k += 1;
            }
        }
        tri.sort_unstable();
        link_vertices.extend(tri);
        for [a, b] in [[0, 1], [0, 2], [1, 2]] {
            edges.push(([tri[a], tri[b]], i as u32));
        }
    }
    edges.sort_unstable();
    link_vertices.sort_unstable();
    link_vertices.dedup();
    let mut parent: Vec<u32> = (0..star.len() as u32).collect();
    let (mut edge_count, mut boundary, mut overfull) = (0usize, false, false);
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j].0 == edges[i].0 {
            union(&mut parent, edges[i].1, edges[j].1);
            j += 1;
        }
        edge_count += 1;
        boundary |= j - i == 1;
        overfull |= j - i > 2;
        i = j;
    }
    let mut fans: Vec<Vec<u32>> = Vec::new();
    let mut fan_of_root: HashMap<u32, usize> = HashMap::new();
    for (i, &t) in star.iter().enumerate() {
        let root = find(&mut parent, i as u32);
        let f = *fan_of_root.entry(root).or_insert_with(|| {
            fans.push(Vec::new());
            fans.len() - 1
        });
        fans[f].push(t);
    }
    let euler = link_vertices.len() as i64 - edge_count as i64 + star.len() as i64;
    let manifold = fans.len() == 1 && !overfull && if boundary { euler == 1 } else { euler == 2 };
    Link { fans, manifold }
}

/// Vertices closer than `tolerance` to another vertex, found with a hash grid
/// of cell `tolerance` (each vertex looks at its 27 neighbouring cells).
fn duplicate_count(points: &[Vec3], tolerance: Real) -> usize {
    if points.is_empty() || tolerance <= 0.0 {
        return 0;
    }
    // Keys relative to the minimum corner so they stay small integers
    // however far the mesh is from the origin.
    let lo = points
        .iter()
        .fold(Vec3::splat(Real::INFINITY), |a, p| a.min(*p));
    let key = |p: Vec3| ((p - lo) / tolerance).floor().as_i64vec3().to_array();
    let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    for (i, p) in points.iter().enumerate() {
        grid.entry(key(*p)).or_default().push(i as u32);
    }
    let mut count = 0;
    for (i, p) in points.iter().enumerate() {
        let [x, y, z] = key(*p);
        let mut found = false;
        'search: for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(cell) = grid.get(&[x + dx, y + dy, z + dz]) else {
                        continue;
                    };
                    if cell
                        .iter()
                        .any(|&j| j as usize != i && points[j as usize].distance(*p) < tolerance)
                    {
                        found = true;
                        break 'search;
                    }
                }
            }
        }
        count += usize::from(found);
    }
    count
}

/// Measures a mesh (linear in its size, plus sorting the faces).
pub fn quality_report(mesh: &TetMesh) -> QualityReport {
    let tets: Vec<[u32; 4]> = mesh.tets().iter().map(|t| t.map(|v| v.0)).collect();
    let n = mesh.vertex_count();
    let mut r = QualityReport {
        tets: tets.len(),
        vertices: n,
        used_vertices: 0,
        min_dihedral_deg: Real::INFINITY,
        max_dihedral_deg: 0.0,
        max_aspect_ratio: 0.0,
        mean_aspect_ratio: 0.0,
        shortest_edge_m: Real::INFINITY,
        longest_edge_m: 0.0,
        min_volume_m3: Real::INFINITY,
        worst_tet: TetId(0),
        duplicate_vertices: 0,
        unused_vertices: 0,
        non_manifold_faces: 0,
        non_manifold_vertices: 0,
        components: 0,
    };
    let mut aspect_sum = 0.0;
    for t in 0..tets.len() {
        let p = mesh.tet_points(TetId(t as u32));
        let angles = dihedral_angles_deg(p);
        let lo = angles.iter().copied().fold(Real::INFINITY, Real::min);
        if lo < r.min_dihedral_deg {
            r.min_dihedral_deg = lo;
            r.worst_tet = TetId(t as u32);
        }
        r.max_dihedral_deg = angles.iter().copied().fold(r.max_dihedral_deg, Real::max);
        let aspect = aspect_ratio(p);
        r.max_aspect_ratio = r.max_aspect_ratio.max(aspect);
        aspect_sum += aspect;
        for [a, b] in TET_EDGES {
            let l = p[a].distance(p[b]);
            r.shortest_edge_m = r.shortest_edge_m.min(l);
            r.longest_edge_m = r.longest_edge_m.max(l);
        }
        r.min_volume_m3 = r
            .min_volume_m3
            .min(tet_signed_volume(p[0], p[1], p[2], p[3]));
    }
    r.mean_aspect_ratio = aspect_sum / tets.len().max(1) as Real;

    let stars = VertexStars::new(n, &tets);
    r.used_vertices = (0..n).filter(|&v| !stars.of(v).is_empty()).count();
    r.unused_vertices = n - r.used_vertices;
    r.non_manifold_vertices = (0..n)
        .filter(|&v| !stars.of(v).is_empty() && !vertex_link(v as u32, stars.of(v), &tets).manifold)
        .count();

    let faces = sorted_faces(&tets);
    let mut i = 0;
    while i < faces.len() {
        let j = i + faces[i..].iter().take_while(|f| f.0 == faces[i].0).count();
        r.non_manifold_faces += usize::from(j - i > 2);
        i = j;
    }
    r.components = tet_components(&tets).0;

    let (lo, hi) = mesh.bounds_m();
    r.duplicate_vertices = duplicate_count(
        mesh.positions_m(),
        DUPLICATE_RELATIVE_DISTANCE * lo.distance(hi),
    );
    r
}

impl fmt::Display for QualityReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{} tetrahedra, {} vertices ({} used), {} component(s)",
            self.tets, self.vertices, self.used_vertices, self.components
        )?;
        writeln!(
            f,
            "dihedral angles {:.2} .. {:.2} deg (worst tetrahedron {})",
            self.min_dihedral_deg, self.max_dihedral_deg, self.worst_tet.0
        )?;
        writeln!(
            f,
            "aspect ratio max {:.3}, mean {:.3} (1 = regular)",
            self.max_aspect_ratio, self.mean_aspect_ratio
        )?;
        writeln!(
            f,
            "edges {:.4e} .. {:.4e} m, smallest volume {:.4e} m^3",
            self.shortest_edge_m, self.longest_edge_m, self.min_volume_m3
        )?;
        write!(
            f,
            "duplicate vertices {}, unused vertices {}, non-manifold faces {}, non-manifold vertices {}",
            self.duplicate_vertices,
            self.unused_vertices,
            self.non_manifold_faces,
            self.non_manifold_vertices
        )
    }
}

#[cfg(test)]
mod tests;
