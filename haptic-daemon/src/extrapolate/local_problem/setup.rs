//! Setting a [`LocalProblem`] from a sample's problem: the checks, the
//! points, S = W^-1 from W's Cholesky factor, the forces at the sample.

use super::dense::{cholesky, cholesky_inverse};
use super::{
    Capsule, LocalContactMsg, LocalProblem, LocalProblemError, MAX_PARTS, MAX_POINTS, MAX_VERTICES,
    Point, TRUST_OF_RADIUS,
};
use crate::math::{V3, ZERO};

impl LocalProblem {
    /// Sets the problem a message carries (see [`LocalProblem::set`]).
    pub fn set_from_wire(&mut self, msg: &LocalContactMsg) -> Result<(), LocalProblemError> {
        self.ready = false;
        let (nv, np, nc) = (
            msg.vertex_count as usize,
            msg.point_count as usize,
            msg.part_count as usize,
        );
        if nv > MAX_VERTICES || np > MAX_POINTS || nc > MAX_PARTS {
            return Err(LocalProblemError::TooLarge {
                vertices: nv,
                points: np,
                parts: nc,
            });
        }
        self.set(
            msg.tool_position_m,
            &msg.parts[..nc],
            &msg.positions_m[..nv],
            &msg.points[..np],
            &msg.compliance_m_per_n[..9 * nv * nv],
        )?;
        self.seq = msg.seq;
        self.t_ns = msg.t_ns;
        // The tool's first position is the problem's own.
        self.track.keep(msg.t_ns, msg.tool_position_m);
        Ok(())
    }

    /// Sets the problem of a sample: the tool at `tool_m`, its `parts`,
    /// the vertices at `positions_m`, the `points`, and the compliance
    /// `w` (m/N, row-major 3V x 3V). On an error the problem is cleared.
    pub fn set(
        &mut self,
        tool_m: V3,
        parts: &[Capsule],
        positions_m: &[V3],
        points: &[Point],
        w: &[f64],
    ) -> Result<(), LocalProblemError> {
        self.ready = false;
        let (nv, np) = (positions_m.len(), points.len());
        if nv > MAX_VERTICES || np > MAX_POINTS || parts.len() > MAX_PARTS {
            return Err(LocalProblemError::TooLarge {
                vertices: nv,
                points: np,
                parts: parts.len(),
            });
        }
        let n = 3 * nv;
        if w.len() != n * n {
            return Err(LocalProblemError::Malformed("compliance size"));
        }
        let finite = |v: &V3| v.iter().all(|x| x.is_finite());
        if !finite(&tool_m)
            || !positions_m.iter().all(finite)
            || !w.iter().all(|x| x.is_finite())
            || !parts
                .iter()
                .all(|p| finite(&p.a_m) && finite(&p.b_m) && p.radius_m > 0.0 && p.onset_m > 0.0)
        {
            return Err(LocalProblemError::Malformed("a value is not finite"));
        }
        for p in points {
            if p.slots.iter().any(|s| *s as usize >= nv)
                || p.part as usize >= parts.len()
                || !(p.stiffness_n_per_m >= 0.0 && p.stiffness_n_per_m.is_finite())
                || !p.weights.iter().all(|w| w.is_finite())
            {
                return Err(LocalProblemError::Malformed("a point"));
            }
        }
        self.tool_m = tool_m;
        self.parts[..parts.len()].copy_from_slice(parts);
        self.part_count = parts.len();
        self.max_move_m = parts
            .iter()
            .map(|p| p.radius_m)
            .fold(f64::INFINITY, f64::min)
            * TRUST_OF_RADIUS;
        self.base = None;
        self.track = super::ToolTrack::default();
        self.history.clear();
        self.seq = 0;
        self.t_ns = 0;
        self.x.clear();
        self.x.extend_from_slice(positions_m);
        self.points.clear();
        self.points.extend_from_slice(points);
        // S = W^-1 from W's Cholesky factor.
        self.w.clear();
        self.w.extend_from_slice(w);
        self.scratch.tslot.clear();
        self.scratch.tslot.resize(nv, u16::MAX);
        self.scratch.tverts.clear();
        self.scratch.w_factor.clear();
        self.scratch.w_factor.extend_from_slice(w);
        if !cholesky(&mut self.scratch.w_factor, n) {
            return Err(LocalProblemError::NotDefinite);
        }
        cholesky_inverse(&self.scratch.w_factor, &mut self.scratch.m, &mut self.s, n);
        self.delta.clear();
        self.delta.resize(n, 0.0);
        self.f0.clear();
        self.f0.resize(n, 0.0);
        self.selection.active.clear();
        self.selection.active.extend(0..points.len() as u16);
        self.selection.selected = false;
        let mut f0 = std::mem::take(&mut self.f0);
        self.tool_force0_n = self.evaluate(&self.delta, ZERO, &mut f0, None).1;
        self.f0 = f0;
        self.f0_eff.clear();
        self.f0_eff.extend_from_slice(&self.f0);
        // Quasi-static until set_inertia.
        self.inertia.m_red.clear();
        // No surface near the tool: nothing to solve (the caller's
        // fallback renders the sample).
        self.ready = n > 0 && !points.is_empty();
        Ok(())
    }
}
