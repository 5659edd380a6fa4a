//! Where a moving point first enters the tissue through its deformed
//! surface: what keeps a penalty tool's tip from passing through.
//!
//! The penalty field pushes each surface point away from the tool's centre
//! line, so it holds only while that line stays outside the tissue: once
//! the tip's centre is past the surface, the points it passed are pushed
//! the other way and the tool falls through (a 2.5 mm probe pressed slowly
//! into a 5 mm-cell box went through at 11 mm and 0.59 N: the surface had
//! wrapped the tip into a cone whose apex it slipped past). So the proxy's
//! tip centre moves along a path tested against the surface triangles at
//! their current positions, and stops short of the first one it would
//! enter (from the outer side of its outward normal): the tissue then
//! yields to the whole depth of the penalty (points at up to the radius),
//! and the proxy follows as far as the tissue gives way. This is the
//! constraint of a god-object (Zilles and Salisbury 1995) on the tip's
//! centre, with the tissue's compliance left to the penalty field.
//!
//! The test is the ray-triangle intersection of Moller and Trumbore (1997)
//! against the triangles of the surface vertices near the path (the
//! [`SurfaceIndex`] BVH, then [`SurfaceFaces`]), each triangle oriented
//! outwards by its tetrahedron's face order ([`crate::mesh::TET_FACES`]).

use crate::backend::Backend;
use crate::contact::instrument::Segment;
use crate::contact::surface::adjacency::Adjacency;
use crate::contact::surface::faces::SurfaceFaces;
use crate::contact::surface::index::SurfaceIndex;
use crate::ids::VertexId;
use crate::math::{Real, Vec3};
use crate::tensor_mass::ElasticModel;

/// Barycentric slack of the intersection test: a path through an edge or
/// a vertex hits the triangles on either side, never slips between them.
const EDGE_SLACK: Real = 1e-9;

/// Finds where a path first enters the tissue; holds its scratch.
pub(in crate::contact) struct Crossing {
    /// How far from the path a vertex of a crossed triangle can be (m):
    /// a triangle's longest rest edge, stretched up to twice (what the
    /// point sampler assumes too).
    reach_m: Real,
    /// The contact points' spacing (tool radii).
    spacing_of_radius: Real,
    faces: SurfaceFaces,
    candidates: Vec<VertexId>,
}

impl Crossing {
    /// Scratch for `model`'s surface, whose longest rest triangle edge is
    /// `longest_edge_m`, sampled by contact points every
    /// `spacing_of_radius` tool radii.
    pub(in crate::contact) fn new(
        model: &ElasticModel,
        longest_edge_m: Real,
        spacing_of_radius: Real,
    ) -> Self {
        Self {
            reach_m: 2.0 * longest_edge_m,
            spacing_of_radius,
            faces: SurfaceFaces::new(model),
            candidates: Vec::new(),
        }
    }

    /// The contact points' spacing (tool radii).
    pub(in crate::contact) fn spacing_of_radius(&self) -> Real {
        self.spacing_of_radius
    }

    /// The fraction of the way from `from_m` to `to_m` at which the path
    /// first enters the tissue through a live surface triangle (at the
    /// simulation's current positions), if it does. `index` must be
    /// refitted to those positions.
    pub(in crate::contact) fn first_entry<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        index: &SurfaceIndex,
        adj: &Adjacency,
        from_m: Vec3,
        to_m: Vec3,
    ) -> Option<Real> {
        let mut first: Option<Real> = None;
        self.each_crossing(sim, index, adj, from_m, to_m, |s, entering| {
            if entering {
                first = Some(first.map_or(s, |f: Real| f.min(s)));
            }
        });
        first
    }

    /// The last place (fraction of the way) where the path from `from_m`
    /// to `to_m` crosses the surface, if that crossing enters the tissue:
    /// then `to_m` is inside, just past that surface.
    pub(in crate::contact) fn inside_past<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        index: &SurfaceIndex,
        adj: &Adjacency,
        from_m: Vec3,
        to_m: Vec3,
    ) -> Option<Real> {
        let mut last: Option<(Real, bool)> = None;
        self.each_crossing(sim, index, adj, from_m, to_m, |s, entering| {
            if last.is_none_or(|(l, _)| s > l) {
                last = Some((s, entering));
            }
        });
        last.and_then(|(s, entering)| entering.then_some(s))
    }

    /// Calls `f(s, entering)` for each live surface triangle the path
    /// crosses, at fraction `s` of the way.
    fn each_crossing<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        index: &SurfaceIndex,
        adj: &Adjacency,
        from_m: Vec3,
        to_m: Vec3,
        mut f: impl FnMut(Real, bool),
    ) {
        let dir = to_m - from_m;
        if dir.length_squared() == 0.0 {
            return;
        }
        self.candidates.clear();
        let path = Segment {
            a_m: from_m,
            b_m: to_m,
        };
        index.candidates(&path, self.reach_m, &mut self.candidates);
        self.faces.begin();
        for ci in 0..self.candidates.len() {
            self.faces
                .around(sim.model(), adj, self.candidates[ci], |tri| {
                    let x = tri.map(|w| sim.position(w));
                    if let Some((s, entering)) = crossing(from_m, dir, &x) {
                        f(s, entering);
                    }
                });
        }
    }
}

/// Where (fraction of `dir`, in [0, 1]) the path `from + s dir` crosses
/// the triangle `x` (outward normal (x1 - x0) x (x2 - x0)), and whether it
/// enters the tissue there (moves against the outward normal).
fn crossing(from: Vec3, dir: Vec3, x: &[Vec3; 3]) -> Option<(Real, bool)> {
    let e1 = x[1] - x[0];
    let e2 = x[2] - x[0];
    let entering = dir.dot(e1.cross(e2)) < 0.0;
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let t = from - x[0];
    let u = t.dot(p) * inv;
    if !(-EDGE_SLACK..=1.0 + EDGE_SLACK).contains(&u) {
        return None;
    }
    let q = t.cross(e1);
    let v = dir.dot(q) * inv;
    if v < -EDGE_SLACK || u + v > 1.0 + EDGE_SLACK {
        return None;
    }
    let s = e2.dot(q) * inv;
    (0.0..=1.0).contains(&s).then_some((s, entering))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_path_crosses_a_triangle_entering_against_its_outward_normal() {
        // The triangle z = 0 with its outward normal +z.
        let tri = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let down = Vec3::new(0.0, 0.0, -2.0);
        let (s, entering) = crossing(Vec3::new(0.2, 0.2, 1.0), down, &tri).unwrap();
        assert!((s - 0.5).abs() < 1e-12 && entering);
        // Upwards through it: leaving.
        let (s, entering) = crossing(Vec3::new(0.2, 0.2, -1.0), -down, &tri).unwrap();
        assert!((s - 0.5).abs() < 1e-12 && !entering);
        // Beside it, short of it, parallel to it: no entry.
        assert!(crossing(Vec3::new(0.8, 0.8, 1.0), down, &tri).is_none());
        assert!(crossing(Vec3::new(0.2, 0.2, 3.0), down, &tri).is_none());
        assert!(crossing(Vec3::new(0.2, 0.2, 1.0), Vec3::X, &tri).is_none());
        // Through an edge: the triangle counts it.
        let (s, entering) = crossing(Vec3::new(0.5, 0.5, 1.0), down, &tri).unwrap();
        assert!((s - 0.5).abs() < 1e-12 && entering);
    }
}
