//! The contact field's evaluation at one sub-step, in two hops: the
//! points' geometry against the swept tool parts ([`ContactField::gauge`]),
//! then the forces they exert ([`ContactField::apply`]). A part of
//! [`super`], which owns the field and documents the law.

use super::friction::{Stick, along_surface};
use super::{
    Acting, CLEAR_MARGIN, CLEAR_MARGIN_M, ContactField, DAMPING_STABILITY, REPORT_WINDOW_S,
    SubStep, spring,
};
use crate::math::{Mat3, Real, Vec3, outer};

impl ContactField {
    /// The contact forces at `at` into `out` (see [`ContactField::add_forces`];
    /// `advance`: friction states move on).
    pub(super) fn evaluate(
        &mut self,
        rest_m: &[Vec3],
        u: &[[Real; 3]],
        u_prev: &[[Real; 3]],
        at: SubStep,
        advance: bool,
        out: &mut [[Real; 3]],
    ) {
        // Within the last REPORT_WINDOW_S (a sub-step's worth of slack for
        // rounding).
        let reported = (1.0 - at.s) * at.step_s <= (REPORT_WINDOW_S - 0.5 * at.h_s).max(0.0);
        if reported {
            self.evaluations += 1;
        }
        self.last_reported = reported;
        let most_damping = self.gauge(rest_m, u, u_prev, at, advance);
        self.apply(most_damping, at, advance, out);
    }

    /// Each point's gap, normal, Hessians and penetration rate against its
    /// tool part at `at` (what acts, in `acting`); returns the largest
    /// contact damping over a vertex's mass times the sub-step.
    fn gauge(
        &mut self,
        rest_m: &[Vec3],
        u: &[[Real; 3]],
        u_prev: &[[Real; 3]],
        at: SubStep,
        advance: bool,
    ) -> Real {
        let SubStep {
            h_s,
            step_s,
            s,
            masses_kg,
        } = at;
        if self.damping_sum.len() < masses_kg.len() {
            // Once, at the first contact.
            self.damping_sum.resize(masses_kg.len(), 0.0);
        }
        let alpha = self.damping_s_per_m;
        let damped = alpha > 0.0 && !masses_kg.is_empty();
        let mut most_damping: Real = 0.0;
        self.part_depth_m.fill(0.0);
        let count = self.points.len();
        let mut first = 0;
        while first < count {
            // One triangle's points facing one part (consecutive, as
            // selected): its corners are read once, and when its bounding
            // sphere is clear of the part's capsule none of its points can
            // touch (each lies within the sphere), which is most triangles
            // of a selection at most sub-steps.
            let head = self.points[first];
            let end = first
                + self.points[first..]
                    .iter()
                    .position(|p| p.vertices != head.vertices || p.part != head.part)
                    .unwrap_or(count - first);
            let run = first..end;
            first = end;
            let sweep = &self.parts[head.part as usize];
            let seg = sweep.at(s);
            let corners = head.vertices.map(|j| {
                let j = j as usize;
                rest_m[j] + Vec3::from_array(u[j])
            });
            let centre = (corners[0] + corners[1] + corners[2]) / 3.0;
            let extent = corners
                .iter()
                .map(|c| c.distance(centre))
                .fold(0.0, Real::max);
            if seg.distance_m(centre) - extent
                > sweep.radius_m * (1.0 + CLEAR_MARGIN) + CLEAR_MARGIN_M
            {
                for i in run {
                    self.acting[i] = None;
                    self.penetration_m[i] = 0.0;
                    if advance {
                        self.sticks[i] = Stick::default();
                    }
                }
                continue;
            }
            for i in run {
                let p = &self.points[i];
                self.acting[i] = None;
                let mut x = Vec3::ZERO;
                for (w, c) in p.weights.iter().zip(&corners) {
                    x += *w * *c;
                }
                let (c, t) = seg.closest_m(x);
                let gap = x - c;
                let dist = gap.length();
                let depth = sweep.radius_m - dist;
                if depth <= 0.0 || dist <= 1e-12 * sweep.radius_m {
                    self.penetration_m[i] = 0.0;
                    if advance {
                        // Out of contact: it sticks afresh when it comes back.
                        self.sticks[i] = Stick::default();
                    }
                    continue;
                }
                // The point's velocity only where it acts.
                let mut vel = Vec3::ZERO;
                for k in 0..3 {
                    let j = p.vertices[k] as usize;
                    let (uj, pj) = (Vec3::from_array(u[j]), Vec3::from_array(u_prev[j]));
                    vel += p.weights[k] * (uj - pj) / h_s;
                }
                self.penetration_m[i] = depth;
                let deepest = &mut self.part_depth_m[p.part as usize];
                *deepest = deepest.max(depth);
                let n = gap / dist;
                let turn = Mat3::IDENTITY - outer(n, n);
                let axis = (seg.b_m - seg.a_m).normalize_or_zero();
                let turn = if t > 0.0 && t < 1.0 {
                    turn - outer(axis, axis)
                } else {
                    turn
                };
                let (spring, slope) = spring(p.stiffness_n_per_m, depth, sweep.radius_m);
                self.spring_hessians[i] = outer(n, n) * slope;
                self.hessians[i] = self.spring_hessians[i] - turn * (spring / dist);
                let tool_vel = ((sweep.to.a_m - sweep.from.a_m)
                    + ((sweep.to.b_m - sweep.from.b_m) - (sweep.to.a_m - sweep.from.a_m)) * t)
                    / step_s;
                let rate = (tool_vel - vel).dot(n);
                self.acting[i] = Some(Acting {
                    n,
                    spring,
                    rate,
                    slip_m: (vel - tool_vel) * h_s,
                });
                if damped {
                    // Gershgorin row of the damping matrix (sum_p c_p w_vp w^T)
                    // over the mass, with c_p = alpha k_p d the point's linear
                    // damping coefficient.
                    for k in 0..3 {
                        let j = p.vertices[k] as usize;
                        let d = &mut self.damping_sum[j];
                        *d += p.weights[k] * alpha * spring;
                        if masses_kg[j] > 0.0 {
                            most_damping = most_damping.max(*d * h_s / masses_kg[j]);
                        }
                    }
                }
            }
        }
        most_damping
    }

    /// The acting points' Hunt-Crossley (and friction) forces spread to
    /// their vertices in `out`, the tools' reactions summed in the report
    /// window.
    fn apply(&mut self, most_damping: Real, at: SubStep, advance: bool, out: &mut [[Real; 3]]) {
        let h_s = at.h_s;
        let alpha = self.damping_s_per_m;
        let damped = alpha > 0.0 && !at.masses_kg.is_empty();
        let reported = self.last_reported;
        // The damping is explicit (backward-difference velocities): above
        // c h / m ~ 1 it overshoots every sub-step, and deep contacts then
        // locked into a period-2 oscillation (the tissue under the tool
        // flipping by +-0.6 N each sub-step, the mean over a step hiding
        // it). Scale it down to what the sub-step can integrate.
        let gamma = if most_damping > DAMPING_STABILITY {
            DAMPING_STABILITY / most_damping
        } else {
            1.0
        };
        for (i, p) in self.points.iter().enumerate() {
            let Some(Acting {
                n,
                spring,
                rate,
                slip_m,
            }) = self.acting[i]
            else {
                continue;
            };
            let factor = (1.0 + gamma * alpha * rate).clamp(0.0, 2.0);
            let f = spring * factor;
            let tool = self.parts[p.part as usize].tool;
            let mu = &self.friction[tool];
            // With friction, the tangential spring's force on the point.
            let mut tangential = Vec3::ZERO;
            if mu.is_active() {
                let k_t = p.stiffness_n_per_m;
                let stick = &mut self.sticks[i];
                tangential = if advance {
                    stick.advance(n, slip_m, spring, k_t, mu)
                } else {
                    stick.force_n(n, k_t)
                };
                if advance && damped && !stick.sliding {
                    // A sticking point's tangential spring is damped like
                    // the normal one (the same coefficient, so the bound
                    // above holds: the damping block is c I), within the
                    // static limit; undamped, it rang at the sub-step
                    // rate and the force depended on the sub-step count.
                    let c = gamma * alpha * spring;
                    tangential -= along_surface(slip_m, n) * (c / h_s);
                    tangential = tangential.clamp_length_max(mu.static_coefficient * spring);
                }
                if !stick.sliding {
                    // A sticking point resists tangential motion too.
                    let t = (Mat3::IDENTITY - outer(n, n)) * k_t;
                    self.spring_hessians[i] += t;
                    self.hessians[i] += t;
                }
            }
            for k in 0..3 {
                let j = p.vertices[k] as usize;
                if damped {
                    self.damping_sum[j] = 0.0;
                }
                let w = p.weights[k] * f;
                let wt = tangential * p.weights[k];
                let o = &mut out[j];
                o[0] += w * n.x + wt.x;
                o[1] += w * n.y + wt.y;
                o[2] += w * n.z + wt.z;
                self.dirty.push(p.vertices[k]);
            }
            if reported {
                self.force_sum_n[tool] -= n * f + tangential;
            }
        }
        // A vertex of several points is listed several times: harmless
        // (zeroing twice), and the list stays bounded by 3 x points.
    }
}
