//! The Newton iterations of [`super::LocalProblem`]: the points near the
//! tool, the energy and its derivatives, the step (by the push-through
//! identity, a dense solve over the touched vertices only) and the line
//! search.

use super::dense::{cholesky, cholesky_solve, closest_on_segment, lu_solve, spring};
use super::{Block, LocalProblem, Point, TOLERANCE_M, TOLERANCE_N};
use crate::math::{V3, ZERO, add, norm, scale, sub};

impl LocalProblem {
    /// The active points: those within `slack_m` of touching the tool moved
    /// by `dx` at the current delta.
    pub(super) fn select(&mut self, dx: V3, slack_m: f64) {
        self.active.clear();
        for (i, p) in self.points.iter().enumerate() {
            if self.gap_m(p, &self.delta, dx) < slack_m {
                self.active.push(i as u16);
            }
        }
    }

    /// Whether a point outside the active ones touches the tool.
    pub(super) fn others_touch(&self, dx: V3) -> bool {
        let mut k = 0;
        for (i, p) in self.points.iter().enumerate() {
            if self.active.get(k) == Some(&(i as u16)) {
                k += 1;
                continue;
            }
            if self.gap_m(p, &self.delta, dx) < 0.0 {
                return true;
            }
        }
        false
    }

    /// Point `p`'s gap to its capsule (m; negative: penetrating).
    pub(super) fn gap_m(&self, p: &Point, delta: &[f64], dx: V3) -> f64 {
        let y = self.point_position(p, delta);
        let c = &self.parts[p.part as usize];
        let (closest, _) = closest_on_segment(add(c.a_m, dx), add(c.b_m, dx), y);
        norm(sub(y, closest)) - c.radius_m
    }

    /// Point `p`'s position with the vertices moved by `delta` (m).
    pub(super) fn point_position(&self, p: &Point, delta: &[f64]) -> V3 {
        let mut y = ZERO;
        for k in 0..3 {
            let v = p.slots[k] as usize;
            let moved = [
                self.x[v][0] + delta[3 * v],
                self.x[v][1] + delta[3 * v + 1],
                self.x[v][2] + delta[3 * v + 2],
            ];
            y = add(y, scale(moved, p.weights[k]));
        }
        y
    }

    /// Newton down Pi over the active points from the current delta
    /// (warm start); false if no Hessian could be factored. Sets
    /// `converged` (false: the iteration or time budget ran out first) and
    /// `iterated` (the iterations taken).
    pub(super) fn newton(&mut self, dx: V3, forces: &mut [f64]) -> bool {
        let n = self.delta.len();
        self.converged = false;
        self.iterated = 0;
        // S delta once, exactly; then kept up to date with S step.
        self.sd.clear();
        for row in self.s.chunks_exact(n) {
            self.sd
                .push(row.iter().zip(&self.delta).map(|(a, b)| a * b).sum());
        }
        let mut energy = self.energy(&self.delta, &self.sd, dx, forces);
        while self.budget > 0 {
            if self.out_of_time() {
                self.budget = 0;
                break;
            }
            self.budget -= 1;
            self.iterated += 1;
            // Gradient S delta + f0 - f(delta).
            self.grad.clear();
            self.grad.extend(
                self.sd
                    .iter()
                    .zip(&self.f0_eff)
                    .zip(forces.iter())
                    .map(|((s, f0), f)| s + f0 - f),
            );
            if self.grad.iter().all(|g| g.abs() < TOLERANCE_N) {
                self.converged = true;
                break;
            }
            // The Newton step with the full Hessian, or where that is no
            // descent (a round tool dragging tissue sideways makes a
            // saddle) the springs' part alone, which always is.
            if !self.newton_step(dx, forces, false) && !self.newton_step(dx, forces, true) {
                return false;
            }
            self.trust_region();
            let slope: f64 = self.step.iter().zip(&self.grad).map(|(a, b)| a * b).sum();
            // Backtracking on Pi (Armijo).
            let mut alpha = 1.0;
            let mut accepted = false;
            for _ in 0..30 {
                self.trial.clear();
                self.trial.extend(
                    self.delta
                        .iter()
                        .zip(&self.step)
                        .map(|(d, s)| d + alpha * s),
                );
                self.trial_sd.clear();
                self.trial_sd
                    .extend(self.sd.iter().zip(&self.sstep).map(|(d, s)| d + alpha * s));
                let (trial, trial_sd) = (
                    std::mem::take(&mut self.trial),
                    std::mem::take(&mut self.trial_sd),
                );
                let e = self.energy(&trial, &trial_sd, dx, forces);
                (self.trial, self.trial_sd) = (trial, trial_sd);
                if e <= energy + 1e-4 * alpha * slope || slope >= 0.0 || slope.is_nan() {
                    energy = e;
                    accepted = true;
                    break;
                }
                alpha *= 0.5;
            }
            if !accepted {
                // No descent left: a minimum to rounding.
                self.energy(&self.delta, &self.sd, dx, forces);
                self.converged = true;
                return true;
            }
            std::mem::swap(&mut self.delta, &mut self.trial);
            std::mem::swap(&mut self.sd, &mut self.trial_sd);
            let moved = self.step.iter().fold(0.0f64, |m, s| m.max(s.abs())) * alpha;
            if moved < TOLERANCE_M {
                self.converged = true;
                break;
            }
        }
        true
    }

    /// The Newton step -H^-1 g into `step`, H = S + G with G the points'
    /// Hessian (the springs' part alone if asked), G nonzero only on the
    /// vertices T of the touching points: by the push-through identity
    /// H^-1 = (I - W_:T (I + G_T W_TT)^-1 G_T P) W, a solve of size 3|T|
    /// instead of 3|V|, or with at least half of V touched a Cholesky
    /// factorisation of H itself (cheaper then: measured on a deep live
    /// poke, the push-through's dense product and LU took most of a tick's
    /// render). False if it is not a descent direction (or the system is
    /// singular).
    pub(super) fn newton_step(&mut self, dx: V3, forces: &mut [f64], springs_only: bool) -> bool {
        let n = self.delta.len();
        let t = self.prepare_step(dx, forces, springs_only);
        if t > 0 {
            let solved = if 2 * t >= n {
                self.full_step(t)
            } else {
                self.pushed_through_step(t)
            };
            if !solved {
                return false;
            }
        }
        let slope: f64 = self.step.iter().zip(&self.grad).map(|(a, b)| a * b).sum();
        slope < 0.0 && self.step.iter().all(|x| x.is_finite())
    }

    /// Before a step: T, z = W g, step = -z, S step = -g and the points'
    /// Hessian G_T (3|T| square, in `gt`); returns 3|T|.
    pub(super) fn prepare_step(&mut self, dx: V3, forces: &mut [f64], springs_only: bool) -> usize {
        let n = self.delta.len();
        // T.
        for v in self.tverts.drain(..) {
            self.tslot[v as usize] = u16::MAX;
        }
        for &i in &self.active {
            let p = &self.points[i as usize];
            if self.gap_m(p, &self.delta, dx) < 0.0 {
                for &v in &p.slots {
                    if self.tslot[v as usize] == u16::MAX {
                        self.tslot[v as usize] = self.tverts.len() as u16;
                        self.tverts.push(v);
                    }
                }
            }
        }
        let t = 3 * self.tverts.len();
        // z = W g.
        self.z.clear();
        for row in self.w.chunks_exact(n) {
            self.z
                .push(row.iter().zip(&self.grad).map(|(a, b)| a * b).sum());
        }
        self.step.clear();
        self.step.extend(self.z.iter().map(|z| -z));
        // S step = -g + P_T^T y (S W = I).
        self.sstep.clear();
        self.sstep.extend(self.grad.iter().map(|g| -g));
        if t > 0 {
            self.gt.clear();
            self.gt.resize(t * t, 0.0);
            let mut gt = std::mem::take(&mut self.gt);
            self.evaluate(
                &self.delta,
                dx,
                forces,
                Some(Block {
                    h: &mut gt,
                    springs_only,
                    slot: &self.tslot,
                    size: t,
                }),
            );
            self.gt = gt;
        }
        t
    }

    /// The step by the push-through identity (few touched vertices): `y`
    /// = (I + G_T W_TT)^-1 G_T z_T, then S step += P_T^T y and step +=
    /// W_:T y. G_T is block-sparse (a point couples its triangle's
    /// vertices only): its product with W_TT (gathered contiguous first)
    /// skips its zeros.
    pub(super) fn pushed_through_step(&mut self, t: usize) -> bool {
        let n = self.delta.len();
        let dof = |k: usize, tv: &[u16]| 3 * tv[k / 3] as usize + k % 3;
        // W_TT, contiguous, in `m`'s place for the moment: then the sum.
        self.wtt.clear();
        for k in 0..t {
            let r = dof(k, &self.tverts) * n;
            self.wtt
                .extend((0..t).map(|l| self.w[r + dof(l, &self.tverts)]));
        }
        self.m.clear();
        self.m.resize(t * t, 0.0);
        self.y.clear();
        for k in 0..t {
            let row = &self.gt[k * t..(k + 1) * t];
            let out = &mut self.m[k * t..(k + 1) * t];
            let mut yk = 0.0;
            for (l, &g) in row.iter().enumerate() {
                if g == 0.0 {
                    continue;
                }
                yk += g * self.z[dof(l, &self.tverts)];
                for (o, w) in out.iter_mut().zip(&self.wtt[l * t..(l + 1) * t]) {
                    *o += g * w;
                }
            }
            out[k] += 1.0;
            self.y.push(yk);
        }
        if !lu_solve(&mut self.m, &mut self.y, t) {
            return false;
        }
        for k in 0..t {
            self.sstep[dof(k, &self.tverts)] += self.y[k];
        }
        // step = -z + W_:T y.
        for (r, out) in self.step.iter_mut().enumerate() {
            let row = &self.w[r * n..(r + 1) * n];
            *out += (0..t)
                .map(|k| row[dof(k, &self.tverts)] * self.y[k])
                .sum::<f64>();
        }
        true
    }

    /// The step by a Cholesky factorisation of H = S + G over all of V
    /// (most vertices touched: n^3/6 against the push-through's ~t^3
    /// LU and product), S step = -g - G step. False if H is not positive
    /// definite (the full Hessian at a saddle: the caller then takes the
    /// springs' part alone).
    pub(super) fn full_step(&mut self, t: usize) -> bool {
        let n = self.delta.len();
        let dof = |k: usize, tv: &[u16]| 3 * tv[k / 3] as usize + k % 3;
        self.m.clear();
        self.m.extend_from_slice(&self.s);
        for k in 0..t {
            let r = dof(k, &self.tverts) * n;
            for l in 0..t {
                self.m[r + dof(l, &self.tverts)] += self.gt[k * t + l];
            }
        }
        if !cholesky(&mut self.m, n) {
            return false;
        }
        self.step.clear();
        self.step.extend(self.grad.iter().map(|g| -g));
        cholesky_solve(&self.m, &mut self.step, n);
        // S step = -g - G step (H step = -g).
        for k in 0..t {
            let row = &self.gt[k * t..(k + 1) * t];
            let gs: f64 = row
                .iter()
                .enumerate()
                .map(|(l, g)| g * self.step[dof(l, &self.tverts)])
                .sum();
            self.sstep[dof(k, &self.tverts)] -= gs;
        }
        true
    }

    /// Scales the step so that no vertex moves more than the trust
    /// region: a long step could carry surface points through the capsule
    /// to its far side (where the penalty pushes them on: another, wrong,
    /// equilibrium).
    pub(super) fn trust_region(&mut self) {
        let longest = self
            .step
            .chunks_exact(3)
            .map(|s| norm([s[0], s[1], s[2]]))
            .fold(0.0f64, f64::max);
        if longest > self.max_move_m {
            let k = self.max_move_m / longest;
            self.step.iter_mut().for_each(|s| *s *= k);
            self.sstep.iter_mut().for_each(|s| *s *= k);
        }
    }

    /// Pi at `delta` (with `sd` = S delta) with the tool moved by `dx`;
    /// the forces on V into `forces`.
    pub(super) fn energy(&self, delta: &[f64], sd: &[f64], dx: V3, forces: &mut [f64]) -> f64 {
        let (e_contact, _, _) = self.evaluate(delta, dx, forces, None);
        delta
            .iter()
            .zip(sd)
            .zip(&self.f0_eff)
            .fold(e_contact, |e, ((d, s), f)| e + d * (0.5 * s + f))
    }

    /// The points' energy (J), force on the tool (N) and whether any
    /// touches it, with the vertices moved by `delta` and the tool by
    /// `dx`; their forces on V into `forces`; with `hess`, their Hessian
    /// added to it (the springs' part alone if asked).
    pub(super) fn evaluate(
        &self,
        delta: &[f64],
        dx: V3,
        forces: &mut [f64],
        mut hess: Option<Block<'_>>,
    ) -> (f64, V3, bool) {
        let mut touching = false;
        forces.iter_mut().for_each(|f| *f = 0.0);
        let mut energy = 0.0;
        let mut tool = ZERO;
        for &i in &self.active {
            let p = &self.points[i as usize];
            let y = self.point_position(p, delta);
            let c = &self.parts[p.part as usize];
            let (a, b) = (add(c.a_m, dx), add(c.b_m, dx));
            let (closest, interior) = closest_on_segment(a, b, y);
            let gap = sub(y, closest);
            let dist = norm(gap);
            let depth = c.radius_m - dist;
            if depth <= 0.0 || dist <= 1e-12 * c.radius_m {
                continue;
            }
            touching = true;
            let normal = scale(gap, 1.0 / dist);
            let (e, f, slope) = spring(p.stiffness_n_per_m, depth, c.onset_m);
            energy += e;
            tool = sub(tool, scale(normal, f));
            for k in 0..3 {
                let v = p.slots[k] as usize;
                for r in 0..3 {
                    forces[3 * v + r] += p.weights[k] * f * normal[r];
                }
            }
            let Some(block) = hess.as_mut() else {
                continue;
            };
            // The point's Hessian: slope n n^T - f/dist (I - n n^T - a a^T).
            let axis = {
                let d = sub(b, a);
                let l = norm(d);
                if interior && l > 0.0 {
                    scale(d, 1.0 / l)
                } else {
                    ZERO
                }
            };
            let mut g = [[0.0; 3]; 3];
            for (r, row) in g.iter_mut().enumerate() {
                for (col, x) in row.iter_mut().enumerate() {
                    let nn = normal[r] * normal[col];
                    *x = slope * nn;
                    if !block.springs_only {
                        let id = if r == col { 1.0 } else { 0.0 };
                        *x -= f / dist * (id - nn - axis[r] * axis[col]);
                    }
                }
            }
            let size = block.size;
            for (i, &vi) in p.slots.iter().enumerate() {
                for (j, &vj) in p.slots.iter().enumerate() {
                    let w = p.weights[i] * p.weights[j];
                    let (si, sj) = (
                        3 * block.slot[vi as usize] as usize,
                        3 * block.slot[vj as usize] as usize,
                    );
                    for (r, row) in g.iter().enumerate() {
                        for (col, x) in row.iter().enumerate() {
                            block.h[(si + r) * size + sj + col] += w * x;
                        }
                    }
                }
            }
        }
        (energy, tool, touching)
    }
}
