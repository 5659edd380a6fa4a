//! The whole next step computed ahead without the tools, and finished
//! locally once they are known (predictor / local corrector).
//!
//! A live loop waits most of a millisecond for the next pose, then has to
//! answer it with a step. Everything in that step except the tools'
//! forces, prescribed vertices and loads is already known: the free motion
//! of the tissue. [`Explicit::prepare_step`] computes all of the next
//! step's sub-steps that way (P_1 .. P_S, the kernel's own pass, with no
//! contact force), and the step, when it comes, recomputes only the rows
//! the tools can have changed:
//!
//! ```text
//! R_0 = contact vertices of the field's points + vertices whose constraint,
//!       target or load changed since the prediction, or whose element was
//!       cut (a cut changes only the tensors among its four vertices)
//! R_k = R_(k-1) + their neighbours         (one ring a sub-step)
//! ```
//!
//! A row outside R_k reads only values that equal the prediction (its own
//! and its neighbours' U(t), its U(t-1), no contact force, the same
//! constraint), so its prediction is the step's value; a row inside is
//! recomputed by [`row_product`] in exactly the pass's order of additions,
//! so the whole step equals the plain one to the bit (tests: each row
//! alone in the kernel's `dispatched_and_portable_passes_are_identical`,
//! its `tests`, and the contact scenes in
//! `sim-server/tests/predicted_step.rs`). On the liver (1,763 vertices, 3
//! sub-steps) a tool pressing 4 mm has the step after a pose recompute
//! about 90 rows against 5,289 for three passes. Once the rows reach half
//! the mesh (many sub-steps) the rest of the step runs whole passes.
//!
//! With multirate stepping (`multirate.rs`) the prediction is the
//! multirate step itself: whole passes at the coarse sub-steps (each
//! vertex by its own step: a slow one reads its U(t - H), kept in the
//! trajectory m slots back), the fast rows alone at the fine ones (the
//! interface interpolated in place, as the plain step does); a slow row
//! is the previous slot's copy between two coarse sub-steps. The
//! correction grows one ring into the fast vertices at a fine sub-step
//! (only they move there) and one ring into all at a coarse one, so on a
//! refined organ it stays within the fast region and a few rings of coarse
//! cells round it: the slow rows of the whole passes come from the
//! prediction.
//!
//! Used where every row's force is the linear kernel's: one part (no
//! worker threads), no nonlinear elements, no nonlinear membrane, and no
//! re-selection of contact points inside the step (a step longer than the
//! field's resampling period). Otherwise the first sub-step's K U alone is
//! computed ahead, as before.

use super::{Ahead, Explicit, Parts, StepSize};
use crate::math::Real;
use crate::tensor_mass::force_term::{ForcePoint, ForceTerm, SubStep};
use crate::tensor_mass::huge_pages::huge_vec;
use crate::tensor_mass::kernel::{
    Kernel, LowerRows, Neighbours, Part, R4, StepInputs, Storage, V3, kind, row_product,
};
use levels::{Levels, levels};
use reach::Reach;

/// One part's pass over every row (the single-part plan: nothing deferred,
/// nothing spilled): U(t+1) over U(t-1) in `next`.
fn whole_pass<S: Storage>(
    kernel: &Kernel<S>,
    inputs: &StepInputs<'_>,
    ring: &mut [R4],
    next: &mut [V3],
) {
    kernel.run_part(
        inputs,
        Part {
            start: 0,
            end: next.len(),
            deferred_end: 0,
            ring,
            deferred: &mut [],
            next,
            spill: &mut [],
        },
    );
}

/// Row `i` of a sub-step: U(t_k + h) from `now` and its own U(t_k - h).
fn row<S: Storage>(
    kernel: &Kernel<S>,
    lower: &LowerRows,
    inputs: &StepInputs<'_>,
    i: usize,
    prev: V3,
) -> V3 {
    let ku = row_product(kernel, lower, inputs.u, i);
    let mut next = prev;
    inputs.integrate(i, ku, &mut next);
    next
}

/// Sub-step `k` whole, into `out` from `before`'s slots (the plain
/// step's arithmetic): a kernel pass over every row at a coarse sub-step
/// (each row's own U(t_k - h) written first), the fast rows alone at a
/// fine one (the slow rows the previous slot's copy, the interface
/// interpolated). Returns the rows computed.
#[allow(clippy::too_many_arguments)]
fn whole_substep<S: Storage>(
    kernel: &Kernel<S>,
    lower: &LowerRows,
    levels: &mut Levels<'_>,
    base: &StepInputs<'_>,
    ring: &mut [R4],
    before: &mut [Vec<V3>],
    out: &mut [V3],
    k: usize,
) -> u64 {
    if levels.fine(k) {
        out.copy_from_slice(&before[k + 1]);
        levels.interpolate(before, k);
        let inputs = StepInputs {
            u: &before[k + 1],
            ..*base
        };
        for &i in levels.fast {
            let i = i as usize;
            out[i] = row(kernel, lower, &inputs, i, before[k][i]);
        }
        levels.restore(&mut before[k + 1]);
        levels.fast.len() as u64
    } else {
        levels.coarse_prev(before, k, out);
        let inputs = StepInputs {
            u: &before[k + 1],
            ..*base
        };
        whole_pass(kernel, &inputs, ring, out);
        out.len() as u64
    }
}

/// The predicted step and the bookkeeping of its correction, allocated at
/// the first prediction and reused.
#[derive(Debug, Default)]
pub(in crate::tensor_mass) struct Prediction {
    /// While a step is finished: U(t-1), U(t), then P_1 .. P_S (each
    /// corrected in place). Between steps slots 0 and 1 are empty (the
    /// state's own arrays) and 2.. hold the prediction (and arrays kept
    /// from a larger sub-step count).
    traj: Vec<Vec<V3>>,
    /// The sub-step count it was made for; `None`: no prediction.
    made_for: Option<usize>,
    lower: LowerRows,
    /// The same edges as one compact list, for the bookkeeping.
    neighbours: Neighbours,
    /// Vertices whose constraint, target or load changed since.
    changed: Vec<u32>,
    /// Per vertex: in `rows`.
    in_rows: Vec<bool>,
    /// Per vertex: in `changed`.
    in_changed: Vec<bool>,
    /// The rows recomputed at the current sub-step.
    rows: Vec<u32>,
    /// Rows recomputed over all finished steps.
    rows_total: u64,
    /// The rows reached half the mesh: the rest of the step runs whole
    /// passes (streaming every row beats gathering most of them).
    whole: bool,
    /// `rows[..counts[k]]` are sub-step `k`'s (the list only grows).
    counts: Vec<u32>,
    /// `rows[..grown_all]` have had every neighbour marked,
    /// `rows[..grown_fast]` their fast ones ([`Prediction::grow`]).
    grown_all: usize,
    grown_fast: usize,
    /// Leave the rows the step's force cannot depend on for
    /// [`Prediction::finish`] (`Explicit::defer_far_rows`).
    pub(in crate::tensor_mass) defer: bool,
    /// How far each row is from the step's first rows.
    reach: Reach,
    /// Sub-steps before this one have far rows left (the whole passes
    /// after it computed every row).
    far_until: usize,
    /// The step's near rows are done and in the state; its far ones wait.
    pending: bool,
    /// The first rows of the step whose rows, counts and reach are kept
    /// (each once, in marking order), and what else they were made for:
    /// while the tools' contact points stay the same (their selection
    /// holds for many steps) the next step's rows are the same, and
    /// finding them again cost about a sixth of the step after the pose.
    kept: Vec<u32>,
    kept_for: Option<KeptFor>,
    /// This step reuses the kept rows.
    reused: bool,
    /// Steps that reused their rows.
    reused_total: u64,
    /// The first rows being gathered (scratch) and a flag per vertex.
    first: Vec<u32>,
    in_first: Vec<bool>,
}

/// What a step's rows depend on besides its first rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct KeptFor {
    substeps: usize,
    m: usize,
    generation: u64,
    defer: bool,
}

/// Which of a sub-step's marked rows a pass recomputes.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Share {
    All,
    /// Those within reach of the step's force ([`Reach::near`]).
    Near,
    /// The rest.
    Far,
}

impl Prediction {
    /// Whether a prediction for `substeps` sub-steps is waiting.
    pub(in crate::tensor_mass) fn ready(&self, substeps: usize) -> bool {
        self.made_for == Some(substeps)
    }

    /// Rows recomputed over all finished steps (each sub-step's counted).
    pub(in crate::tensor_mass) fn rows_total(&self) -> u64 {
        self.rows_total
    }

    /// Steps that reused the rows kept from the step before.
    pub(in crate::tensor_mass) fn reused_total(&self) -> u64 {
        self.reused_total
    }

    /// Drops the prediction (a new state, a new sub-step count, cleared loads).
    pub(in crate::tensor_mass) fn forget(&mut self) {
        if self.made_for.take().is_some() {
            for &v in &self.changed {
                self.in_changed[v as usize] = false;
            }
            self.changed.clear();
        }
    }

    /// Vertex `v`'s constraint, target or load changed after the
    /// prediction: its row is recomputed at every sub-step.
    pub(in crate::tensor_mass) fn touch(&mut self, v: usize) {
        if self.made_for.is_some() && !self.in_changed[v] {
            self.in_changed[v] = true;
            self.changed.push(v as u32);
        }
    }

    /// Computes P_1 .. P_S from U(t-1) = `prev`, U(t) = `now` with
    /// `base`'s coefficients and forces (its `u` is ignored): each sub-step
    /// a kernel pass (`ring` its accumulator), or with multirate `levels`
    /// the fast rows alone at the fine sub-steps.
    #[allow(clippy::too_many_arguments)]
    pub(in crate::tensor_mass) fn predict<S: Storage>(
        &mut self,
        kernel: &Kernel<S>,
        substeps: usize,
        levels: &mut Levels<'_>,
        base: &StepInputs<'_>,
        ring: &mut [R4],
        prev: &mut Vec<V3>,
        now: &mut Vec<V3>,
    ) {
        let n = now.len();
        if !self.lower.fits(n) {
            self.lower = LowerRows::new(kernel);
            self.neighbours = Neighbours::new(kernel, &self.lower);
            self.in_rows = vec![false; n];
            self.in_changed = vec![false; n];
            self.in_first = vec![false; n];
            // Each lists a vertex at most once: no step allocates.
            self.rows = Vec::with_capacity(n);
            self.first = Vec::with_capacity(n);
            self.kept = Vec::with_capacity(n);
            self.kept_for = None;
            self.changed = Vec::with_capacity(n);
            self.reach = Reach::new(n);
        }
        // Never shrunk: a sub-step count that comes and goes (explicit
        // contact springs) reuses its arrays instead of reallocating them.
        if self.traj.len() < substeps + 2 {
            self.traj.resize_with(substeps + 2, Vec::new);
        }
        self.counts.reserve(substeps);
        for b in &mut self.traj[2..substeps + 2] {
            if b.len() != n {
                *b = huge_vec(n, [0.0; 3]);
            }
        }
        std::mem::swap(prev, &mut self.traj[0]);
        std::mem::swap(now, &mut self.traj[1]);
        for k in 0..substeps {
            // P_(k+1) from P_k and each vertex's own previous value.
            let (before, after) = self.traj.split_at_mut(k + 2);
            whole_substep(
                kernel,
                &self.lower,
                levels,
                base,
                ring,
                before,
                &mut after[0],
                k,
            );
        }
        std::mem::swap(prev, &mut self.traj[0]);
        std::mem::swap(now, &mut self.traj[1]);
        self.made_for = Some(substeps);
    }

    /// Starts finishing the predicted step: takes the state's arrays
    /// (U(t-1), U(t)) into the trajectory and marks the first sub-step's
    /// rows: the changed vertices and `contact` ones. When they, the
    /// sub-steps and the fast set are the last kept step's, its rows
    /// (every sub-step's) and reach serve again: they depend on nothing
    /// else (the edges' places never change).
    pub(in crate::tensor_mass) fn begin(
        &mut self,
        levels: &Levels<'_>,
        prev: &mut Vec<V3>,
        now: &mut Vec<V3>,
        contact: impl Iterator<Item = u32>,
    ) {
        std::mem::swap(prev, &mut self.traj[0]);
        std::mem::swap(now, &mut self.traj[1]);
        for c in 0..self.changed.len() {
            let v = self.changed[c];
            self.in_changed[v as usize] = false;
            self.gather_first(v);
        }
        // Cleared, not taken: its capacity serves every step.
        self.changed.clear();
        for v in contact {
            self.gather_first(v);
        }
        for &v in &self.first {
            self.in_first[v as usize] = false;
        }
        self.far_until = usize::MAX;
        let substeps = self.made_for.unwrap_or(0);
        let now_for = KeptFor {
            substeps,
            m: levels.m,
            generation: levels.generation,
            defer: self.defer,
        };
        self.reused = self.kept_for == Some(now_for) && self.first == self.kept;
        if self.reused {
            self.reused_total += 1;
            self.first.clear();
            return;
        }
        self.drop_rows();
        for f in 0..self.first.len() {
            let v = self.first[f];
            self.mark(v);
        }
        std::mem::swap(&mut self.first, &mut self.kept);
        self.first.clear();
        self.kept_for = Some(now_for);
        if self.defer {
            self.reach
                .measure(&self.neighbours, levels, &self.rows, substeps);
        }
    }

    /// Adds `v` to the step's first rows (once).
    fn gather_first(&mut self, v: u32) {
        if !self.in_first[v as usize] {
            self.in_first[v as usize] = true;
            self.first.push(v);
        }
    }

    /// Forgets the kept rows, counts and reach (only the vertices set are
    /// reset).
    fn drop_rows(&mut self) {
        for &r in &self.rows {
            self.in_rows[r as usize] = false;
        }
        self.rows.clear();
        self.counts.clear();
        (self.grown_all, self.grown_fast) = (0, 0);
        self.reach.clear();
        self.kept_for = None;
    }

    fn mark(&mut self, v: u32) {
        if !self.in_rows[v as usize] {
            self.in_rows[v as usize] = true;
            self.rows.push(v);
        }
    }

    /// Adds the neighbours of every marked row (sub-step `k`'s rows): at
    /// a fine sub-step only the fast ones, the only rows it moves (a slow
    /// neighbour reads the change at the next coarse sub-step, when every
    /// neighbour of the marked rows is added). Only the rows marked since
    /// the last such growth are visited: the older ones' neighbours are in
    /// already (the list only grows), which keeps a step of many sub-steps
    /// linear in its rows.
    pub(in crate::tensor_mass) fn grow(&mut self, k: usize, levels: &Levels<'_>) {
        if self.whole || self.reused {
            return;
        }
        let fine = levels.fine(k);
        let count = self.rows.len();
        let from = if fine {
            self.grown_fast
        } else {
            self.grown_all
        };
        for r in from..count {
            let i = self.rows[r] as usize;
            for &j in self.neighbours.of(i) {
                if (!fine || levels.is_fast(j as usize)) && !self.in_rows[j as usize] {
                    self.in_rows[j as usize] = true;
                    self.rows.push(j);
                }
            }
        }
        self.grown_fast = count;
        if !fine {
            self.grown_all = count;
        }
    }

    /// Sub-step `k`'s arrays: U(t_k - h), U(t_k) and U(t_k + h) (holding
    /// the prediction).
    pub(in crate::tensor_mass) fn substep(&mut self, k: usize) -> (&[V3], &[V3], &mut [V3]) {
        let (before, after) = self.traj.split_at_mut(k + 2);
        (&before[k], &before[k + 1], &mut after[0])
    }

    /// Recomputes the marked rows of sub-step `k`: U(t_k + h) from U(t_k)
    /// and each row's own U(t_k - h) with `base`'s coefficients,
    /// constraints and forces (its `u` is ignored); once they are half the
    /// mesh, every row by the kernel's pass (with its accumulator `ring`).
    /// At a fine sub-step the marked slow rows take the previous slot's
    /// value and the fast ones are recomputed against the interpolated
    /// interface. (The contact field, evaluated before, reads only its
    /// points' vertices, which `multirate_cover` made fast: it never sees
    /// the interface, interpolated or not.) With `defer`, only the rows
    /// the step's force can depend on ([`Reach`]); the others wait for
    /// [`Prediction::finish`].
    pub(in crate::tensor_mass) fn correct_rows<S: Storage>(
        &mut self,
        kernel: &Kernel<S>,
        k: usize,
        levels: &mut Levels<'_>,
        base: &StepInputs<'_>,
        ring: &mut [R4],
    ) {
        let n = self.in_rows.len();
        if self.reused {
            // Its rows never reached half the mesh (the kept ones would not
            // have been kept), and its counts are all there.
            let share = if self.defer { Share::Near } else { Share::All };
            self.recompute(kernel, k, levels, base, ring, share);
            return;
        }
        if !self.whole && 2 * self.rows.len() > n {
            self.whole = true;
            self.kept_for = None;
            // The whole passes read every row: the sub-steps before
            // finish their far rows first.
            if self.defer {
                for j in 0..k {
                    self.recompute(kernel, j, levels, base, ring, Share::Far);
                }
            }
            self.far_until = k;
        }
        if self.whole {
            self.recompute(kernel, k, levels, base, ring, Share::All);
            return;
        }
        self.counts.push(self.rows.len() as u32);
        let share = if self.defer { Share::Near } else { Share::All };
        self.recompute(kernel, k, levels, base, ring, share);
    }

    /// Sub-step `k`'s `share` of its rows (every row, by whole passes,
    /// when `whole` and `share` is [`Share::All`]).
    fn recompute<S: Storage>(
        &mut self,
        kernel: &Kernel<S>,
        k: usize,
        levels: &mut Levels<'_>,
        base: &StepInputs<'_>,
        ring: &mut [R4],
        share: Share,
    ) {
        let whole = self.whole && share == Share::All;
        let count = if whole { 0 } else { self.counts[k] as usize };
        let (reach, rows) = (&self.reach, &self.rows[..count]);
        let take = |i: usize| match share {
            Share::All => true,
            Share::Near => reach.near(i, k),
            Share::Far => !reach.near(i, k),
        };
        let (before, after) = self.traj.split_at_mut(k + 2);
        let out = &mut after[0];
        if whole {
            self.rows_total +=
                whole_substep(kernel, &self.lower, levels, base, ring, before, out, k);
            return;
        }
        let mut done = 0u64;
        if levels.fine(k) {
            for &r in rows {
                let i = r as usize;
                if !levels.is_fast(i) && take(i) {
                    out[i] = before[k + 1][i];
                }
            }
            levels.interpolate(before, k);
            let inputs = StepInputs {
                u: &before[k + 1],
                ..*base
            };
            for &r in rows {
                let i = r as usize;
                if levels.is_fast(i) && take(i) {
                    done += 1;
                    out[i] = row(kernel, &self.lower, &inputs, i, before[k][i]);
                }
            }
            levels.restore(&mut before[k + 1]);
        } else {
            let inputs = StepInputs {
                u: &before[k + 1],
                ..*base
            };
            let slow = levels.slow_prev(k);
            for &r in rows {
                let i = r as usize;
                if !take(i) {
                    continue;
                }
                done += 1;
                let prev = if levels.is_fast(i) {
                    before[k][i]
                } else {
                    before[slow][i]
                };
                out[i] = row(kernel, &self.lower, &inputs, i, prev);
            }
        }
        self.rows_total += done;
    }

    /// Whether a step's far rows wait for [`Prediction::finish`].
    pub(in crate::tensor_mass) fn pending(&self) -> bool {
        self.pending
    }

    /// The step's near rows are done (with `defer`): U(t) and U(t-1) go
    /// to the state (`now`, `prev`), which readers of the force see; the
    /// rows far from the tools keep the prediction until
    /// [`Prediction::finish`].
    pub(in crate::tensor_mass) fn hold(&mut self, prev: &mut Vec<V3>, now: &mut Vec<V3>) {
        let s = self.made_for.unwrap_or(self.traj.len() - 2);
        std::mem::swap(now, &mut self.traj[s + 1]);
        std::mem::swap(prev, &mut self.traj[s]);
        self.pending = true;
    }

    /// Recomputes the far rows of every sub-step, in order, and ends the
    /// step ([`Prediction::end`]): the state is then the plain step's.
    pub(in crate::tensor_mass) fn finish<S: Storage>(
        &mut self,
        kernel: &Kernel<S>,
        levels: &mut Levels<'_>,
        base: &StepInputs<'_>,
        ring: &mut [R4],
        prev: &mut Vec<V3>,
        now: &mut Vec<V3>,
    ) {
        if !std::mem::take(&mut self.pending) {
            return;
        }
        let s = self.made_for.unwrap_or(self.traj.len() - 2);
        std::mem::swap(now, &mut self.traj[s + 1]);
        std::mem::swap(prev, &mut self.traj[s]);
        for k in 0..s.min(self.far_until) {
            self.recompute(kernel, k, levels, base, ring, Share::Far);
        }
        self.end(levels, prev, now);
    }

    /// Ends the step: U(t) and U(t-1) back to the state (`now`, `prev`:
    /// P_S and P_(S-1)), the other arrays kept for the next prediction.
    /// With multirate `levels`, a slow vertex's U(t-1) is its value
    /// before the last coarse pass (m slots back), as the plain step leaves it.
    pub(in crate::tensor_mass) fn end(
        &mut self,
        levels: &Levels<'_>,
        prev: &mut Vec<V3>,
        now: &mut Vec<V3>,
    ) {
        let s = self.made_for.unwrap_or(self.traj.len() - 2);
        if levels.m > 1 {
            let (before, after) = self.traj.split_at_mut(s);
            let (back, last) = (&before[s + 1 - levels.m], &mut after[0]);
            for (i, fast) in levels.is_fast.iter().enumerate() {
                if !fast {
                    last[i] = back[i];
                }
            }
        }
        std::mem::swap(now, &mut self.traj[s + 1]);
        std::mem::swap(prev, &mut self.traj[s]);
        // The two emptied slots become 0 and 1.
        let mut empty = 0;
        for k in 0..self.traj.len() {
            if self.traj[k].is_empty() {
                self.traj.swap(k, empty);
                empty += 1;
            }
        }
        // The rows are kept for the next step unless it went whole (or
        // stopped short of its sub-steps).
        if self.kept_for.is_none() || self.counts.len() != s {
            self.drop_rows();
        }
        self.whole = false;
        self.reused = false;
        self.made_for = None;
    }
}

impl<S: Storage> Explicit<S> {
    /// [`Explicit::prepare_step`] where every row's force is the linear
    /// kernel's: the whole step without the tools (this module).
    pub(super) fn predict(&mut self) {
        if self.ahead.prediction.ready(self.size.substeps) {
            return;
        }
        let substeps = self.size.substeps;
        let mut p = self.split(false);
        p.prediction.predict(
            p.kernel,
            substeps,
            &mut p.levels,
            &p.base,
            p.ring,
            p.next,
            p.u,
        );
    }

    /// The prediction beside the step's inputs (`base`'s contact forces
    /// only `with_contact`), borrowed apart.
    fn split(&mut self, with_contact: bool) -> Split<'_, S> {
        let m = self.fine_per_coarse();
        let Self {
            kernel,
            u,
            next,
            coef,
            kind,
            target,
            fext,
            fmem,
            parts: Parts { buffers, .. },
            ahead: Ahead { prediction, .. },
            multirate,
            ..
        } = self;
        Split {
            kernel,
            prediction,
            levels: levels(m, multirate.as_mut()),
            base: StepInputs {
                u: &[],
                coef,
                kind,
                target,
                fext,
                fmem: if with_contact { fmem } else { &[] },
                fnl: &[],
            },
            ring: &mut buffers[0].ring,
            next,
            u,
        }
    }

    /// The predicted step finished with the tools: `field`'s forces (if
    /// any) at every sub-step, and the rows they and the changed vertices
    /// reach recomputed (the same arithmetic as the plain step).
    pub(super) fn finish_predicted<F: ForceTerm>(&mut self, mut field: Option<&mut F>) {
        let substeps = self.size.substeps;
        let h = self.size.dt_s / substeps as Real;
        let m = self.fine_per_coarse();
        let Self {
            kernel,
            u,
            next,
            coef,
            kind,
            target,
            fext,
            fmem,
            ahead: Ahead { prediction, .. },
            model,
            size: StepSize { dt_s, .. },
            parts: Parts { buffers, .. },
            multirate,
            ..
        } = self;
        let mut levels = levels(m, multirate.as_mut());
        let contact = field
            .as_deref()
            .into_iter()
            .flat_map(|f| f.points().iter().flat_map(|p| p.vertices()));
        prediction.begin(&levels, next, u, contact);
        for k in 0..substeps {
            if k > 0 {
                prediction.grow(k, &levels);
            }
            if let Some(field) = field.as_deref_mut() {
                field.zero(fmem);
                let (prev, now, _) = prediction.substep(k);
                let at = SubStep {
                    h_s: h,
                    step_s: *dt_s,
                    s: (k + 1) as Real / substeps as Real,
                    masses_kg: model.masses_kg(),
                };
                field.add_forces(model.mesh().positions_m(), now, prev, at, fmem);
            }
            let base = StepInputs {
                u: &[],
                coef,
                kind,
                target,
                fext,
                fmem,
                fnl: &[],
            };
            prediction.correct_rows(kernel, k, &mut levels, &base, &mut buffers[0].ring);
            if let Some(field) = field.as_deref_mut()
                && field.implicit_springs()
            {
                let (_, now, out) = prediction.substep(k);
                let inverse_d = |i: usize| (kind[i] == kind::FREE).then(|| coef[i][0]);
                field.correct_implicit(inverse_d, now, out);
            }
        }
        if prediction.defer {
            prediction.hold(next, u);
        } else {
            prediction.end(&levels, next, u);
        }
        self.ahead.predicted_steps += 1;
        self.steps += 1;
        self.follow_tangent();
    }
}

impl<S: Storage> Explicit<S> {
    /// Has each predicted step leave the rows its force cannot depend on
    /// (those far from the tools, [`reach`]) until
    /// [`Explicit::finish_step`], so that a live loop sends the force
    /// first and finishes the step after: the state is the plain step's
    /// once finished, and until then its far rows hold the prediction.
    /// Every call that steps, prepares or changes the model or its inputs
    /// finishes a pending step first.
    pub fn defer_far_rows(&mut self, on: bool) {
        self.finish_step();
        self.ahead.prediction.defer = on;
    }

    /// Finishes a step [`Explicit::defer_far_rows`] left pending (nothing
    /// otherwise).
    pub fn finish_step(&mut self) {
        if !self.ahead.prediction.pending() {
            return;
        }
        // The far rows never carry a contact force (the field writes only
        // its points' vertices, all near): `fmem` is as it was in the step.
        let mut p = self.split(true);
        p.prediction
            .finish(p.kernel, &mut p.levels, &p.base, p.ring, p.next, p.u);
    }
}

/// [`Explicit::split`]: what a prediction pass borrows.
struct Split<'a, S: Storage> {
    kernel: &'a Kernel<S>,
    prediction: &'a mut Prediction,
    levels: Levels<'a>,
    base: StepInputs<'a>,
    ring: &'a mut [R4],
    next: &'a mut Vec<V3>,
    u: &'a mut Vec<V3>,
}

mod levels;
mod reach;
#[cfg(test)]
mod tests;
