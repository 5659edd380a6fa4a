//! Carrying a per-vertex field (displacements, the previous state, any
//! P1 field) from one mesh of a body to another mesh of the same body:
//! what a refinement that follows the tools needs when it swaps meshes
//! while the tissue is deformed.
//!
//! A vertex of the new mesh at the rest position of a vertex of the old one
//! takes its value (vertices are matched by their rest positions, bit for
//! bit, so any renumbering between the two meshes is irrelevant: bisection
//! makes a midpoint from the same two ends the same way every time). Any
//! other vertex (a midpoint the old mesh did not have) takes the old
//! field's P1 interpolation at its rest position, in the old tetrahedron
//! holding it. So a field linear over the old elements is carried exactly
//! (refining loses nothing), a vertex the new mesh drops (coarsening) just
//! stops being carried, and refining back restores what the coarse mesh
//! had at its vertices (remove-then-restore).

use super::TetMesh;
use crate::ids::VertexId;
use crate::math::{Real, Vec3, tet_signed_volume};
use std::collections::HashMap;
use thiserror::Error;

/// Why a field cannot be carried from one mesh to another.
#[derive(Debug, Error, PartialEq)]
pub enum TransferError {
    /// A vertex of the new mesh lies in no tetrahedron of the old one: the
    /// two meshes are not of the same body.
    #[error(
        "vertex {vertex} of the new mesh (at {at_m:?} m) lies in no tetrahedron of the old mesh: the two meshes do not fill the same body"
    )]
    Outside {
        /// The new mesh's vertex.
        vertex: usize,
        /// Its rest position (m).
        at_m: [Real; 3],
    },
    /// Two vertices of the old mesh share a rest position, so a new vertex
    /// there cannot be matched to one of them.
    #[error(
        "vertices {first} and {second} of the old mesh share the rest position {at_m:?} m: a mesh with coincident vertices cannot follow the tools"
    )]
    Coincident {
        /// The first vertex.
        first: usize,
        /// The second.
        second: usize,
        /// Where (m).
        at_m: [Real; 3],
    },
}

/// Where one vertex of the new mesh takes its value from.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Source {
    /// The old mesh's vertex at the same rest position.
    Same(u32),
    /// The P1 interpolation in an old tetrahedron (its vertices, weights
    /// summing to one).
    Inside([u32; 4], [Real; 4]),
}

/// How every vertex of a new mesh takes its value from an old mesh of the
/// same body.
#[derive(Clone, Debug)]
pub struct VertexTransfer {
    sources: Vec<Source>,
    old_count: usize,
}

/// A rest position as a hashable key (-0.0 and 0.0 alike).
fn key(p: Vec3) -> [u64; 3] {
    p.to_array().map(|c| (c + 0.0).to_bits())
}

/// The barycentric weights of `p` in the tetrahedron `q`.
fn weights(q: &[Vec3; 4], p: Vec3) -> [Real; 4] {
    let v = tet_signed_volume(q[0], q[1], q[2], q[3]);
    let w = [
        tet_signed_volume(p, q[1], q[2], q[3]),
        tet_signed_volume(q[0], p, q[2], q[3]),
        tet_signed_volume(q[0], q[1], p, q[3]),
        tet_signed_volume(q[0], q[1], q[2], p),
    ];
    w.map(|x| x / v)
}

/// Tolerance on a barycentric weight for a point on an old element's
/// boundary (round-off of the midpoints' coordinates).
const ON_FACE: Real = 1e-9;

/// The old mesh's tetrahedra binned on a uniform grid by bounding box, for
/// locating the few new vertices the old mesh does not have.
struct Bins {
    lo: Vec3,
    size_m: Real,
    dims: [usize; 3],
    start: Vec<u32>,
    tets: Vec<u32>,
}

impl Bins {
    fn new(mesh: &TetMesh) -> Self {
        let (lo, hi) = mesh.bounds_m();
        let n = mesh.tet_count().max(1);
        // About one tetrahedron's bounding box per bin, at most 2^21 bins.
        let extent = (hi - lo).max(Vec3::splat(1e-12));
        let size_m = ((extent.x * extent.y * extent.z) / n as Real)
            .cbrt()
            .max(extent.max_element() / 128.0);
        let dims = (extent / size_m)
            .to_array()
            .map(|d| (d as usize + 1).min(128));
        let cell = |p: Vec3| -> [usize; 3] {
            let c = ((p - lo) / size_m).to_array();
            [0, 1, 2].map(|k| (c[k].max(0.0) as usize).min(dims[k] - 1))
        };
        let flat = |c: [usize; 3]| (c[2] * dims[1] + c[1]) * dims[0] + c[0];
        let ranges: Vec<([usize; 3], [usize; 3])> = (0..mesh.tet_count())
            .map(|t| {
                let p = mesh.tet_points(crate::ids::TetId::from(t));
                let (a, b) = (
                    p.iter().fold(p[0], |m, x| m.min(*x)),
                    p.iter().fold(p[0], |m, x| m.max(*x)),
                );
                (cell(a), cell(b))
            })
            .collect();
        let mut count = vec![0u32; dims[0] * dims[1] * dims[2] + 1];
        let each = |r: &([usize; 3], [usize; 3]), f: &mut dyn FnMut(usize)| {
            for z in r.0[2]..=r.1[2] {
                for y in r.0[1]..=r.1[1] {
                    for x in r.0[0]..=r.1[0] {
                        f(flat([x, y, z]));
                    }
                }
            }
        };
        for r in &ranges {
            each(r, &mut |b| count[b + 1] += 1);
        }
        for b in 1..count.len() {
            count[b] += count[b - 1];
        }
        let mut fill = count.clone();
        let mut tets = vec![0u32; *count.last().unwrap_or(&0) as usize];
        for (t, r) in ranges.iter().enumerate() {
            each(r, &mut |b| {
                tets[fill[b] as usize] = t as u32;
                fill[b] += 1;
            });
        }
        Self {
            lo,
            size_m,
            dims,
            start: count,
            tets,
        }
    }

    /// The old tetrahedron holding `p` (the one it is deepest in) and its
    /// weights, if any holds it.
    fn locate(&self, mesh: &TetMesh, p: Vec3) -> Option<(u32, [Real; 4])> {
        let c = ((p - self.lo) / self.size_m).to_array();
        let mut b = [0usize; 3];
        for k in 0..3 {
            if !(c[k] >= -ON_FACE && (c[k] as usize) <= self.dims[k]) {
                return None;
            }
            b[k] = (c[k].max(0.0) as usize).min(self.dims[k] - 1);
        }
        let flat = (b[2] * self.dims[1] + b[1]) * self.dims[0] + b[0];
        let (s, e) = (self.start[flat] as usize, self.start[flat + 1] as usize);
        self.tets[s..e]
            .iter()
            .map(|&t| {
                let w = weights(&mesh.tet_points(crate::ids::TetId(t)), p);
                (t, w)
            })
            .max_by(|a, b| {
                let m = |w: &[Real; 4]| w.iter().copied().fold(Real::INFINITY, Real::min);
                m(&a.1).total_cmp(&m(&b.1))
            })
            .filter(|(_, w)| w.iter().all(|x| *x >= -ON_FACE))
    }
}

impl VertexTransfer {
    /// How the vertices of `new` take their values from `old` (both meshes
    /// of one body at rest, in metres).
    pub fn new(old: &TetMesh, new: &TetMesh) -> Result<Self, TransferError> {
        let mut at: HashMap<[u64; 3], u32> = HashMap::with_capacity(old.vertex_count());
        for (v, p) in old.positions_m().iter().enumerate() {
            if let Some(first) = at.insert(key(*p), v as u32) {
                return Err(TransferError::Coincident {
                    first: first as usize,
                    second: v,
                    at_m: p.to_array(),
                });
            }
        }
        let mut bins = None;
        let sources = (new.positions_m().iter().enumerate())
            .map(|(v, p)| {
                if let Some(&o) = at.get(&key(*p)) {
                    return Ok(Source::Same(o));
                }
                let bins = bins.get_or_insert_with(|| Bins::new(old));
                let (t, w) = bins.locate(old, *p).ok_or(TransferError::Outside {
                    vertex: v,
                    at_m: p.to_array(),
                })?;
                let tet = old.tets()[t as usize].map(|x| x.0);
                Ok(Source::Inside(tet, w))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            sources,
            old_count: old.vertex_count(),
        })
    }

    /// The new mesh's vertex count.
    pub fn len(&self) -> usize {
        self.sources.len()
    }

    /// Whether the new mesh has no vertex.
    pub fn is_empty(&self) -> bool {
        self.sources.is_empty()
    }

    /// How many of the new mesh's vertices are old ones.
    pub fn matched(&self) -> usize {
        (self.sources.iter())
            .filter(|s| matches!(s, Source::Same(_)))
            .count()
    }

    /// The old vertex at the new vertex `v`'s rest position, if there is one.
    pub fn old_vertex(&self, v: VertexId) -> Option<VertexId> {
        match self.sources.get(v.idx()) {
            Some(Source::Same(o)) => Some(VertexId(*o)),
            _ => None,
        }
    }

    /// The new vertex at each old vertex's rest position (`None` where the
    /// new mesh dropped it).
    pub fn new_of_old(&self) -> Vec<Option<VertexId>> {
        let mut out = vec![None; self.old_count];
        for (v, s) in self.sources.iter().enumerate() {
            if let Source::Same(o) = s {
                out[*o as usize] = Some(VertexId::from(v));
            }
        }
        out
    }

    /// The field `old` (one value per old vertex) on the new mesh's vertices.
    ///
    /// # Panics
    /// If `old` has fewer values than the old mesh has vertices.
    pub fn carry(&self, old: &[Vec3]) -> Vec<Vec3> {
        assert!(old.len() >= self.old_count, "one value per old vertex");
        (self.sources.iter())
            .map(|s| match *s {
                Source::Same(o) => old[o as usize],
                Source::Inside(tet, w) => (0..4).map(|k| old[tet[k] as usize] * w[k]).sum(),
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::refine::refine;
    use crate::mesh::{BoxSpec, CellSize};

    fn cube() -> TetMesh {
        BoxSpec::new(Vec3::new(0.04, 0.02, 0.02), CellSize::EdgeM(0.005))
            .generate()
            .unwrap()
    }

    fn sphere(c: Vec3, r: Real, h: Real) -> impl Fn(crate::ids::TetId, &[Vec3; 4]) -> Option<Real> {
        move |_, p: &[Vec3; 4]| p.iter().any(|x| x.distance(c) <= r).then_some(h)
    }

    fn linear(p: Vec3) -> Vec3 {
        Vec3::new(
            0.3 * p.x - 0.1 * p.y + 0.002,
            0.05 * p.z + 0.2 * p.x,
            -0.4 * p.y + 0.1 * p.z - 0.001,
        )
    }

    #[test]
    fn a_linear_field_is_carried_exactly_both_ways() {
        let coarse = cube();
        let fine = refine(
            &coarse,
            1_000_000,
            sphere(Vec3::new(0.01, 0.01, 0.02), 0.006, 0.00125),
        )
        .unwrap()
        .mesh;
        let u0: Vec<Vec3> = coarse.positions_m().iter().map(|p| linear(*p)).collect();
        let up = VertexTransfer::new(&coarse, &fine).unwrap();
        assert_eq!(up.matched(), coarse.vertex_count());
        let u1 = up.carry(&u0);
        for (p, u) in fine.positions_m().iter().zip(&u1) {
            assert!((linear(*p) - *u).length() < 1e-15, "{p} {u}");
        }
        let down = VertexTransfer::new(&fine, &coarse).unwrap();
        assert_eq!(down.carry(&u1), u0);
    }

    /// A field that is not linear is changed by refining (interpolated),
    /// but refining and coarsening back gives the coarse values again, and
    /// moving the refined region (refine at A, then at B) keeps every value
    /// at the vertices both meshes share.
    #[test]
    fn remove_then_restore_and_moving_the_region_keep_shared_values() {
        let coarse = cube();
        let a = refine(
            &coarse,
            1_000_000,
            sphere(Vec3::new(0.012, 0.01, 0.02), 0.008, 0.00125),
        )
        .unwrap()
        .mesh;
        let b = refine(
            &coarse,
            1_000_000,
            sphere(Vec3::new(0.02, 0.01, 0.02), 0.008, 0.00125),
        )
        .unwrap()
        .mesh;
        let bumpy = |p: Vec3| Vec3::new((p.x * 400.0).sin(), (p.y * 300.0).cos(), p.z * p.x * 1e3);
        let ua: Vec<Vec3> = a.positions_m().iter().map(|p| bumpy(*p)).collect();
        let to_b = VertexTransfer::new(&a, &b).unwrap();
        let ub = to_b.carry(&ua);
        let mut shared = 0;
        for (v, u) in ub.iter().enumerate() {
            if let Some(o) = to_b.old_vertex(VertexId::from(v)) {
                assert_eq!(*u, ua[o.idx()]);
                shared += 1;
            }
        }
        assert!(shared > coarse.vertex_count(), "{shared}");
        let back = VertexTransfer::new(&b, &coarse).unwrap().carry(&ub);
        let direct = VertexTransfer::new(&a, &coarse).unwrap().carry(&ua);
        assert_eq!(back, direct);
    }

    /// The refinement breaks ties by position: two refinements for spheres
    /// that overlap make the same tetrahedra deep inside the overlap.
    #[test]
    fn overlapping_refinements_agree_inside_the_overlap() {
        let coarse = cube();
        let (ca, cb) = (Vec3::new(0.015, 0.01, 0.02), Vec3::new(0.025, 0.01, 0.02));
        let mid = (ca + cb) * 0.5;
        let inside = |m: &TetMesh| {
            let mut keys: Vec<[[u64; 3]; 4]> = (0..m.tet_count())
                .map(|t| m.tet_points(crate::ids::TetId::from(t)))
                .filter(|p| p.iter().all(|x| x.distance(mid) < 0.004))
                .map(|p| {
                    let mut k = p.map(key);
                    k.sort_unstable();
                    k
                })
                .collect();
            keys.sort_unstable();
            keys
        };
        let a = refine(&coarse, 1_000_000, sphere(ca, 0.01, 0.00125))
            .unwrap()
            .mesh;
        let b = refine(&coarse, 1_000_000, sphere(cb, 0.01, 0.00125))
            .unwrap()
            .mesh;
        let (ka, kb) = (inside(&a), inside(&b));
        assert!(ka.len() > 50, "{}", ka.len());
        assert_eq!(ka, kb);
    }

    #[test]
    fn meshes_of_different_bodies_and_coincident_vertices_are_refused() {
        let coarse = cube();
        let other = BoxSpec::new(Vec3::new(0.05, 0.02, 0.02), CellSize::EdgeM(0.005))
            .generate()
            .unwrap();
        assert!(matches!(
            VertexTransfer::new(&coarse, &other),
            Err(TransferError::Outside { .. })
        ));
        // Two tetrahedra touching at one point, each with its own vertex there.
        let p = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::Z,
            Vec3::X,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(1.0, 0.0, 1.0),
        ];
        let twice = TetMesh::new(p, vec![[0, 1, 2, 3], [4, 5, 6, 7]]).unwrap();
        assert_eq!(
            VertexTransfer::new(&twice, &coarse).unwrap_err(),
            TransferError::Coincident {
                first: 1,
                second: 4,
                at_m: [1.0, 0.0, 0.0]
            }
        );
    }
}
