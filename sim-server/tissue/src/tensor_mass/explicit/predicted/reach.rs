//! Which rows a step's force can depend on: the rest of the correction
//! can wait until the force sample is out.
//!
//! The force the tools feel after a step (the contact field, evaluated at
//! every sub-step on its points' vertices, and the elastic force at a
//! grip's vertices, which reads their neighbours at the end) reads the
//! step's first rows (the contact vertices and those whose constraint or
//! load changed) at every sub-step and their neighbours at the last. A
//! row's value at sub-step k is read by the row itself at k + 1 (its own
//! U, or a slow row's copy), and by its neighbours at the first sub-step
//! after k that recomputes them: every sub-step for a fast row, only the
//! whole passes for a slow one. So each row has a last sub-step whose value
//! the force needs, found backwards from the end:
//!
//! ```text
//! last(first rows) = last(their neighbours) = S - 1
//! a = last(i) if i is fast (or one step for all), else the last whole pass <= last(i)
//! last(j) >= a - 1 for every neighbour j of i
//! ```
//!
//! and sub-step k recomputes before the sample only its rows with
//! `k <= last`. With one step for all that is the diamond of rows within
//! min(k, S - k) rings of the first rows; with multirate a slow row's rings
//! count only the whole passes, so the coarse organ round a refined spot
//! is hardly touched before the sample. The correction's own rows lie
//! within k rings of the first rows, so what is left for after the sample
//! is the outer part of its cone.

use super::Levels;
use crate::tensor_mass::kernel::Neighbours;

/// Not needed by the force at any sub-step.
const NEVER: i32 = -1;

/// Each row's last sub-step the force needs, preallocated (a step
/// allocates nothing).
#[derive(Debug, Default)]
pub(super) struct Reach {
    /// Per vertex: the last sub-step whose value the force needs
    /// ([`NEVER`]: none).
    last: Vec<i32>,
    /// The vertices whose `last` is set.
    found: Vec<u32>,
}

impl Reach {
    /// For `n` vertices.
    pub(super) fn new(n: usize) -> Self {
        Self {
            last: vec![NEVER; n],
            found: Vec::with_capacity(n),
        }
    }

    /// Finds every row's last needed sub-step for a step of `substeps`
    /// whose first rows are `from` (see the module docs).
    pub(super) fn measure(
        &mut self,
        neighbours: &Neighbours,
        levels: &Levels<'_>,
        from: &[u32],
        substeps: usize,
    ) {
        self.clear();
        if self.last.is_empty() || substeps == 0 {
            return;
        }
        let end = substeps as i32 - 1;
        for &v in from {
            self.raise(v, end);
        }
        // Their neighbours at the end (a grip's elastic force).
        for f in 0..self.found.len() {
            let i = self.found[f] as usize;
            for &j in neighbours.of(i) {
                self.raise(j, end);
            }
        }
        // Backwards, each row once, at its final `last`: a raise from a row
        // at `l` is at most `l - 1`, so a level is complete when reached.
        for level in (1..=end).rev() {
            let mut f = 0;
            while f < self.found.len() {
                let i = self.found[f] as usize;
                f += 1;
                if self.last[i] != level {
                    continue;
                }
                let read_at = if levels.is_fast(i) {
                    level
                } else {
                    level - level % levels.m as i32
                };
                if read_at < 1 {
                    continue;
                }
                for &j in neighbours.of(i) {
                    self.raise(j, read_at - 1);
                }
            }
        }
    }

    fn raise(&mut self, v: u32, to: i32) {
        let last = &mut self.last[v as usize];
        if *last == NEVER {
            self.found.push(v);
        }
        *last = (*last).max(to);
    }

    /// Whether the force needs vertex `i`'s value of sub-step `k` (every
    /// vertex's, when nothing was measured: never too few rows).
    pub(super) fn near(&self, i: usize, k: usize) -> bool {
        self.last.get(i).is_none_or(|&l| l >= k as i32)
    }

    /// Forgets what was measured (only the vertices set are reset).
    pub(super) fn clear(&mut self) {
        for &v in &self.found {
            self.last[v as usize] = NEVER;
        }
        self.found.clear();
    }
}
