//! The step's rows split into contiguous parts for worker threads: each
//! part's range, the rows earlier parts reach (finished after the join),
//! its scratch, and the recursive `rayon::join` that runs them.

use crate::tensor_mass::kernel::{Kernel, Part, R4, StepInputs, Storage, V3};

/// Row ranges and the rows each part must finish after the join.
#[derive(Clone, Debug)]
pub(super) struct PartPlan {
    pub(super) start: usize,
    pub(super) end: usize,
    pub(super) deferred_end: usize,
    pub(super) spill_len: usize,
}

/// A part's scratch, allocated once: its accumulator ring, its deferred
/// rows' K U and its spill past its end.
#[derive(Clone, Debug)]
pub(super) struct PartBuffers {
    pub(super) ring: Vec<R4>,
    pub(super) deferred: Vec<V3>,
    pub(super) spill: Vec<V3>,
}

/// Splits rows into `threads` contiguous parts of about equal work (rows plus
/// blocks), and finds for each which rows earlier parts reach.
pub(super) fn plan_parts<S: Storage>(kernel: &Kernel<S>, threads: usize) -> Vec<PartPlan> {
    let n = kernel.rows();
    let work = |i: usize| 1 + kernel.row(i).len();
    let total: usize = (0..n).map(work).sum();
    let parts = threads.min(n.max(1));
    let mut bounds = vec![0usize];
    let mut acc = 0;
    for i in 0..n {
        acc += work(i);
        if bounds.len() < parts && acc * parts >= total * bounds.len() {
            bounds.push(i + 1);
        }
    }
    while bounds.len() < parts + 1 {
        bounds.push(n);
    }
    *bounds.last_mut().expect("non-empty") = n;
    let mut plans = Vec::with_capacity(parts);
    let mut reach_before = 0usize;
    for w in bounds.windows(2) {
        let (start, end) = (w[0], w[1]);
        let reach = (start..end)
            .map(|i| kernel.reach(i) + 1)
            .max()
            .unwrap_or(end);
        plans.push(PartPlan {
            start,
            end,
            deferred_end: reach_before.clamp(start, end),
            spill_len: reach.saturating_sub(end),
        });
        reach_before = reach_before.max(reach);
    }
    plans
}

/// Runs parts recursively with `rayon::join` (no allocation per step).
pub(super) fn run_parts<S: Storage>(
    kernel: &Kernel<S>,
    inputs: &StepInputs<'_>,
    plans: &[PartPlan],
    offset: usize,
    next: &mut [V3],
    buffers: &mut [PartBuffers],
) {
    if let [p] = plans {
        let b = &mut buffers[0];
        kernel.run_part(
            inputs,
            Part {
                start: p.start,
                end: p.end,
                deferred_end: p.deferred_end,
                ring: &mut b.ring,
                deferred: &mut b.deferred,
                next: &mut next[p.start - offset..p.end - offset],
                spill: &mut b.spill,
            },
        );
        return;
    }
    let mid = plans.len() / 2;
    let split = plans[mid].start - offset;
    let (next_a, next_b) = next.split_at_mut(split);
    let (buf_a, buf_b) = buffers.split_at_mut(mid);
    let (pa, pb) = plans.split_at(mid);
    rayon::join(
        || run_parts(kernel, inputs, pa, offset, next_a, buf_a),
        || run_parts(kernel, inputs, pb, plans[mid].start, next_b, buf_b),
    );
}
