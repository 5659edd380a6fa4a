//! Phase 1a of a tool's update under the penalty law: a proxy that is
//! catching up (coming in from its fulcrum after a let-go, following a
//! pose that jumped) slows down near the tissue, so a still hand feels its
//! tool come back at the entry speed instead of a blow at the speed limit
//! (see [`crate::contact::tool::proxy`]).
//!
//! Ahead of the proxy the tissue is found as the tips' surface test finds
//! it ([`crate::contact::surface::crossing`]: the first surface triangle
//! the tip's centre line would enter), over the distance the proxy needs
//! to slow down; the step is then taken again no faster than lets the
//! proxy slow to the hand's speed plus the entry speed by the time its tip
//! reaches the surface. A tip already touching takes that speed at once.

use super::ToolContact;
use crate::backend::Backend;
use crate::contact::ToolKind;
use crate::contact::config::ContactLaw;
use crate::contact::instrument::ToolPose;
use crate::contact::surface::adjacency::Adjacency;
use crate::contact::surface::crossing::Crossing;
use crate::contact::surface::index::SurfaceIndex;
use crate::math::{Real, Vec3};

/// A proxy that followed the hand this recently (s) is not slowed: it
/// left the hand only for a moment (a pose that jumped away and back), and
/// comes back to the contact it left as before the entry speed. Slowed, a
/// 5 ms jump of 1 m kept the force below half for 56 ms instead of 9 (a
/// client without the daemon's pose check). A proxy coming in from its
/// fulcrum after a let-go has not followed the hand since.
pub(in crate::contact) const RECENTLY_FOLLOWING_S: Real = 0.1;

impl ToolContact {
    /// Keeps the time the proxy has been catching up, after this step's
    /// placing (of `dt_s`).
    pub(in crate::contact) fn note_catching_up(&mut self, dt_s: Real) {
        self.catching_up_s = if self.proxy.catching_up() {
            self.catching_up_s + dt_s
        } else {
            0.0
        };
    }

    /// Whether [`ToolContact::approach`] may slow the proxy this step
    /// (after [`ToolContact::note_catching_up`]): it has been catching up
    /// ([`crate::contact::tool::proxy::Proxy::catching_up`]: a proxy following
    /// the hand never is) for longer than [`RECENTLY_FOLLOWING_S`], faster
    /// than it may near the tissue. Not for the cavitron (it burns its way
    /// where the hand takes it) nor jaws holding tissue (they carry it
    /// along).
    pub(in crate::contact) fn approach_due(&self) -> bool {
        self.catching_up_s > RECENTLY_FOLLOWING_S
            && self.pose.is_some()
            && self.law == ContactLaw::Penalty
            && self.decl.kind != ToolKind::Cavitron
            && !self.gripping
            && self.proxy.speed_m_s() > self.proxy.near_tissue_speed_m_s()
    }

    /// Phase 1a (when [`ToolContact::approach_due`]): the step is taken
    /// again slower if the tip touched the tissue at the last step
    /// (`touching`, the tissue then pushing the tool with `out_n`) and
    /// moves into it, or if the surface is within the proxy's braking
    /// distance ahead. `index` must be refitted to the current positions
    /// unless `touching`. A tool leaving the tissue is not held back: a
    /// hand that left must not feel the tissue it left.
    pub(in crate::contact) fn approach<B: Backend + ?Sized>(
        &mut self,
        sim: &B,
        index: &SurfaceIndex,
        adj: &Adjacency,
        crossing: &mut Crossing,
        touching: Option<Vec3>,
    ) {
        let Some(pose) = self.pose else { return };
        let from = self.step_start_m();
        let step_m = from.distance(pose.end_m);
        let distance_m = if let Some(out_n) = touching {
            if (pose.end_m - from).dot(out_n) > 0.0 {
                return;
            }
            0.0
        } else {
            let dir = (pose.end_m - from).normalize_or_zero();
            // This step, the next, the braking and the tip's radius.
            let r = self.decl.radius_m;
            let look_m = self.proxy.braking_distance_m() + 2.0 * step_m + r;
            let Some(s) = crossing.first_entry(sim, index, adj, from, from + dir * look_m) else {
                return;
            };
            s * look_m - r - step_m
        };
        let limit_m_s = self.proxy.approach_speed_m_s(distance_m);
        if self.proxy.speed_m_s() <= limit_m_s {
            return;
        }
        let at = self.proxy.slow_to(limit_m_s, sim.dt_s());
        self.slowed = true;
        let pose = ToolPose::new(&self.decl, at, self.direction);
        self.direction = pose.direction;
        self.pose = Some(pose);
    }
}
