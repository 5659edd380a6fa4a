//! Multirate stepping: the vertices whose elements need a short step are
//! sub-stepped at it, the rest of the organ keeps a longer one.
//!
//! A `[[refine]]` region of 2.5 mm cells in a 5 mm organ needs 13 sub-steps
//! a millisecond where the organ alone needs 5; with one step for all, the
//! whole organ pays for the few refined cells. This is explicit subcycling
//! with a nodal partition (Belytschko, Yen and Mullen 1979, "Mixed methods
//! for time integration", CMAME 17/18; the form whose stability Smolinski,
//! Sleith and Belytschko 1996 prove for linear structural dynamics,
//! Comput. Mech. 18:236-244, with step bounds from element frequencies):
//!
//! - a **fast** vertex belongs to an element whose own stable step (Irons'
//!   element bound, [`crate::tensor_mass::stability`]) is shorter than the
//!   coarse step, or to one ring of elements around those (Daniel 1997
//!   found that moving the partition one row of elements into the slow side
//!   narrows the subcycled scheme's resonance bands to nothing in practice),
//!   or is touched by a tool's contact or a nonlinear element (whose
//!   springs and tangent then set only the fast step);
//! - every H = dt / n_c (the **coarse** sub-step, set by the largest element
//!   bound among the elements that hold a slow vertex), one whole kernel
//!   pass moves every vertex by its own step: slow vertices by H, fast ones
//!   by h = H / m (the per-vertex coefficients of the central difference);
//! - the m - 1 fine sub-steps between recompute only the fast rows
//!   ([`row_product`], the pass's own arithmetic), reading the slow
//!   neighbours linearly interpolated between U(t) and U(t + H), which the
//!   pass has already computed (slow first).
//!
//! The step is then stable when h is under the bound of every element and
//! H under the bound of every element with a slow vertex, which is what
//! the partition enforces. The energy of an undamped refined block over
//! thousands of steps and the agreement with one step for all are tested
//! (`sim-server/tissue/tests/multirate.rs`).
//!
//! A scene asks for it (`[simulation] multirate = true`); it engages only
//! when the predicted work (a whole pass per coarse sub-step plus the fast
//! rows per fine one, a gathered row costing [`GATHERED_ROW_COST`] streamed
//! ones) is below [`ENGAGE_BELOW`] of one step for all.

use super::{DtPolicy, Explicit, MAX_SUBSTEPS, MultirateError};
use crate::math::Real;
use crate::tensor_mass::force_term::{ForcePoint, ForceTerm};
use crate::tensor_mass::kernel::{Kernel, LowerRows, Storage, V3, row_product};
use crate::tensor_mass::model::ElasticModel;

/// The work of one row recomputed alone (gathered), in rows of a whole
/// streamed pass (the AVX2 pass is about this much faster per row than
/// the scalar gather of [`crate::tensor_mass::kernel::row_product`]).
pub const GATHERED_ROW_COST: Real = 3.0;

/// Multirate engages when its predicted work is below this fraction of one
/// step for all (below, the bookkeeping is not worth it).
pub const ENGAGE_BELOW: Real = 0.8;

/// What the partition is: reported by `sim-server run` and the benches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MultirateReport {
    /// Vertices stepped at the fine step.
    pub fast_vertices: usize,
    /// Of all vertices.
    pub vertices: usize,
    /// Slow vertices read (interpolated) by fast rows.
    pub interface_vertices: usize,
    /// Coarse sub-steps per step (whole passes; not engaged: the count the
    /// slow elements would allow).
    pub coarse_substeps: usize,
    /// Fine sub-steps per step (the fast rows'); one step for all would
    /// take this many whole passes.
    pub fine_substeps: usize,
    /// Whether the partition is in use (its predicted work is below
    /// [`ENGAGE_BELOW`] of one step for all).
    pub engaged: bool,
}

/// The partition and the buffers of the fine sub-steps, reused.
#[derive(Debug)]
pub(super) struct Multirate {
    /// Column-ordered edges, for the fast rows' products.
    pub(super) lower: LowerRows,
    /// Per vertex: fast by its elements' bounds (the base partition).
    base: Vec<bool>,
    /// Per vertex: fast now (base, or touched by a tool or a nonlinear element).
    pub(super) is_fast: Vec<bool>,
    /// Fast vertices, ascending.
    pub(super) fast: Vec<u32>,
    /// Slow vertices adjacent to a fast one, ascending.
    pub(super) interface: Vec<u32>,
    /// U(t + H) of the interface vertices while they hold interpolated values.
    pub(super) saved: Vec<V3>,
    /// The fast rows' new values before they are written.
    pub(super) fresh: Vec<V3>,
    /// Coarse sub-steps a step needs by the elastic bound of the elements
    /// that hold a slow vertex (before any sub-step factor).
    pub(super) coarse_base: usize,
    /// Whether the partition is in use.
    pub(super) engaged: bool,
    /// Counts the changes of the fast set (a predicted step's rows are
    /// reused only while it stays the same).
    pub(super) generation: u64,
}

/// Each vertex's neighbours through the kernel's edges (both directions).
fn for_neighbours<S: Storage>(
    kernel: &Kernel<S>,
    lower: &LowerRows,
    i: usize,
    mut f: impl FnMut(usize),
) {
    let (_, _, edges) = kernel.parts();
    for e in &edges[kernel.row(i)] {
        f(e.col as usize);
    }
    for &[j, _] in lower.of(i) {
        f(j as usize);
    }
}

/// Coarse sub-steps a step of `dt_s` needs for omega_max^2 = `lambda`.
fn count_for(dt_s: Real, lambda: Real) -> usize {
    let dt_max = 2.0 / lambda.max(0.0).sqrt();
    if dt_max.is_finite() {
        ((dt_s / dt_max).ceil() as usize).max(1)
    } else {
        1
    }
}

/// One candidate partition: elements with lambda above `threshold` fast.
struct Candidate {
    base: Vec<bool>,
    fast_count: usize,
    coarse_base: usize,
}

impl Multirate {
    /// The partition with the least predicted work for steps of `dt_s`
    /// that take `uniform` sub-steps with one step for all.
    pub(super) fn plan<S: Storage>(
        model: &ElasticModel,
        kernel: &Kernel<S>,
        dt_s: Real,
        uniform: usize,
    ) -> Self {
        let lower = LowerRows::new(kernel);
        let lambdas = model.element_lambdas();
        let topo = model.topology();
        let tets = model.mesh().tets();
        let n = kernel.rows();
        let alive = |t: usize| topo.is_alive(crate::ids::TetId::from(t));
        let top = (0..tets.len())
            .filter(|&t| alive(t))
            .map(|t| lambdas[t])
            .fold(0.0, Real::max);
        let rows = n as Real;
        let work_of = |c: &Candidate| {
            let m = uniform.div_ceil(c.coarse_base).max(1);
            c.coarse_base as Real
                * (rows + (m - 1) as Real * c.fast_count as Real * GATHERED_ROW_COST)
        };
        // Thresholds from the stiffest element down by 1.5x in lambda
        // (1.22x in step): refined cells sit at 4x per halving.
        let mut threshold = top / 1.5;
        let first = Self::candidate(model, kernel, &lower, dt_s, threshold);
        let mut all_fast = first.fast_count == n;
        let (mut work, mut cand) = (work_of(&first), first);
        for _ in 1..16 {
            // Lower thresholds only add fast vertices.
            if all_fast {
                break;
            }
            threshold /= 1.5;
            let next = Self::candidate(model, kernel, &lower, dt_s, threshold);
            all_fast = next.fast_count == n;
            let w = work_of(&next);
            if w < work {
                (work, cand) = (w, next);
            }
        }
        let engaged = work < ENGAGE_BELOW * uniform as Real * rows;
        let mut plan = Self {
            lower,
            is_fast: cand.base.clone(),
            base: cand.base,
            fast: Vec::new(),
            interface: Vec::new(),
            saved: Vec::new(),
            fresh: Vec::new(),
            coarse_base: cand.coarse_base,
            engaged,
            generation: 0,
        };
        plan.rebuild_lists(kernel);
        plan
    }

    fn candidate<S: Storage>(
        model: &ElasticModel,
        kernel: &Kernel<S>,
        lower: &LowerRows,
        dt_s: Real,
        threshold: Real,
    ) -> Candidate {
        let lambdas = model.element_lambdas();
        let topo = model.topology();
        let tets = model.mesh().tets();
        let n = kernel.rows();
        let mut core = vec![false; n];
        for (t, tet) in tets.iter().enumerate() {
            if topo.is_alive(crate::ids::TetId::from(t)) && lambdas[t] > threshold {
                for v in tet {
                    core[v.idx()] = true;
                }
            }
        }
        // One ring more: the partition moved one row of elements into the
        // slow side.
        let mut base = core.clone();
        for (i, _) in core.iter().enumerate().filter(|(_, c)| **c) {
            for_neighbours(kernel, lower, i, |j| base[j] = true);
        }
        let mut coarse = 0.0;
        for (t, tet) in tets.iter().enumerate() {
            if topo.is_alive(crate::ids::TetId::from(t)) && tet.iter().any(|v| !base[v.idx()]) {
                coarse = Real::max(coarse, lambdas[t]);
            }
        }
        Candidate {
            fast_count: base.iter().filter(|f| **f).count(),
            base,
            coarse_base: count_for(dt_s, coarse),
        }
    }

    /// Rebuilds the fast and interface lists from `is_fast`.
    fn rebuild_lists<S: Storage>(&mut self, kernel: &Kernel<S>) {
        self.generation += 1;
        self.fast.clear();
        self.interface.clear();
        let n = self.is_fast.len();
        let mut seen = vec![false; n];
        for i in 0..n {
            if self.is_fast[i] {
                self.fast.push(i as u32);
                let (is_fast, lower) = (&self.is_fast, &self.lower);
                for_neighbours(kernel, lower, i, |j| {
                    if !is_fast[j] {
                        seen[j] = true;
                    }
                });
            }
        }
        self.interface
            .extend((0..n).filter(|&j| seen[j]).map(|j| j as u32));
        self.saved.resize(self.interface.len(), [0.0; 3]);
        self.fresh.resize(self.fast.len(), [0.0; 3]);
    }

    /// Makes the partition's fast set the base one plus `extra` vertices
    /// and their neighbours. Returns the vertices whose level changed.
    pub(super) fn set_extra<S: Storage>(
        &mut self,
        kernel: &Kernel<S>,
        extra: impl IntoIterator<Item = u32>,
    ) -> Vec<u32> {
        let before = std::mem::replace(&mut self.is_fast, self.base.clone());
        for v in extra {
            let v = v as usize;
            if v < self.is_fast.len() {
                self.is_fast[v] = true;
                let is_fast = &mut self.is_fast;
                for_neighbours(kernel, &self.lower, v, |j| is_fast[j] = true);
            }
        }
        let changed: Vec<u32> = (0..before.len())
            .filter(|&v| before[v] != self.is_fast[v])
            .map(|v| v as u32)
            .collect();
        if !changed.is_empty() {
            self.rebuild_lists(kernel);
        }
        changed
    }

    /// Adds `vertices` (and their neighbours) to the fast set. Returns the
    /// vertices that became fast.
    pub(super) fn grow<S: Storage>(
        &mut self,
        kernel: &Kernel<S>,
        vertices: impl IntoIterator<Item = u32>,
    ) -> Vec<u32> {
        let mut changed = Vec::new();
        for v in vertices {
            let v = v as usize;
            if v >= self.is_fast.len() {
                continue;
            }
            let is_fast = &mut self.is_fast;
            let mut mark = |j: usize| {
                if !is_fast[j] {
                    is_fast[j] = true;
                    changed.push(j as u32);
                }
            };
            mark(v);
            for_neighbours(kernel, &self.lower, v, mark);
        }
        if !changed.is_empty() {
            self.rebuild_lists(kernel);
        }
        changed
    }

    /// Whether each of `vertices` is fast.
    pub(super) fn covers(&self, vertices: impl IntoIterator<Item = u32>) -> bool {
        vertices
            .into_iter()
            .all(|v| self.is_fast.get(v as usize).copied().unwrap_or(true))
    }

    /// The report for `coarse` and `fine` sub-steps a step.
    pub(super) fn report(&self, coarse: usize, fine: usize) -> MultirateReport {
        MultirateReport {
            fast_vertices: self.fast.len(),
            vertices: self.is_fast.len(),
            interface_vertices: self.interface.len(),
            coarse_substeps: coarse,
            fine_substeps: fine,
            engaged: self.engaged,
        }
    }
}

/// The level parameters of a step: total (fine) sub-steps, coarse ones,
/// and whether the slow vertices take the coarse one.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) struct Levels {
    fine: usize,
    coarse: usize,
    engaged: bool,
}

impl Levels {
    fn own(&self, fast: bool) -> usize {
        if self.engaged && !fast {
            self.coarse
        } else {
            self.fine
        }
    }
}

impl<S: Storage> Explicit<S> {
    /// Turns multirate stepping on (the partition with the least predicted
    /// work; see the module docs) or off. Returns the partition, which is
    /// in use only when it pays ([`MultirateReport::engaged`]). Allocates:
    /// call at setup.
    pub fn set_multirate(&mut self, on: bool) -> Result<Option<MultirateReport>, MultirateError> {
        self.finish_step();
        if !on {
            // One step for all at the count the bounds need (not the
            // multiple of the coarse count it was rounded to).
            let fine = self.needed_substeps(self.size.tangent_lambda);
            self.relevel(Levels {
                fine,
                coarse: fine,
                engaged: false,
            });
            self.multirate = None;
            return Ok(None);
        }
        if self.size.policy == DtPolicy::Unchecked {
            return Err(MultirateError::Unchecked);
        }
        if !self.kernel.is_elastic()
            || self
                .large
                .as_ref()
                .is_some_and(|l| l.computes_whole_forces())
        {
            return Err(MultirateError::WholeForces);
        }
        let uniform = self.size.elastic_substeps * self.size.substep_factor;
        let mut plan = Multirate::plan(&self.model, &self.kernel, self.size.dt_s, uniform);
        if let Some(large) = &self.large {
            plan.set_extra(&self.kernel, large.vertices().iter().copied());
        }
        self.multirate = Some(plan);
        self.resubstep(self.size.substeps);
        Ok(self.multirate())
    }

    /// The multirate partition, when multirate stepping is on.
    pub fn multirate(&self) -> Option<MultirateReport> {
        self.multirate.as_ref().map(|p| {
            let (coarse, fine) = (self.size.coarse_substeps, self.size.substeps);
            // Not engaged: the coarse count it would take, beside one step for all.
            let would = (p.coarse_base * self.size.substep_factor).min(fine);
            p.report(if p.engaged { coarse } else { would }, fine)
        })
    }

    /// Fine sub-steps per coarse one (1: one step for all).
    pub(super) fn fine_per_coarse(&self) -> usize {
        match &self.multirate {
            Some(p) if p.engaged => self.size.substeps / self.size.coarse_substeps,
            _ => 1,
        }
    }

    /// Sub-steps vertex `v` takes a step.
    pub(super) fn own_substeps(&self, v: usize) -> usize {
        self.levels().own(self.vertex_is_fast(v))
    }

    fn vertex_is_fast(&self, v: usize) -> bool {
        self.multirate.as_ref().is_none_or(|p| p.is_fast[v])
    }

    fn levels(&self) -> Levels {
        Levels {
            fine: self.size.substeps,
            coarse: self.size.coarse_substeps,
            engaged: self.multirate.as_ref().is_some_and(|p| p.engaged),
        }
    }

    /// The levels for `n` fine sub-steps: with the partition engaged, the
    /// coarse count its slow elements need (times the sub-step factor) and
    /// `n` rounded up to a whole multiple of it.
    pub(super) fn levels_for(&self, n: usize) -> Levels {
        match &self.multirate {
            Some(p) if p.engaged => {
                let coarse = (p.coarse_base * self.size.substep_factor).min(n).max(1);
                let fine = (n.div_ceil(coarse) * coarse).min(MAX_SUBSTEPS / coarse * coarse);
                Levels {
                    fine: fine.max(coarse),
                    coarse,
                    engaged: true,
                }
            }
            _ => Levels {
                fine: n,
                coarse: n,
                engaged: false,
            },
        }
    }

    /// Moves to `new` levels, keeping every vertex's velocity
    /// (U(t) - U(t-1)) / h with its own h: an O(n) pass.
    pub(super) fn relevel(&mut self, new: Levels) {
        let old = self.levels();
        if old == new {
            return;
        }
        self.forget_prepared();
        for v in 0..self.u.len() {
            let fast = self.vertex_is_fast(v);
            let (o, w) = (old.own(fast), new.own(fast));
            if o != w {
                self.rescale_velocity(v, o as Real / w as Real);
            }
        }
        self.size.substeps = new.fine;
        self.size.coarse_substeps = new.coarse;
        if let Some(p) = &mut self.multirate {
            p.engaged = new.engaged;
        }
        self.size.resubsteps += 1;
        for v in 0..self.u.len() {
            self.refresh_vertex(v);
        }
    }

    /// U(t-1) of `v` moved for a step `ratio` times the old one, keeping its velocity.
    fn rescale_velocity(&mut self, v: usize, ratio: Real) {
        let (now, before) = (self.u[v], &mut self.next[v]);
        for k in 0..3 {
            before[k] = now[k] - (now[k] - before[k]) * ratio;
        }
    }

    /// After the fast set changed (`changed` switched level): their
    /// velocities kept and their coefficients refreshed.
    fn after_level_change(&mut self, changed: &[u32]) {
        let l = self.levels();
        if !l.engaged || changed.is_empty() {
            return;
        }
        self.forget_prepared();
        for &v in changed {
            let v = v as usize;
            let fast_now = self.vertex_is_fast(v);
            let (before, now) = (l.own(!fast_now), l.own(fast_now));
            if before != now {
                self.rescale_velocity(v, before as Real / now as Real);
            }
            self.refresh_vertex(v);
        }
    }

    /// Makes the fast set the base one plus the nonlinear elements'
    /// vertices (the region that follows the tools), at a step boundary.
    pub(super) fn multirate_follow_region(&mut self) {
        let Some(plan) = &mut self.multirate else {
            return;
        };
        let extra = self.large.iter().flat_map(|l| l.vertices().iter().copied());
        let changed = plan.set_extra(&self.kernel, extra);
        // Each changed vertex switched level.
        self.after_level_change(&changed);
    }

    /// Makes every vertex the contact `field` reaches fast (its springs then
    /// set only the fine step), at a step boundary.
    pub(super) fn multirate_cover<F: ForceTerm>(&mut self, field: &F) {
        let Some(plan) = &mut self.multirate else {
            return;
        };
        if !plan.engaged {
            return;
        }
        let reached = || field.points().iter().flat_map(|p| p.vertices());
        if plan.covers(reached()) {
            return;
        }
        let changed = plan.grow(&self.kernel, reached());
        self.after_level_change(&changed);
    }

    /// Writes the slow neighbours of the fast vertices at the fraction `s`
    /// of the coarse sub-step (linear between U(t) in `next` and U(t + H)
    /// in `u`), keeping U(t + H) aside.
    pub(super) fn interpolate_interface(&mut self, s: Real) {
        let Some(plan) = &mut self.multirate else {
            return;
        };
        for (saved, &j) in plan.saved.iter_mut().zip(&plan.interface) {
            let j = j as usize;
            *saved = self.u[j];
            for d in 0..3 {
                self.u[j][d] = self.next[j][d] + s * (self.u[j][d] - self.next[j][d]);
            }
        }
    }

    /// One fine sub-step of the fast rows alone (the pass's own products
    /// and integration), then the interface's U(t + H) back.
    pub(super) fn fast_rows(&mut self) {
        // Out of `self` while the pass's inputs borrow it.
        let Some(mut plan) = self.multirate.take() else {
            return;
        };
        let pass = self.pass();
        for (fresh, &i) in plan.fresh.iter_mut().zip(&plan.fast) {
            let i = i as usize;
            let ku = row_product(pass.kernel, &plan.lower, pass.inputs.u, i);
            let mut v = pass.next[i];
            pass.inputs.integrate(i, ku, &mut v);
            *fresh = v;
        }
        for (fresh, &i) in plan.fresh.iter().zip(&plan.fast) {
            let i = i as usize;
            self.next[i] = self.u[i];
            self.u[i] = *fresh;
        }
        for (saved, &j) in plan.saved.iter().zip(&plan.interface) {
            self.u[j as usize] = *saved;
        }
        self.multirate = Some(plan);
    }
}
