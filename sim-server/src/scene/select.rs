//! Selections (box, sphere, physical tag of tetrahedra or of surface
//! triangles) of vertices and tetrahedra, and the tetrahedra a vessel
//! segment crosses.

use super::spec::Selection;
use super::{SceneError, SceneSource};
use crate::ids::{TetId, VertexId};
use crate::math::{Real, Vec3};
use crate::mesh::{TET_FACES, TetMesh};
use toml::Spanned;

/// The physical tags a mesh file gave.
#[derive(Clone, Debug, Default)]
pub struct Tags {
    /// Per tetrahedron (0: none).
    pub tets: Vec<i32>,
    /// The tagged surface triangles (Gmsh physical surfaces, medit
    /// triangle references, tagged VTK triangles) and their tags.
    pub surface: Vec<([VertexId; 3], i32)>,
}

/// A checked selection.
#[derive(Clone, Copy, Debug)]
pub enum Region {
    /// Axis-aligned box (min, max).
    Box(Vec3, Vec3),
    /// Sphere (centre, radius).
    Sphere(Vec3, Real),
    /// Physical tag of tetrahedra.
    Physical(i32),
    /// Physical tag of surface triangles (vertices only).
    Surface(i32),
}

impl Region {
    /// Checks that exactly one key is given and the values make sense.
    pub fn new(src: &SceneSource, sel: &Spanned<Selection>) -> Result<Self, SceneError> {
        let s = sel.get_ref();
        let given = s.box_m.is_some() as u8
            + s.sphere_m.is_some() as u8
            + s.physical.is_some() as u8
            + s.surface_physical.is_some() as u8;
        if given != 1 {
            return Err(src.error(
                sel.span(),
                "`select` needs exactly one of box_m, sphere_m, physical, surface_physical",
            ));
        }
        if let Some(tag) = s.surface_physical {
            return Ok(Region::Surface(tag));
        }
        if let Some([a, b]) = s.box_m {
            let (a, b) = (Vec3::from_array(a), Vec3::from_array(b));
            if !(a.is_finite() && b.is_finite()) || a.cmpgt(b).any() {
                return Err(src.error(
                    sel.span(),
                    "box_m must be [[x0, y0, z0], [x1, y1, z1]] with x0 <= x1, y0 <= y1, z0 <= z1",
                ));
            }
            return Ok(Region::Box(a, b));
        }
        if let Some([x, y, z, r]) = s.sphere_m {
            let c = Vec3::new(x, y, z);
            if !(c.is_finite() && r.is_finite() && r > 0.0) {
                return Err(src.error(sel.span(), "sphere_m must be [cx, cy, cz, r] with r > 0"));
            }
            return Ok(Region::Sphere(c, r));
        }
        Ok(Region::Physical(s.physical.expect("one key is given")))
    }

    /// [`Region::new`] for a selection of tetrahedra (a region, the
    /// hybrid's part): a surface tag selects vertices only, and is refused.
    pub fn for_tets(src: &SceneSource, sel: &Spanned<Selection>) -> Result<Self, SceneError> {
        match Self::new(src, sel)? {
            Region::Surface(_) => Err(src.error(
                sel.span(),
                "surface_physical selects the vertices of a surface ([[fixed]], [[load]]); tetrahedra are selected by box_m, sphere_m or physical",
            )),
            r => Ok(r),
        }
    }

    fn contains(&self, p: Vec3) -> bool {
        match *self {
            Region::Box(a, b) => p.cmpge(a).all() && p.cmple(b).all(),
            Region::Sphere(c, r) => p.distance_squared(c) <= r * r,
            Region::Physical(_) | Region::Surface(_) => false,
        }
    }

    /// Tetrahedra selected: by centroid, or by physical tag (none by a
    /// surface tag: see [`Region::for_tets`]).
    pub fn tets(&self, mesh: &TetMesh, tags: &Tags) -> Vec<TetId> {
        (0..mesh.tet_count())
            .map(TetId::from)
            .filter(|t| match *self {
                Region::Physical(tag) => tags.tets.get(t.idx()) == Some(&tag),
                Region::Surface(_) => false,
                _ => {
                    let p = mesh.tet_points(*t);
                    self.contains((p[0] + p[1] + p[2] + p[3]) / 4.0)
                }
            })
            .collect()
    }

    /// Vertices selected: by rest position, belonging to a tetrahedron of
    /// the tag, or to a surface triangle of the surface tag.
    pub fn vertices(&self, mesh: &TetMesh, tags: &Tags) -> Vec<VertexId> {
        let mut hit = vec![false; mesh.vertex_count()];
        match *self {
            Region::Physical(_) => {
                for t in self.tets(mesh, tags) {
                    for v in mesh.tets()[t.idx()] {
                        hit[v.idx()] = true;
                    }
                }
            }
            Region::Surface(tag) => {
                for (tri, _) in tags.surface.iter().filter(|(_, t)| *t == tag) {
                    for v in tri {
                        hit[v.idx()] = true;
                    }
                }
            }
            _ => {
                for (v, p) in mesh.positions_m().iter().enumerate() {
                    hit[v] = self.contains(*p);
                }
                // Vertices no tetrahedron uses are never selected.
                let mut used = vec![false; hit.len()];
                for t in mesh.tets() {
                    for v in t {
                        used[v.idx()] = true;
                    }
                }
                for (h, u) in hit.iter_mut().zip(used) {
                    *h &= u;
                }
            }
        }
        (0..hit.len())
            .filter(|&v| hit[v])
            .map(VertexId::from)
            .collect()
    }
}

/// Whether segment (a, b) passes through tetrahedron `p` (positively
/// oriented): clip the segment by the four face half-spaces.
pub fn segment_crosses_tet(a: Vec3, b: Vec3, p: [Vec3; 4]) -> bool {
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    let d = b - a;
    for f in TET_FACES {
        let n = (p[f[1]] - p[f[0]]).cross(p[f[2]] - p[f[0]]); // outward
        // inside: n.(a + s d - p_f0) <= 0  <=>  s (n.d) <= n.(p_f0 - a)
        let (nd, rhs) = (n.dot(d), n.dot(p[f[0]] - a));
        if nd.abs() < 1e-300 {
            if rhs < 0.0 {
                return false;
            }
        } else if nd > 0.0 {
            hi = hi.min(rhs / nd);
        } else {
            lo = lo.max(rhs / nd);
        }
        if lo > hi {
            return false;
        }
    }
    true
}

/// Distance from `x` to segment (a, b).
pub fn distance_to_segment(x: Vec3, a: Vec3, b: Vec3) -> Real {
    let d = b - a;
    let s = if d.length_squared() > 0.0 {
        ((x - a).dot(d) / d.length_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    x.distance(a + d * s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_tet_crossing() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        assert!(segment_crosses_tet(
            Vec3::new(0.1, 0.1, -1.0),
            Vec3::new(0.1, 0.1, 1.0),
            p
        ));
        assert!(!segment_crosses_tet(
            Vec3::new(0.9, 0.9, -1.0),
            Vec3::new(0.9, 0.9, 1.0),
            p
        ));
        assert!(!segment_crosses_tet(
            Vec3::new(0.1, 0.1, -1.0),
            Vec3::new(0.1, 0.1, -0.5),
            p
        ));
        // A segment entirely inside.
        assert!(segment_crosses_tet(Vec3::splat(0.1), Vec3::splat(0.2), p));
        assert!(
            (distance_to_segment(Vec3::new(0.0, 1.0, 0.0), Vec3::ZERO, Vec3::X) - 1.0).abs()
                < 1e-15
        );
        assert!(
            (distance_to_segment(Vec3::new(2.0, 0.0, 0.0), Vec3::ZERO, Vec3::X) - 1.0).abs()
                < 1e-15
        );
    }
}
