//! Tool geometry: the shaft and tip segments of a posed tool, capsule
//! distances, and the contact planes vertices are projected on.

use super::ToolDecl;
use crate::math::{Real, Vec3};

/// Below this fulcrum-to-tip distance (m) the shaft direction is undefined
/// and the previous one is kept.
const MIN_REACH_M: Real = 1e-9;

/// A segment from `a_m` to `b_m`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// One end (m).
    pub a_m: Vec3,
    /// The other end (m).
    pub b_m: Vec3,
}

impl Segment {
    /// The larger of the two ends' distances to `other`'s (m): no point of
    /// one segment is further than this from the other (the Hausdorff
    /// distance between two segments is at most their ends' displacement).
    pub fn end_shift_m(&self, other: &Segment) -> Real {
        self.a_m
            .distance(other.a_m)
            .max(self.b_m.distance(other.b_m))
    }

    /// A cheap rejection before [`Segment::distance_m`]: false when `x_m`
    /// is outside the segment's bounding box grown by `r_m` (then it is
    /// certainly farther than `r_m`).
    #[inline]
    pub fn might_touch(&self, x_m: Vec3, r_m: Real) -> bool {
        let lo = self.a_m.min(self.b_m) - Vec3::splat(r_m);
        let hi = self.a_m.max(self.b_m) + Vec3::splat(r_m);
        x_m.cmpge(lo).all() && x_m.cmple(hi).all()
    }

    /// Distance from `x_m` to the segment (m).
    pub fn distance_m(&self, x_m: Vec3) -> Real {
        x_m.distance(self.closest_m(x_m).0)
    }

    /// The point of the segment closest to `x_m` (m) and its parameter
    /// along the segment (0 at `a_m`, 1 at `b_m`).
    pub fn closest_m(&self, x_m: Vec3) -> (Vec3, Real) {
        let d = self.b_m - self.a_m;
        let len2 = d.length_squared();
        let t = if len2 > 0.0 {
            ((x_m - self.a_m).dot(d) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (self.a_m + d * t, t)
    }
}

/// A tool placed by its tip: the shaft runs from the fulcrum through the tip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToolPose {
    /// Unit shaft direction T, from the fulcrum towards the tip.
    pub direction: Vec3,
    /// The tool end (m): the requested tip, pulled back to `length_m` from
    /// the fulcrum if it was further (the tool cannot be longer than itself).
    pub end_m: Vec3,
    /// The last `tip_length_m` of the inserted part (from its start to the end).
    pub tip: Segment,
    /// The inserted shaft before the tip (fulcrum to tip start), if the tool
    /// is inserted deeper than its tip.
    pub shaft: Option<Segment>,
    /// Radius of both (m).
    pub radius_m: Real,
}

impl ToolPose {
    /// Places `decl` with its tip at `tip_m`; `previous_direction` is used
    /// when the tip sits on the fulcrum.
    pub fn new(decl: &ToolDecl, tip_m: Vec3, previous_direction: Vec3) -> Self {
        let fulcrum = Vec3::from_array(decl.fulcrum_m);
        let reach = tip_m - fulcrum;
        let len = reach.length();
        let direction = if len > MIN_REACH_M {
            reach / len
        } else {
            previous_direction
        };
        let inserted = len.min(decl.length_m);
        let end_m = fulcrum + direction * inserted;
        let tip_len = decl.tip_length_m.min(inserted);
        let tip_start = end_m - direction * tip_len;
        let shaft = (inserted > decl.tip_length_m).then_some(Segment {
            a_m: fulcrum,
            b_m: tip_start,
        });
        Self {
            direction,
            end_m,
            tip: Segment {
                a_m: tip_start,
                b_m: end_m,
            },
            shaft,
            radius_m: decl.radius_m,
        }
    }
}

/// A plane through `point_m` with unit normal `normal` (pointing out of the
/// tissue, towards the tool).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    /// A point of the plane (m).
    pub point_m: Vec3,
    /// Unit normal.
    pub normal: Vec3,
}

impl Plane {
    /// The plane of normal `normal` tangent to the capsule (`segment`,
    /// `radius_m`) on the tissue side (-normal): every point of the capsule
    /// has a height >= 0 above it, so a vertex put on it is outside the tool.
    pub fn tangent(segment: &Segment, radius_m: Real, normal: Vec3) -> Self {
        let low = if segment.a_m.dot(normal) <= segment.b_m.dot(normal) {
            segment.a_m
        } else {
            segment.b_m
        };
        Self {
            point_m: low - normal * radius_m,
            normal,
        }
    }

    /// Signed height (m) of `x_m` above the plane (positive on the tool side).
    pub fn height_m(&self, x_m: Vec3) -> Real {
        (x_m - self.point_m).dot(self.normal)
    }

    /// The orthogonal projection of `x_m` on the plane.
    pub fn project(&self, x_m: Vec3) -> Vec3 {
        x_m - self.normal * self.height_m(x_m)
    }

    /// Distance (m), within the plane, from the projection of `x_m` to the
    /// projection of `segment`: at most the radius when `x_m` lies in the
    /// tool's footprint (its shadow along the normal).
    pub fn footprint_distance_m(&self, x_m: Vec3, segment: &Segment) -> Real {
        Segment {
            a_m: self.project(segment.a_m),
            b_m: self.project(segment.b_m),
        }
        .distance_m(self.project(x_m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::ToolKind;

    fn decl() -> ToolDecl {
        ToolDecl {
            name: "t".into(),
            kind: ToolKind::Hook,
            fulcrum_m: [0.0, 0.0, 0.1],
            length_m: 0.2,
            radius_m: 0.002,
            tip_length_m: 0.01,
            friction: Default::default(),
        }
    }

    #[test]
    fn pose_splits_shaft_and_tip_and_clamps_to_length() {
        let p = ToolPose::new(&decl(), Vec3::new(0.0, 0.0, 0.0), Vec3::NEG_Z);
        assert!((p.direction - Vec3::NEG_Z).length() < 1e-15);
        assert!((p.tip.a_m - Vec3::new(0.0, 0.0, 0.01)).length() < 1e-15);
        assert_eq!(p.shaft.unwrap().a_m, Vec3::new(0.0, 0.0, 0.1));
        let far = ToolPose::new(&decl(), Vec3::new(0.0, 0.0, -1.0), Vec3::NEG_Z);
        assert!((far.end_m - Vec3::new(0.0, 0.0, -0.1)).length() < 1e-15);
        let shallow = ToolPose::new(&decl(), Vec3::new(0.0, 0.0, 0.095), Vec3::NEG_Z);
        assert!(shallow.shaft.is_none());
    }

    #[test]
    fn tangent_plane_touches_the_capsule_from_below() {
        let s = Segment {
            a_m: Vec3::new(0.0, 0.0, 1.0),
            b_m: Vec3::ZERO,
        };
        let n = Vec3::new(0.3, 0.0, 1.0).normalize();
        let plane = Plane::tangent(&s, 0.5, n);
        // The closest capsule point is on the plane, the segment is r above it.
        assert!((plane.height_m(Vec3::ZERO) - 0.5).abs() < 1e-15);
        assert!(plane.height_m(s.a_m) > 0.5);
        let x = plane.project(Vec3::new(2.0, 1.0, 3.0));
        assert!(plane.height_m(x).abs() < 1e-14);
        assert!(s.distance_m(x) >= 0.5 - 1e-14);
    }
}
