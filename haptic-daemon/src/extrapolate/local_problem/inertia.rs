//! The tissue's inertia in a [`LocalProblem`]: the lumped masses the
//! simulation sends condensed on the problem's vertices (Guyan's
//! reduction, M = S G S with G = C^T M C and S = W^-1), each solve an
//! implicit Euler step of the condensed tissue from the vertices'
//! velocities at the sample (the first spanning the sample's age), and
//! the history of the problem's force that re-bases it on a newer sample.

use super::dense::{cholesky, cholesky_inverse};
use super::{HISTORY, LocalContactMsg, LocalProblem, LocalProblemError};
use crate::math::{V3, ZERO, add, scale, sub};

/// The tissue's inertia condensed on the problem's vertices (empty
/// `m_red`: quasi-static).
#[derive(Debug)]
pub(super) struct Inertia {
    /// The condensed mass M = S G S, row-major (3V)^2.
    pub(super) m_red: Vec<f64>,
    /// S + A(h) and its inverse for the haptic tick h (the problem's `s`
    /// and `w` hold those of the step under way: the first step's, which
    /// spans the sample's age, then these).
    pub(super) s_tick: Vec<f64>,
    pub(super) w_tick: Vec<f64>,
    /// The damping (1/s).
    pub(super) damping_per_s: f64,
    /// The step under way (s), whether it is the first, and the haptic
    /// tick (s).
    pub(super) step_s: f64,
    pub(super) first_step: bool,
    pub(super) tick_s: f64,
    /// The vertices' velocity, and delta before the step.
    pub(super) vel: Vec<f64>,
    pub(super) delta_prev: Vec<f64>,
}

impl Inertia {
    /// No inertia, with room for `n` coordinates.
    pub(super) fn with_capacity(n: usize) -> Self {
        Self {
            m_red: Vec::with_capacity(n * n),
            s_tick: Vec::with_capacity(n * n),
            w_tick: Vec::with_capacity(n * n),
            damping_per_s: 0.0,
            step_s: 0.0,
            first_step: false,
            tick_s: 0.0,
            vel: Vec::with_capacity(n),
            delta_prev: Vec::with_capacity(n),
        }
    }
}

impl Clone for Inertia {
    fn clone(&self) -> Self {
        let mut out = Self::with_capacity(self.vel.capacity());
        out.clone_from(self);
        out
    }

    /// Into the existing allocations.
    fn clone_from(&mut self, o: &Self) {
        self.m_red.clone_from(&o.m_red);
        self.s_tick.clone_from(&o.s_tick);
        self.w_tick.clone_from(&o.w_tick);
        self.damping_per_s = o.damping_per_s;
        self.step_s = o.step_s;
        self.first_step = o.first_step;
        self.tick_s = o.tick_s;
        self.vel.clone_from(&o.vel);
        self.delta_prev.clone_from(&o.delta_prev);
    }
}

/// With inertia: each tick's time (ns) and force change, oldest first from
/// `next` on (a ring of [`HISTORY`]), `len` filled.
#[derive(Clone, Copy, Debug)]
pub(super) struct ForceHistory {
    t_ns: [u64; HISTORY],
    change: [V3; HISTORY],
    len: usize,
    next: usize,
}

impl Default for ForceHistory {
    fn default() -> Self {
        Self {
            t_ns: [0; HISTORY],
            change: [ZERO; HISTORY],
            len: 0,
            next: 0,
        }
    }
}

impl ForceHistory {
    /// Forgets every tick.
    pub(super) fn clear(&mut self) {
        self.len = 0;
        self.next = 0;
    }

    /// Keeps a tick's force change.
    pub(super) fn remember(&mut self, now_ns: u64, change: V3) {
        self.t_ns[self.next] = now_ns;
        self.change[self.next] = change;
        self.next = (self.next + 1) % HISTORY;
        self.len = (self.len + 1).min(HISTORY);
    }

    /// The problem's force change at `t_ns`, for a problem taken at
    /// `problem_t_ns`: zero at its own step's time, each tick's after,
    /// linear in between, the newest past it; `None` when the ticks kept
    /// no longer reach back to it.
    pub(super) fn change_at(&self, t_ns: u64, problem_t_ns: u64) -> Option<V3> {
        let mut after: Option<(u64, V3)> = None;
        for k in 0..self.len {
            let i = (self.next + HISTORY - 1 - k) % HISTORY;
            let (t, c) = (self.t_ns[i], self.change[i]);
            if t <= t_ns {
                return Some(match after {
                    None => c,
                    Some((ta, ca)) => lerp(t, c, ta, ca, t_ns),
                });
            }
            after = Some((t, c));
        }
        // Before every tick kept: from the problem's own step (change
        // zero), if the ring still holds its first tick.
        if self.len == HISTORY {
            return None;
        }
        Some(match after {
            None => ZERO,
            Some((ta, ca)) if t_ns > problem_t_ns => lerp(problem_t_ns, ZERO, ta, ca, t_ns),
            Some(_) => ZERO,
        })
    }
}

impl LocalProblem {
    /// [`LocalProblem::set_inertia`] from the message the problem was set
    /// from ([`LocalProblem::set_from_wire`]); `Ok(false)` when it carries
    /// none (the problem stays quasi-static).
    pub fn set_inertia_from_wire(
        &mut self,
        msg: &LocalContactMsg,
        first_step_s: f64,
        tick_s: f64,
    ) -> Result<bool, LocalProblemError> {
        if msg.inertia == 0 || !self.is_ready() {
            return Ok(false);
        }
        let nv = (msg.vertex_count as usize).min(msg.velocities_m_per_s.len());
        self.set_inertia(
            &msg.column_mass[..9 * nv * nv],
            msg.damping_per_s,
            &msg.velocities_m_per_s[..nv],
            first_step_s,
            tick_s,
        )?;
        Ok(true)
    }

    /// Whether the problem carries the tissue's inertia.
    pub fn has_inertia(&self) -> bool {
        self.ready && !self.inertia.m_red.is_empty()
    }

    /// Gives the problem the tissue's inertia (after [`LocalProblem::set`]):
    /// `column_mass` G = C_V^T M C_V (the lumped masses seen through W's
    /// columns, row-major 3V square), mass-proportional `damping_per_s`,
    /// the vertices' velocities at the sample. Each solve is then one
    /// implicit Euler step of the condensed tissue (Guyan: mass S G S,
    /// stiffness S), the first spanning `first_step_s` (the sample's age
    /// when it is first rendered), each later one `tick_s`. The render then
    /// needs the sample the problem was taken with (a later one: `None`).
    pub fn set_inertia(
        &mut self,
        column_mass: &[f64],
        damping_per_s: f64,
        velocities_m_per_s: &[V3],
        first_step_s: f64,
        tick_s: f64,
    ) -> Result<(), LocalProblemError> {
        let n = self.delta.len();
        if column_mass.len() != n * n || velocities_m_per_s.len() * 3 != n {
            return Err(LocalProblemError::Malformed("inertia size"));
        }
        let valid = first_step_s > 0.0
            && tick_s > 0.0
            && damping_per_s >= 0.0
            && column_mass.iter().all(|x| x.is_finite())
            && velocities_m_per_s.iter().flatten().all(|x| x.is_finite());
        if !valid {
            return Err(LocalProblemError::Malformed("inertia value"));
        }
        // M = S G S (two dense products; on the set-up side). S G goes in
        // the factor's scratch (n^2, overwritten by `stepped` below).
        matmul_into(&self.s, column_mass, &mut self.scratch.w_factor, n);
        matmul_into(&self.scratch.w_factor, &self.s, &mut self.inertia.m_red, n);
        self.inertia.damping_per_s = damping_per_s;
        // The tick's S + A and inverse, then the first step's in s and w.
        let static_s = std::mem::take(&mut self.s);
        self.inertia.s_tick.clear();
        self.inertia.s_tick.extend_from_slice(&static_s);
        let mut s_tick = std::mem::take(&mut self.inertia.s_tick);
        let mut w_tick = std::mem::take(&mut self.inertia.w_tick);
        let ok = self.stepped(&mut s_tick, &mut w_tick, tick_s);
        (self.inertia.s_tick, self.inertia.w_tick) = (s_tick, w_tick);
        self.s = static_s;
        let mut s = std::mem::take(&mut self.s);
        let mut w = std::mem::take(&mut self.w);
        let ok = ok && self.stepped(&mut s, &mut w, first_step_s);
        (self.s, self.w) = (s, w);
        if !ok {
            self.ready = false;
            self.inertia.m_red.clear();
            return Err(LocalProblemError::NotDefinite);
        }
        self.inertia.step_s = first_step_s;
        self.inertia.first_step = true;
        self.inertia.tick_s = tick_s;
        self.inertia.vel.clear();
        self.inertia.vel.extend(velocities_m_per_s.iter().flatten());
        Ok(())
    }

    /// After the first step (which spans the sample's age): a haptic tick
    /// per step from now on.
    pub(super) fn end_first_step(&mut self) {
        if self.inertia.first_step {
            self.inertia.first_step = false;
            self.inertia.step_s = self.inertia.tick_s;
            std::mem::swap(&mut self.s, &mut self.inertia.s_tick);
            std::mem::swap(&mut self.w, &mut self.inertia.w_tick);
        }
    }

    /// `s` (S on entry) becomes S + (1/h^2 + c/h) M for a step `h_s`, `w`
    /// its inverse; false if not positive definite.
    fn stepped(&mut self, s: &mut [f64], w: &mut Vec<f64>, h_s: f64) -> bool {
        let n = self.delta.len();
        let a = 1.0 / (h_s * h_s) + self.inertia.damping_per_s / h_s;
        for (x, m) in s.iter_mut().zip(&self.inertia.m_red) {
            *x += a * m;
        }
        self.scratch.w_factor.clear();
        self.scratch.w_factor.extend_from_slice(s);
        if !cholesky(&mut self.scratch.w_factor, n) {
            return false;
        }
        cholesky_inverse(&self.scratch.w_factor, &mut self.scratch.m, w, n);
        true
    }

    /// With inertia, off the RT thread: one time step of the problem with
    /// the tool at `tool_m` at `t_ns` (a position the hand took since the
    /// problem's state), kept in the history as a render's would be, with
    /// the full iteration budget and no time budget. The set-up thread
    /// steps a new problem through the hand's recent positions so that the
    /// RT thread goes on from now, one tick a step, where one implicit step
    /// over the whole age damped the problem's transient (measured:
    /// `hapbench extrapolation`, docs/results/extrapolation.md). False if the step failed (the
    /// state before it stands; the set-up stops catching up there).
    pub fn catch_up(&mut self, t_ns: u64, tool_m: V3) -> bool {
        if !self.has_inertia() {
            return false;
        }
        self.budget.begin(false);
        self.track.keep(t_ns, tool_m);
        match self.solve_within_budget(tool_m) {
            Some((change, _)) => {
                self.history.remember(t_ns, change);
                true
            }
            None => false,
        }
    }
}

/// The value at `t` on the line through (`t0`, `c0`) and (`t1`, `c1`),
/// `t0 <= t <= t1`.
fn lerp(t0: u64, c0: V3, t1: u64, c1: V3, t: u64) -> V3 {
    if t1 <= t0 {
        return c1;
    }
    let w = (t - t0) as f64 / (t1 - t0) as f64;
    add(c0, scale(sub(c1, c0), w))
}

/// `out` = `a` `b` (row-major n x n), by row axpys over slices (they
/// vectorise; indexed loops did not).
fn matmul_into(a: &[f64], b: &[f64], out: &mut Vec<f64>, n: usize) {
    out.clear();
    out.resize(n * n, 0.0);
    for (a_row, out_row) in a.chunks_exact(n).zip(out.chunks_exact_mut(n)) {
        for (&x, b_row) in a_row.iter().zip(b.chunks_exact(n)) {
            if x != 0.0 {
                for (o, y) in out_row.iter_mut().zip(b_row) {
                    *o += x * y;
                }
            }
        }
    }
}
