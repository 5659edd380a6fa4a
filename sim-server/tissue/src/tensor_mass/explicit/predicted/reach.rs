//! Which rows a step's force can depend on: the rest of the correction
//! can wait until the force sample is out.
//!
//! A row of sub-step `k` reads its neighbours' values of sub-step `k - 1`
//! (one ring), so the force the tools feel after a step of S sub-steps
//! (the contact field, evaluated at every sub-step on its points'
//! vertices, and the elastic force at a grip's vertices, one ring more
//! at the end) depends on sub-step `k` only within S - k rings of the
//! step's first rows (the contact vertices and the vertices whose
//! constraint or load changed). The correction's own rows lie within
//! `k` rings of them, so the rows the force needs are the diamond
//! `d <= min(k, S - k)`, at most S / 2 rings wide, where the whole
//! correction's cone is S rings wide at its end. On a refined liver (6
//! to 10 sub-steps a millisecond) that is a third or less of its rows.
//!
//! The distance is the graph distance through the kernel's edges (every
//! vertex, fast or slow: a fine sub-step that moves only the fast rows
//! makes the true dependency narrower, never wider).

use crate::tensor_mass::kernel::{Kernel, LowerRows, Storage};

/// Ring distances from the step's first rows, measured up to a depth,
/// preallocated (a step allocates nothing).
#[derive(Debug, Default)]
pub(super) struct Reach {
    /// Per vertex: rings from the first rows; `u16::MAX` beyond the depth.
    dist: Vec<u16>,
    /// The vertices whose distance is set, in the order found.
    found: Vec<u32>,
}

impl Reach {
    /// For `n` vertices.
    pub(super) fn new(n: usize) -> Self {
        Self {
            dist: vec![u16::MAX; n],
            found: Vec::with_capacity(n),
        }
    }

    /// Measures the distance of every vertex within `depth` rings of
    /// `from` (breadth first).
    pub(super) fn measure<S: Storage>(
        &mut self,
        kernel: &Kernel<S>,
        lower: &LowerRows,
        from: &[u32],
        depth: usize,
    ) {
        self.clear();
        for &v in from {
            if self.dist[v as usize] == u16::MAX {
                self.dist[v as usize] = 0;
                self.found.push(v);
            }
        }
        let (_, _, edges) = kernel.parts();
        let depth = depth.min(u16::MAX as usize - 1) as u16;
        let mut at = 0;
        while at < self.found.len() {
            let i = self.found[at] as usize;
            at += 1;
            let d = self.dist[i];
            if d >= depth {
                continue;
            }
            let mut reach = |j: u32| {
                if self.dist[j as usize] == u16::MAX {
                    self.dist[j as usize] = d + 1;
                    self.found.push(j);
                }
            };
            for e in &edges[kernel.row(i)] {
                reach(e.col);
            }
            for &[j, _] in lower.of(i) {
                reach(j);
            }
        }
    }

    /// Whether vertex `i` is within `rings` of the first rows (every
    /// vertex is when nothing was measured: never too few rows).
    pub(super) fn near(&self, i: usize, rings: usize) -> bool {
        self.dist
            .get(i)
            .is_none_or(|&d| d != u16::MAX && (d as usize) <= rings)
    }

    /// Forgets the distances (only those set are reset).
    pub(super) fn clear(&mut self) {
        for &v in &self.found {
            self.dist[v as usize] = u16::MAX;
        }
        self.found.clear();
    }
}
