//! The Newton iterations of [`super::LocalProblem`]: the points near the
//! tool, the energy and its derivatives, the step (by the push-through
//! identity, a dense solve over the touched vertices only) and the line
//! search.

use super::dense::{cholesky, cholesky_solve, closest_on_segment, lu_solve, spring};
use super::{Block, LocalProblem, Point, RENDER_ITERATIONS, TOLERANCE_M, TOLERANCE_N};
use crate::math::{V3, ZERO, add, norm, scale, sub};

/// What a render may still spend: Newton iterations and, with a time
/// budget ([`LocalProblem::set_time_budget`]), time.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Budget {
    /// Newton iterations left in this render (bounds the RT thread's time).
    pub(super) left: usize,
    /// The most a render may take, and when this one started.
    pub(super) time: Option<std::time::Duration>,
    started: Option<std::time::Instant>,
}

impl Budget {
    /// A new solve's budgets: [`RENDER_ITERATIONS`] iterations and, if
    /// `timed` and a time budget is set, the clock started.
    pub(super) fn begin(&mut self, timed: bool) {
        self.left = RENDER_ITERATIONS;
        self.started = self
            .time
            .filter(|_| timed)
            .map(|_| std::time::Instant::now());
    }

    /// Whether this render's time budget is spent.
    pub(super) fn out_of_time(&self) -> bool {
        match (self.time, self.started) {
            (Some(b), Some(t0)) => t0.elapsed() >= b,
            _ => false,
        }
    }
}

/// The points that may touch in this solve, and the tool motion the
/// selection was made for.
#[derive(Debug)]
pub(super) struct Selection {
    /// Their indices.
    pub(super) active: Vec<u16>,
    /// Whether `active` is a selection with the normal slack, and the tool
    /// motion it was made for.
    pub(super) selected: bool,
    pub(super) selected_dx: V3,
}

impl Selection {
    /// None, with room for `points`.
    pub(super) fn with_capacity(points: usize) -> Self {
        Self {
            active: Vec::with_capacity(points),
            selected: false,
            selected_dx: ZERO,
        }
    }
}

impl Clone for Selection {
    fn clone(&self) -> Self {
        let mut out = Self::with_capacity(super::MAX_POINTS);
        out.clone_from(self);
        out
    }

    /// Into the existing allocation: a derived `clone_from` would replace
    /// `active` by a vector only as long as the source's, and the RT
    /// thread's next selection would grow it.
    fn clone_from(&mut self, o: &Self) {
        self.active.clone_from(&o.active);
        self.selected = o.selected;
        self.selected_dx = o.selected_dx;
    }
}

/// The Newton iterations' buffers (3V or (3V)^2, allocated once).
#[derive(Debug)]
pub(super) struct Scratch {
    /// Per vertex: its slot among the touched vertices T (u16::MAX: not
    /// touched), and T.
    pub(super) tslot: Vec<u16>,
    pub(super) tverts: Vec<u16>,
    /// The points' Hessian on T, I + G_T W_TT, W_TT gathered, W g, the
    /// T-sized solve.
    pub(super) gt: Vec<f64>,
    pub(super) m: Vec<f64>,
    pub(super) wtt: Vec<f64>,
    pub(super) z: Vec<f64>,
    pub(super) y: Vec<f64>,
    pub(super) grad: Vec<f64>,
    pub(super) step: Vec<f64>,
    pub(super) trial: Vec<f64>,
    /// S delta, S step, and S trial (kept so that no product with S is
    /// needed inside the iterations: S W = I gives S step cheaply).
    pub(super) sd: Vec<f64>,
    pub(super) sstep: Vec<f64>,
    pub(super) trial_sd: Vec<f64>,
    /// delta at the start of the solve.
    pub(super) start: Vec<f64>,
    /// Of `set`: W's Cholesky factor.
    pub(super) w_factor: Vec<f64>,
    pub(super) forces: Vec<f64>,
}

impl Scratch {
    /// The step's slope along the gradient, step . grad (negative: a
    /// descent direction).
    fn slope(&self) -> f64 {
        self.step.iter().zip(&self.grad).map(|(a, b)| a * b).sum()
    }

    /// Room for `vertices`.
    pub(super) fn with_capacity(vertices: usize) -> Self {
        let n = 3 * vertices;
        Self {
            tslot: Vec::with_capacity(vertices),
            tverts: Vec::with_capacity(vertices),
            gt: Vec::with_capacity(n * n),
            m: Vec::with_capacity(n * n),
            wtt: Vec::with_capacity(n * n),
            z: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            grad: Vec::with_capacity(n),
            step: Vec::with_capacity(n),
            trial: Vec::with_capacity(n),
            sd: Vec::with_capacity(n),
            sstep: Vec::with_capacity(n),
            trial_sd: Vec::with_capacity(n),
            start: Vec::with_capacity(n),
            w_factor: Vec::with_capacity(n * n),
            forces: Vec::with_capacity(n),
        }
    }

    /// Copies what a clone of the problem carries (into the existing
    /// allocations): the touched set, the factor and the last step; the
    /// iterations' own products (`gt`, `m`, `wtt`, `z`, `y`, `sd`, `sstep`,
    /// `trial_sd`) are rebuilt before they are read.
    pub(super) fn carry_from(&mut self, o: &Self) {
        self.tslot.clone_from(&o.tslot);
        self.tverts.clone_from(&o.tverts);
        self.grad.clone_from(&o.grad);
        self.w_factor.clone_from(&o.w_factor);
        self.step.clone_from(&o.step);
        self.trial.clone_from(&o.trial);
        self.forces.clone_from(&o.forces);
        self.start.clone_from(&o.start);
    }
}

impl LocalProblem {
    /// The active points: those within `slack_m` of touching the tool moved
    /// by `dx` at the current delta.
    pub(super) fn select(&mut self, dx: V3, slack_m: f64) {
        self.selection.active.clear();
        for (i, p) in self.points.iter().enumerate() {
            if self.gap_m(p, &self.delta, dx) < slack_m {
                self.selection.active.push(i as u16);
            }
        }
    }

    /// Whether a point outside the active ones touches the tool.
    pub(super) fn others_touch(&self, dx: V3) -> bool {
        let mut k = 0;
        for (i, p) in self.points.iter().enumerate() {
            if self.selection.active.get(k) == Some(&(i as u16)) {
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
        self.scratch.sd.clear();
        for row in self.s.chunks_exact(n) {
            self.scratch
                .sd
                .push(row.iter().zip(&self.delta).map(|(a, b)| a * b).sum());
        }
        let mut energy = self.energy(&self.delta, &self.scratch.sd, dx, forces);
        while self.budget.left > 0 {
            if self.budget.out_of_time() {
                self.budget.left = 0;
                break;
            }
            self.budget.left -= 1;
            self.iterated += 1;
            // Gradient S delta + f0 - f(delta).
            self.scratch.grad.clear();
            self.scratch.grad.extend(
                self.scratch
                    .sd
                    .iter()
                    .zip(&self.f0_eff)
                    .zip(forces.iter())
                    .map(|((s, f0), f)| s + f0 - f),
            );
            if self.scratch.grad.iter().all(|g| g.abs() < TOLERANCE_N) {
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
            let slope = self.scratch.slope();
            // Backtracking on Pi (Armijo).
            let mut alpha = 1.0;
            let mut accepted = false;
            for _ in 0..30 {
                self.scratch.trial.clear();
                self.scratch.trial.extend(
                    self.delta
                        .iter()
                        .zip(&self.scratch.step)
                        .map(|(d, s)| d + alpha * s),
                );
                self.scratch.trial_sd.clear();
                self.scratch.trial_sd.extend(
                    self.scratch
                        .sd
                        .iter()
                        .zip(&self.scratch.sstep)
                        .map(|(d, s)| d + alpha * s),
                );
                let (trial, trial_sd) = (
                    std::mem::take(&mut self.scratch.trial),
                    std::mem::take(&mut self.scratch.trial_sd),
                );
                let e = self.energy(&trial, &trial_sd, dx, forces);
                (self.scratch.trial, self.scratch.trial_sd) = (trial, trial_sd);
                if e <= energy + 1e-4 * alpha * slope || slope >= 0.0 || slope.is_nan() {
                    energy = e;
                    accepted = true;
                    break;
                }
                alpha *= 0.5;
            }
            if !accepted {
                // No descent left: a minimum to rounding.
                self.energy(&self.delta, &self.scratch.sd, dx, forces);
                self.converged = true;
                return true;
            }
            std::mem::swap(&mut self.delta, &mut self.scratch.trial);
            std::mem::swap(&mut self.scratch.sd, &mut self.scratch.trial_sd);
            let moved = self.scratch.step.iter().fold(0.0f64, |m, s| m.max(s.abs())) * alpha;
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
        let slope = self.scratch.slope();
        slope < 0.0 && self.scratch.step.iter().all(|x| x.is_finite())
    }

    /// Before a step: T, z = W g, step = -z, S step = -g and the points'
    /// Hessian G_T (3|T| square, in `gt`); returns 3|T|.
    pub(super) fn prepare_step(&mut self, dx: V3, forces: &mut [f64], springs_only: bool) -> usize {
        let n = self.delta.len();
        // T.
        for v in self.scratch.tverts.drain(..) {
            self.scratch.tslot[v as usize] = u16::MAX;
        }
        for &i in &self.selection.active {
            let p = &self.points[i as usize];
            if self.gap_m(p, &self.delta, dx) < 0.0 {
                for &v in &p.slots {
                    if self.scratch.tslot[v as usize] == u16::MAX {
                        self.scratch.tslot[v as usize] = self.scratch.tverts.len() as u16;
                        self.scratch.tverts.push(v);
                    }
                }
            }
        }
        let t = 3 * self.scratch.tverts.len();
        // z = W g.
        self.scratch.z.clear();
        for row in self.w.chunks_exact(n) {
            self.scratch
                .z
                .push(row.iter().zip(&self.scratch.grad).map(|(a, b)| a * b).sum());
        }
        self.scratch.step.clear();
        self.scratch.step.extend(self.scratch.z.iter().map(|z| -z));
        // S step = -g + P_T^T y (S W = I).
        self.scratch.sstep.clear();
        self.scratch
            .sstep
            .extend(self.scratch.grad.iter().map(|g| -g));
        if t > 0 {
            self.scratch.gt.clear();
            self.scratch.gt.resize(t * t, 0.0);
            let mut gt = std::mem::take(&mut self.scratch.gt);
            self.evaluate(
                &self.delta,
                dx,
                forces,
                Some(Block {
                    h: &mut gt,
                    springs_only,
                    slot: &self.scratch.tslot,
                    size: t,
                }),
            );
            self.scratch.gt = gt;
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
        self.scratch.wtt.clear();
        for k in 0..t {
            let r = dof(k, &self.scratch.tverts) * n;
            self.scratch
                .wtt
                .extend((0..t).map(|l| self.w[r + dof(l, &self.scratch.tverts)]));
        }
        self.scratch.m.clear();
        self.scratch.m.resize(t * t, 0.0);
        self.scratch.y.clear();
        for k in 0..t {
            let row = &self.scratch.gt[k * t..(k + 1) * t];
            let out = &mut self.scratch.m[k * t..(k + 1) * t];
            let mut yk = 0.0;
            for (l, &g) in row.iter().enumerate() {
                if g == 0.0 {
                    continue;
                }
                yk += g * self.scratch.z[dof(l, &self.scratch.tverts)];
                for (o, w) in out.iter_mut().zip(&self.scratch.wtt[l * t..(l + 1) * t]) {
                    *o += g * w;
                }
            }
            out[k] += 1.0;
            self.scratch.y.push(yk);
        }
        if !lu_solve(&mut self.scratch.m, &mut self.scratch.y, t) {
            return false;
        }
        for k in 0..t {
            self.scratch.sstep[dof(k, &self.scratch.tverts)] += self.scratch.y[k];
        }
        // step = -z + W_:T y.
        for (r, out) in self.scratch.step.iter_mut().enumerate() {
            let row = &self.w[r * n..(r + 1) * n];
            *out += (0..t)
                .map(|k| row[dof(k, &self.scratch.tverts)] * self.scratch.y[k])
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
        self.scratch.m.clear();
        self.scratch.m.extend_from_slice(&self.s);
        for k in 0..t {
            let r = dof(k, &self.scratch.tverts) * n;
            for l in 0..t {
                self.scratch.m[r + dof(l, &self.scratch.tverts)] += self.scratch.gt[k * t + l];
            }
        }
        if !cholesky(&mut self.scratch.m, n) {
            return false;
        }
        self.scratch.step.clear();
        self.scratch
            .step
            .extend(self.scratch.grad.iter().map(|g| -g));
        cholesky_solve(&self.scratch.m, &mut self.scratch.step, n);
        // S step = -g - G step (H step = -g).
        for k in 0..t {
            let row = &self.scratch.gt[k * t..(k + 1) * t];
            let gs: f64 = row
                .iter()
                .enumerate()
                .map(|(l, g)| g * self.scratch.step[dof(l, &self.scratch.tverts)])
                .sum();
            self.scratch.sstep[dof(k, &self.scratch.tverts)] -= gs;
        }
        true
    }

    /// Scales the step so that no vertex moves more than the trust
    /// region: a long step could carry surface points through the capsule
    /// to its far side (where the penalty pushes them on: another, wrong,
    /// equilibrium).
    pub(super) fn trust_region(&mut self) {
        let longest = self
            .scratch
            .step
            .chunks_exact(3)
            .map(|s| norm([s[0], s[1], s[2]]))
            .fold(0.0f64, f64::max);
        if longest > self.max_move_m {
            let k = self.max_move_m / longest;
            self.scratch.step.iter_mut().for_each(|s| *s *= k);
            self.scratch.sstep.iter_mut().for_each(|s| *s *= k);
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
        for &i in &self.selection.active {
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
