//! Conforming local refinement of a tetrahedral mesh by longest-edge
//! bisection (Rivara and Levin 1992, "A 3-D refinement algorithm suitable for
//! adaptive and multi-grid techniques"; the longest-edge propagation path of
//! Rivara 1997).
//!
//! Why this design: a tool narrower than the cells wraps a coarse linear
//! surface into a cone that slips off its tip (the design notes on contact);
//! the cure is cells no larger than the tool's radius where it touches, not a
//! finer organ everywhere (explicit cost grows as N^(4/3)). Bisection keeps
//! the mesh conforming at every step (an edge is always split in every
//! tetrahedron that holds it, so no hanging vertex ever exists), children
//! keep their parent's orientation, material and tags, and bisecting only
//! longest edges (after the neighbours' longer ones: the propagation path)
//! keeps the elements' shapes within a few classes, so the explicit stable
//! step falls with the cell size and not with slivers. Red-green refinement
//! was not chosen: its green closures must be undone before a tetrahedron is
//! refined again, and its shapes depend on the order of refinement.
//!
//! The refinement is a function of the mesh's geometry and a target cell
//! size per region: the same input always gives the same mesh, and ties
//! between equal edges are broken by the vertices' positions, not their
//! indices, so that refinements for overlapping regions agree where they
//! overlap (a tetrahedron's bisection tree does not depend on the order its
//! neighbours were split in).

use super::TetMesh;
use crate::ids::TetId;
use crate::math::{Real, Vec3};
use std::collections::HashMap;
use thiserror::Error;

/// An edge as its two vertices, smaller index first.
type Edge = (u32, u32);

fn edge(a: u32, b: u32) -> Edge {
    if a < b { (a, b) } else { (b, a) }
}

/// Why a refinement was refused.
#[derive(Debug, Error, PartialEq)]
pub enum RefineError {
    /// A target cell size that is not a positive finite length.
    #[error("a refinement's cell size must be a positive finite length, got {0} m")]
    BadCell(Real),
    /// The refined mesh failed validation (cannot happen for a valid input:
    /// bisection halves volumes and keeps orientation).
    #[error("the refined mesh is invalid: {0}")]
    Mesh(super::MeshError),
}

// The mesh's error is in the message, not a separate `source()`, so that a
// chain of causes does not say it twice.
impl From<super::MeshError> for RefineError {
    fn from(e: super::MeshError) -> Self {
        Self::Mesh(e)
    }
}

/// A refined mesh and how it descends from the input.
#[derive(Clone, Debug)]
pub struct Refined {
    /// The refined mesh: the input's vertices first, in their order, then
    /// the midpoints in the order they were made.
    pub mesh: TetMesh,
    /// Per refined tetrahedron, the input tetrahedron it lies in.
    pub parent_tet: Vec<u32>,
    /// Per vertex beyond the input's, the edge (two earlier vertices) whose
    /// midpoint it is.
    pub midpoint_of: Vec<[u32; 2]>,
    /// Bisected edges, each with its midpoint and the order it was bisected
    /// in: what [`Refined::split_triangle`] follows.
    bisected: HashMap<Edge, (u32, u32)>,
    /// Whether the refinement stopped at the element budget before every
    /// tetrahedron reached its target.
    pub stopped_at_budget: bool,
}

impl Refined {
    /// The refined mesh's triangles that tile the input triangle `tri`
    /// (a face of the input mesh), each in `tri`'s orientation: how a
    /// tagged surface follows the refinement.
    pub fn split_triangle(&self, tri: [u32; 3]) -> Vec<[u32; 3]> {
        let mut out = Vec::new();
        let mut stack = vec![tri];
        while let Some(t) = stack.pop() {
            // A face lies whole in one tetrahedron until the first of its
            // edges is bisected; then it is split at that edge's midpoint
            // and its halves go on the same way.
            let first = (0..3)
                .filter_map(|k| {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    self.bisected
                        .get(&edge(a, b))
                        .map(|&(m, order)| (order, k, m))
                })
                .min();
            match first {
                None => out.push(t),
                Some((_, k, m)) => {
                    let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                    stack.push([a, m, c]);
                    stack.push([m, b, c]);
                }
            }
        }
        out
    }
}

/// Two points in lexicographic order (x, then y, then z).
fn lex(a: Vec3, b: Vec3) -> std::cmp::Ordering {
    (a.x.total_cmp(&b.x))
        .then(a.y.total_cmp(&b.y))
        .then(a.z.total_cmp(&b.z))
}

/// The working state of one refinement.
struct Bisector {
    positions: Vec<Vec3>,
    tets: Vec<[u32; 4]>,
    parent: Vec<u32>,
    edge_tets: HashMap<Edge, Vec<u32>>,
    bisected: HashMap<Edge, (u32, u32)>,
    midpoint_of: Vec<[u32; 2]>,
}

impl Bisector {
    fn new(mesh: &TetMesh) -> Self {
        let tets: Vec<[u32; 4]> = mesh.tets().iter().map(|t| t.map(|v| v.0)).collect();
        let mut edge_tets: HashMap<Edge, Vec<u32>> = HashMap::with_capacity(tets.len() * 2);
        for (t, tet) in tets.iter().enumerate() {
            for [a, b] in super::TET_EDGES {
                edge_tets
                    .entry(edge(tet[a], tet[b]))
                    .or_default()
                    .push(t as u32);
            }
        }
        Self {
            positions: mesh.positions_m().to_vec(),
            parent: (0..tets.len() as u32).collect(),
            tets,
            edge_tets,
            bisected: HashMap::new(),
            midpoint_of: Vec::new(),
        }
    }

    /// The total order the propagation climbs: squared length, then the
    /// ends' rest positions (lexicographically, smaller end first), then
    /// their indices (only for coincident vertices). Ties broken by
    /// positions, not indices, make the refinement a function of the
    /// geometry alone: a tetrahedron is always bisected at the same edge,
    /// whatever the numbering, so two refinements of one mesh for regions
    /// that overlap give the same tetrahedra inside the overlap (what lets a
    /// refinement that follows a tool change only where the tool has moved).
    fn compare(&self, x: Edge, y: Edge) -> std::cmp::Ordering {
        let ends = |e: Edge| {
            let (a, b) = (self.positions[e.0 as usize], self.positions[e.1 as usize]);
            if lex(a, b).is_le() { (a, b) } else { (b, a) }
        };
        let (x0, x1) = ends(x);
        let (y0, y1) = ends(y);
        (x0.distance_squared(x1).total_cmp(&y0.distance_squared(y1)))
            .then_with(|| lex(x0, y0))
            .then_with(|| lex(x1, y1))
            .then(x.cmp(&y))
    }

    fn longest(&self, t: u32) -> Edge {
        let tet = self.tets[t as usize];
        super::TET_EDGES
            .iter()
            .map(|&[a, b]| edge(tet[a], tet[b]))
            .max_by(|&x, &y| self.compare(x, y))
            .expect("six edges")
    }

    fn points(&self, t: u32) -> [Vec3; 4] {
        self.tets[t as usize].map(|v| self.positions[v as usize])
    }

    /// Bisects `e` along its propagation path: every tetrahedron holding
    /// `e` first has its own longer longest edge bisected, so each split is
    /// of a longest edge. Returns false when the budget would be passed
    /// (nothing half done: every bisection made is complete).
    fn refine_edge(&mut self, e: Edge, max_tets: usize, made: &mut Vec<u32>) -> bool {
        let mut path = vec![e];
        while let Some(&e) = path.last() {
            let Some(holders) = self.edge_tets.get(&e) else {
                path.pop(); // bisected on the way
                continue;
            };
            if let Some(longer) = holders.iter().map(|&t| self.longest(t)).find(|&l| l != e) {
                path.push(longer);
                continue;
            }
            if self.tets.len() + holders.len() > max_tets {
                return false;
            }
            self.bisect(e, made);
            path.pop();
        }
        true
    }

    /// Splits every tetrahedron holding `e` at its midpoint.
    fn bisect(&mut self, e: Edge, made: &mut Vec<u32>) {
        let holders = self.edge_tets.remove(&e).expect("a live edge");
        let m = self.positions.len() as u32;
        let (pa, pb) = (self.positions[e.0 as usize], self.positions[e.1 as usize]);
        self.positions.push((pa + pb) * 0.5);
        self.midpoint_of.push([e.0, e.1]);
        self.bisected.insert(e, (m, self.bisected.len() as u32));
        for t in holders {
            let tet = self.tets[t as usize];
            for [a, b] in super::TET_EDGES {
                let k = edge(tet[a], tet[b]);
                if k != e
                    && let Some(list) = self.edge_tets.get_mut(&k)
                {
                    list.retain(|&x| x != t);
                }
            }
            // Replacing one end of the edge by its midpoint keeps the
            // orientation: each child is the parent with one vertex moved
            // half-way along an edge (half the volume, same sign).
            let ia = tet.iter().position(|&v| v == e.0).expect("holds e");
            let ib = tet.iter().position(|&v| v == e.1).expect("holds e");
            let mut near_a = tet;
            near_a[ib] = m;
            let mut near_b = tet;
            near_b[ia] = m;
            let u = self.tets.len() as u32;
            self.tets[t as usize] = near_a;
            self.tets.push(near_b);
            self.parent.push(self.parent[t as usize]);
            for (child, verts) in [(t, near_a), (u, near_b)] {
                for [a, b] in super::TET_EDGES {
                    self.edge_tets
                        .entry(edge(verts[a], verts[b]))
                        .or_default()
                        .push(child);
                }
            }
            made.push(t);
            made.push(u);
        }
    }
}

/// A tetrahedron's cell size: the edge of the cube that six tetrahedra of
/// its volume fill, (6 V)^(1/3). The generators' `cell_m` is exactly this
/// for their tetrahedra (six to a cube, on either lattice), so a region
/// refined to `cell_m` has the cells of a mesh generated with it; each
/// bisection divides it by 2^(1/3).
pub fn cell_size_m(p: &[Vec3; 4]) -> Real {
    (6.0 * crate::math::tet_signed_volume(p[0], p[1], p[2], p[3]).abs()).cbrt()
}

/// Refines `mesh` until every tetrahedron for which `target_m` gives a cell
/// size has its [`cell_size_m`] no larger than it (tetrahedra for which it
/// gives `None` are split only as conformity requires), or until the mesh
/// would pass `max_tets` tetrahedra (then [`Refined::stopped_at_budget`]).
///
/// `target_m` sees the input tetrahedron a tetrahedron lies in and its four
/// corners, so regions can be any shape or follow the input's tags. The output is conforming, every tetrahedron positively oriented.
pub fn refine(
    mesh: &TetMesh,
    max_tets: usize,
    target_m: impl Fn(TetId, &[Vec3; 4]) -> Option<Real>,
) -> Result<Refined, RefineError> {
    let mut b = Bisector::new(mesh);
    let mut queue: Vec<u32> = (0..b.tets.len() as u32).rev().collect();
    let mut made = Vec::new();
    let mut stopped_at_budget = false;
    'work: while let Some(t) = queue.pop() {
        let Some(h) = target_m(TetId(b.parent[t as usize]), &b.points(t)) else {
            continue;
        };
        if !(h.is_finite() && h > 0.0) {
            return Err(RefineError::BadCell(h));
        }
        if cell_size_m(&b.points(t)) <= h {
            continue;
        }
        let e = b.longest(t);
        made.clear();
        if !b.refine_edge(e, max_tets, &mut made) {
            stopped_at_budget = true;
            break 'work;
        }
        // The tetrahedron at `t` is now a child; it and every tetrahedron
        // made on the way are looked at again.
        queue.extend(made.iter().copied());
    }
    let mesh = TetMesh::new(b.positions, b.tets)?;
    debug_assert_eq!(mesh.reoriented(), 0, "bisection keeps orientation");
    Ok(Refined {
        mesh,
        parent_tet: b.parent,
        midpoint_of: b.midpoint_of,
        bisected: b.bisected,
        stopped_at_budget,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::tet_signed_volume;
    use crate::mesh::quality::quality_report;
    use crate::mesh::{BoxSpec, CellSize, TET_FACES};

    /// The mesh's reason is said once: in the message, not again as a
    /// separate cause (anyhow's "Caused by" repeated it).
    #[test]
    fn an_invalid_mesh_is_said_once() {
        let mesh_error = TetMesh::new(Vec::new(), vec![[0, 1, 2, 3]]).unwrap_err();
        let reason = mesh_error.to_string();
        let e = RefineError::from(mesh_error);
        assert!(e.to_string().contains(&reason), "{e}");
        assert!(std::error::Error::source(&e).is_none());
    }

    fn cube(size_m: Real, cell_m: Real) -> TetMesh {
        BoxSpec::new(Vec3::splat(size_m), CellSize::EdgeM(cell_m))
            .generate()
            .unwrap()
    }

    /// Each face as sorted vertices, with how many tetrahedra hold it, and
    /// the boundary faces (held once) in their outward orientation.
    fn faces(mesh: &TetMesh) -> (HashMap<[u32; 3], usize>, Vec<[u32; 3]>) {
        let mut count: HashMap<[u32; 3], usize> = HashMap::new();
        let mut oriented: HashMap<[u32; 3], [u32; 3]> = HashMap::new();
        for tet in mesh.tets() {
            for f in TET_FACES {
                let tri = f.map(|k| tet[k].0);
                let mut key = tri;
                key.sort_unstable();
                *count.entry(key).or_default() += 1;
                oriented.insert(key, tri);
            }
        }
        let boundary = (count.iter())
            .filter(|(_, n)| **n == 1)
            .map(|(k, _)| oriented[k])
            .collect();
        (count, boundary)
    }

    fn area(mesh: &TetMesh, tris: &[[u32; 3]]) -> Real {
        let p = mesh.positions_m();
        (tris.iter())
            .map(|t| {
                let [a, b, c] = t.map(|v| p[v as usize]);
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }

    fn volume(mesh: &TetMesh) -> Real {
        (0..mesh.tet_count())
            .map(|t| {
                let p = mesh.tet_points(crate::ids::TetId::from(t));
                tet_signed_volume(p[0], p[1], p[2], p[3])
            })
            .sum()
    }

    fn longest_m(p: &[Vec3; 4]) -> Real {
        (super::super::TET_EDGES.iter())
            .map(|[a, b]| p[*a].distance(p[*b]))
            .fold(0.0, Real::max)
    }

    fn sphere(c: Vec3, r: Real, h: Real) -> impl Fn(TetId, &[Vec3; 4]) -> Option<Real> {
        move |_, p: &[Vec3; 4]| p.iter().any(|x| x.distance(c) <= r).then_some(h)
    }

    #[test]
    fn a_refined_region_is_conforming_oriented_and_fills_the_same_volume() {
        let mesh = cube(0.02, 0.005);
        let c = Vec3::new(0.01, 0.01, 0.02);
        let r = refine(&mesh, 1_000_000, sphere(c, 0.006, 0.00125)).unwrap();
        let fine = &r.mesh;
        assert!(
            fine.tet_count() > 4 * mesh.tet_count(),
            "{}",
            fine.tet_count()
        );
        assert_eq!(fine.reoriented(), 0);
        assert!(!r.stopped_at_budget);
        // Every face held by one or two tetrahedra, and the boundary exactly
        // the cube's surface: a hanging vertex would leave a crack inside,
        // faces held once that add to the boundary's area.
        let (count, boundary) = faces(fine);
        assert!(count.values().all(|&n| n <= 2));
        let (_, coarse_boundary) = faces(&mesh);
        let (a, a0) = (area(fine, &boundary), area(&mesh, &coarse_boundary));
        assert!((a - a0).abs() < 1e-12 * a0, "boundary {a} m^2 against {a0}");
        assert!((volume(fine) - 0.02f64.powi(3)).abs() < 1e-15);
        assert!((0..fine.tet_count()).all(|t| {
            let p = fine.tet_points(crate::ids::TetId::from(t));
            tet_signed_volume(p[0], p[1], p[2], p[3]) > 0.0
        }));
        // Every tetrahedron touching the sphere reached the target; far
        // from it the cells are the input's.
        for t in 0..fine.tet_count() {
            let p = fine.tet_points(crate::ids::TetId::from(t));
            if p.iter().any(|x| x.distance(c) <= 0.006) {
                assert!(
                    cell_size_m(&p) <= 0.00125 + 1e-15,
                    "tet {t}: {}",
                    cell_size_m(&p)
                );
                // Bisection of the generator's shapes keeps a cell's
                // longest edge within its cube's diagonal.
                assert!(longest_m(&p) <= 0.00125 * 3f64.sqrt() + 1e-15);
            }
        }
        let far = Vec3::new(0.0, 0.0, 0.0);
        let untouched = (0..mesh.tet_count())
            .filter(|&t| {
                let p = mesh.tet_points(crate::ids::TetId::from(t));
                p.iter().all(|x| x.distance(far) < 0.006)
            })
            .count();
        let kept = (0..fine.tet_count())
            .filter(|&t| {
                let p = fine.tet_points(crate::ids::TetId::from(t));
                p.iter().all(|x| x.distance(far) < 0.006)
            })
            .count();
        assert_eq!(kept, untouched, "the far corner was refined");
    }

    #[test]
    fn bisection_keeps_the_elements_shapes_and_the_input_vertices() {
        let mesh = cube(0.02, 0.005);
        let r = refine(&mesh, 1_000_000, sphere(Vec3::splat(0.01), 0.004, 0.0006)).unwrap();
        let (q0, q) = (quality_report(&mesh), quality_report(&r.mesh));
        // Longest-edge bisection makes a bounded set of shapes: the worst
        // dihedral angle may fall, but not towards a sliver.
        assert!(
            q.min_dihedral_deg >= 0.5 * q0.min_dihedral_deg,
            "min dihedral {} deg from {}",
            q.min_dihedral_deg,
            q0.min_dihedral_deg
        );
        assert!(q.max_aspect_ratio <= 3.0 * q0.max_aspect_ratio);
        let n0 = mesh.vertex_count();
        assert_eq!(&r.mesh.positions_m()[..n0], mesh.positions_m());
        assert_eq!(r.midpoint_of.len(), r.mesh.vertex_count() - n0);
        for (k, [a, b]) in r.midpoint_of.iter().enumerate() {
            let p = r.mesh.positions_m();
            let m = (p[*a as usize] + p[*b as usize]) * 0.5;
            assert_eq!(p[n0 + k], m);
        }
        // Children lie in their parents: a child's centroid is inside.
        for t in 0..r.mesh.tet_count() {
            let p = r.mesh.tet_points(crate::ids::TetId::from(t));
            let c = (p[0] + p[1] + p[2] + p[3]) / 4.0;
            let q = mesh.tet_points(crate::ids::TetId::from(r.parent_tet[t] as usize));
            let v = |a, b, c, d| tet_signed_volume(a, b, c, d);
            let sub = v(c, q[1], q[2], q[3]).abs()
                + v(q[0], c, q[2], q[3]).abs()
                + v(q[0], q[1], c, q[3]).abs()
                + v(q[0], q[1], q[2], c).abs();
            assert!((sub - v(q[0], q[1], q[2], q[3])).abs() < 1e-12 * sub);
        }
    }

    #[test]
    fn split_triangles_tile_the_refined_boundary() {
        let mesh = cube(0.02, 0.005);
        let r = refine(
            &mesh,
            1_000_000,
            sphere(Vec3::new(0.0, 0.01, 0.01), 0.005, 0.001),
        )
        .unwrap();
        let (_, coarse) = faces(&mesh);
        let mut split: Vec<[u32; 3]> = coarse.iter().flat_map(|t| r.split_triangle(*t)).collect();
        let (_, mut fine) = faces(&r.mesh);
        // Same triangles with the same orientation (rotations aside).
        let canon = |t: &[u32; 3]| {
            let k = (0..3).min_by_key(|&k| t[k]).unwrap();
            [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
        };
        split = split.iter().map(canon).collect();
        fine = fine.iter().map(canon).collect();
        split.sort_unstable();
        fine.sort_unstable();
        assert!(split.len() > coarse.len());
        assert_eq!(split, fine);
    }

    #[test]
    fn a_budget_stops_the_refinement_conforming() {
        let mesh = cube(0.02, 0.005);
        let budget = 3 * mesh.tet_count();
        let r = refine(&mesh, budget, sphere(Vec3::splat(0.01), 0.02, 0.0002)).unwrap();
        assert!(r.stopped_at_budget);
        assert!(r.mesh.tet_count() <= budget);
        let (count, boundary) = faces(&r.mesh);
        assert!(count.values().all(|&n| n <= 2));
        let (_, coarse) = faces(&mesh);
        let (a, a0) = (area(&r.mesh, &boundary), area(&mesh, &coarse));
        assert!((a - a0).abs() < 1e-12 * a0);
    }

    #[test]
    fn the_same_input_gives_the_same_mesh_and_bad_sizes_are_refused() {
        let mesh = cube(0.01, 0.005);
        let target = sphere(Vec3::splat(0.005), 0.003, 0.001);
        let (a, b) = (
            refine(&mesh, 100_000, &target).unwrap(),
            refine(&mesh, 100_000, &target).unwrap(),
        );
        assert_eq!(a.mesh.tets(), b.mesh.tets());
        assert_eq!(a.mesh.positions_m(), b.mesh.positions_m());
        for bad in [0.0, -1.0, Real::NAN, Real::INFINITY] {
            assert!(matches!(
                refine(&mesh, 100, |_, _| Some(bad)),
                Err(RefineError::BadCell(_))
            ));
        }
        // Nothing asked: the mesh as it was.
        let same = refine(&mesh, 100, |_, _| None).unwrap();
        assert_eq!(same.mesh.tets(), mesh.tets());
    }
}
