//! The hot stiffness kernel: the model's tensors copied into compressed rows
//! (one row per vertex, holding the edges to higher-numbered neighbours), in
//! `f32` or `f64` storage, and the fused step that computes K U and advances
//! the central-difference integration in one pass over memory.
//!
//! Row `i` reads U_j only for j >= i and scatters K_ij^T U_i only into rows
//! j > i. So once row `i` is processed its K U is final and its new
//! displacement can be written at once (into the buffer that held U(t-1)),
//! and threads that own contiguous row ranges only meet where a row's edges
//! reach past its range: those contributions go to a per-thread spill buffer
//! and the few rows they reach are finished after the join. No atomics.

use super::huge_pages::collect_huge;
use super::model::{CutChange, ElasticModel};
use crate::math::Real;
pub(in crate::tensor_mass) use rows::{LowerRows, Neighbours, row_product};
#[cfg(target_arch = "x86_64")]
pub use storage::Windows;
use storage::pack;
pub(super) use storage::widen;
pub use storage::{Block, LanePrecision, Storage};

/// A 3-vector of state.
pub type V3 = [Real; 3];

/// A ring accumulator: a 3-vector padded to 4 lanes for SIMD.
pub type R4 = [Real; 4];

/// y = K x for a row-major block.
#[inline(always)]
fn mul<S: Storage>(k: &Block<S>, x: &V3) -> V3 {
    let k = widen(k);
    [
        k[0] * x[0] + k[1] * x[1] + k[2] * x[2],
        k[3] * x[0] + k[4] * x[1] + k[5] * x[2],
        k[6] * x[0] + k[7] * x[1] + k[8] * x[2],
    ]
}

/// y = K^T x for a row-major block.
#[inline(always)]
fn mul_t<S: Storage>(k: &Block<S>, x: &V3) -> V3 {
    let k = widen(k);
    [
        k[0] * x[0] + k[3] * x[1] + k[6] * x[2],
        k[1] * x[0] + k[4] * x[1] + k[7] * x[2],
        k[2] * x[0] + k[5] * x[1] + k[8] * x[2],
    ]
}

#[inline(always)]
fn add(a: &mut V3, b: V3) {
    a[0] += b[0];
    a[1] += b[1];
    a[2] += b[2];
}

/// One off-diagonal block with its column, stored together so the step
/// reads one stream for the edges (40 bytes in f32).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct EdgeBlock<S: Storage> {
    /// K_ij, row-major.
    pub k: Block<S>,
    /// j.
    pub col: u32,
}

/// The stiffness in compressed upper rows.
#[derive(Clone, Debug)]
pub struct Kernel<S: Storage> {
    diag: Vec<Block<S>>,
    row_start: Vec<u32>,
    edges: Vec<EdgeBlock<S>>,
    /// Largest j - i over the edges: how far ahead a row scatters.
    span: usize,
    /// What the tensors hold.
    holds: Holds,
}

/// What a kernel's tensors hold.
#[derive(Clone, Debug)]
enum Holds {
    /// The model's tensors: every element's, and a linear capsule's.
    Elastic,
    /// Only a linear capsule membrane's springs, and where they sit (every
    /// element is nonlinear and computes its whole force in the nonlinear
    /// pass): see [`Kernel::beside_whole_forces`].
    Membrane(membrane::MembraneRows),
    /// Nothing (every element nonlinear, no linear capsule): K u = 0, and
    /// cuts change nothing.
    Nothing,
}

impl<S: Storage> Kernel<S> {
    /// Copies the model's tensors. Edge ids are already sorted by (a, b), so
    /// an edge's id is its slot.
    pub fn new(model: &ElasticModel) -> Self {
        let n = model.vertex_count();
        let edges = model.topology().edges();
        let mut row_start = vec![0u32; n + 1];
        for [a, _] in edges {
            row_start[a.idx() + 1] += 1;
        }
        for i in 0..n {
            row_start[i + 1] += row_start[i];
        }
        Self {
            diag: collect_huge(n, model.vertex_tensors().iter().map(pack)),
            row_start,
            edges: collect_huge(
                edges.len(),
                edges
                    .iter()
                    .zip(model.edge_tensors())
                    .map(|([_, b], k)| EdgeBlock {
                        k: pack(k),
                        col: b.0,
                    }),
            ),
            span: edges
                .iter()
                .map(|[a, b]| (b.0 - a.0) as usize)
                .max()
                .unwrap_or(0),
            holds: Holds::Elastic,
        }
    }

    /// A kernel without elastic tensors for `n` vertices: K u = 0, so the
    /// step only integrates the other forces (for a model whose every
    /// element is nonlinear: the nonlinear pass then computes the whole
    /// elastic force, and streaming the linear tensors only to cancel them
    /// would cost the linear step again).
    pub fn without_elastic(n: usize) -> Self {
        Self {
            diag: collect_huge(n, std::iter::repeat_n([S::default(); 9], n)),
            row_start: vec![0; n + 1],
            edges: Vec::new(),
            span: 0,
            holds: Holds::Nothing,
        }
    }

    /// Whether it holds the elastic tensors.
    pub fn is_elastic(&self) -> bool {
        matches!(self.holds, Holds::Elastic)
    }

    /// Copies the 4 vertex and 6 edge tensors a cut changed (the capsule's
    /// springs alone in a kernel that holds only those).
    pub fn update(&mut self, model: &ElasticModel, change: &CutChange) {
        if !self.is_elastic() {
            self.update_capsule(model, change);
            return;
        }
        for v in change.vertices {
            self.diag[v.idx()] = pack(&model.vertex_tensors()[v.idx()]);
        }
        for e in change.edges {
            self.edges[e.idx()].k = pack(&model.edge_tensors()[e.idx()]);
        }
    }

    /// Number of rows (vertices).
    pub fn rows(&self) -> usize {
        self.diag.len()
    }

    /// Number of stored edge blocks.
    pub fn blocks(&self) -> usize {
        self.edges.len()
    }

    /// Largest j - i over the edges.
    pub fn span(&self) -> usize {
        self.span
    }

    /// The edges of row `i` as a slot range.
    #[inline(always)]
    pub fn row(&self, i: usize) -> std::ops::Range<usize> {
        self.row_start[i] as usize..self.row_start[i + 1] as usize
    }

    /// Highest column reached by row `i` (or `i` itself).
    pub fn reach(&self, i: usize) -> usize {
        let r = self.row(i);
        if r.is_empty() {
            i
        } else {
            self.edges[r.end - 1].col as usize
        }
    }

    /// Bytes of tensor and index data the kernel streams per pass.
    pub fn bytes(&self) -> usize {
        self.diag.len() * std::mem::size_of::<Block<S>>()
            + self.row_start.len() * 4
            + self.edges.len() * std::mem::size_of::<EdgeBlock<S>>()
    }

    /// K u into `out` (a plain, unfused product, for tests and power iteration).
    pub fn apply(&self, u: &[V3], out: &mut [V3]) {
        for (i, o) in out.iter_mut().enumerate() {
            *o = mul(&self.diag[i], &u[i]);
        }
        for i in 0..self.rows() {
            for e in &self.edges[self.row(i)] {
                let j = e.col as usize;
                let a = mul(&e.k, &u[j]);
                add(&mut out[i], a);
                let b = mul_t(&e.k, &u[i]);
                add(&mut out[j], b);
            }
        }
    }
}

/// Vertex kinds in the integration.
pub mod kind {
    /// Integrated.
    pub const FREE: u8 = 0;
    /// Displacement imposed (fixed = imposed zero).
    pub const PRESCRIBED: u8 = 1;
    /// No live tetrahedron: held where it is.
    pub const INACTIVE: u8 = 2;
}

/// Per-vertex integration data shared read-only by all threads during a step.
pub struct StepInputs<'a> {
    /// U(t).
    pub u: &'a [V3],
    /// (a, b, c): U(t+1) = a F + b U(t) - c U(t-1).
    pub coef: &'a [V3],
    /// [`kind`] of each vertex.
    pub kind: &'a [u8],
    /// Imposed displacements (read for PRESCRIBED vertices).
    pub target: &'a [V3],
    /// External forces (N); empty when there are none.
    pub fext: &'a [V3],
    /// Nonlinear membrane forces (N); empty without a nonlinear membrane.
    pub fmem: &'a [V3],
    /// Nonlinear elements' forces (N): corrections to the linear ones, or
    /// whole forces beside a kernel without tensors; empty without them.
    pub fnl: &'a [V3],
}

impl StepInputs<'_> {
    /// Hints the cache to fetch the imposed displacement of the vertex a few
    /// rows on when it has one: held vertices are scattered through the
    /// numbering, so each read of `target` would otherwise miss (14% of the
    /// step on the 1M-tetrahedron box, per `perf annotate`).
    #[inline(always)]
    pub fn prefetch_ahead(&self, i: usize) {
        const AHEAD: usize = 16;
        if self.kind.get(i + AHEAD) == Some(&kind::PRESCRIBED) {
            prefetch_at(self.target, i + AHEAD);
        }
    }

    /// Finishes vertex `i`: `ku` is its final (K U)_i, `next` holds U_i(t-1)
    /// on entry and U_i(t+1) on exit.
    #[inline(always)]
    pub fn integrate(&self, i: usize, ku: V3, next: &mut V3) {
        match self.kind[i] {
            kind::FREE => {
                let [a, b, c] = self.coef[i];
                let u = self.u[i];
                let fe = self.fext.get(i).copied().unwrap_or([0.0; 3]);
                let fm = self.fmem.get(i).copied().unwrap_or([0.0; 3]);
                let fl = self.fnl.get(i).copied().unwrap_or([0.0; 3]);
                for d in 0..3 {
                    next[d] = a * (fe[d] + fm[d] + fl[d] - ku[d]) + b * u[d] - c * next[d];
                }
            }
            kind::PRESCRIBED => *next = self.target[i],
            _ => *next = self.u[i],
        }
    }
}

/// One thread's share of a step.
pub struct Part<'a> {
    /// First row.
    pub start: usize,
    /// One past the last row.
    pub end: usize,
    /// Rows `start..deferred_end` get contributions from earlier parts and are
    /// finished after the join.
    pub deferred_end: usize,
    /// K U accumulators of the rows in flight, indexed by row modulo its
    /// length (a power of two above the kernel's span + 1): they stay in cache
    /// instead of streaming an n-long array. All zero on entry and exit.
    pub ring: &'a mut [R4],
    /// Final K U of the deferred rows (`start..deferred_end`), without the
    /// contributions of earlier parts.
    pub deferred: &'a mut [V3],
    /// U(t-1) on entry, U(t+1) on exit, rows `start..end` (deferred rows untouched).
    pub next: &'a mut [V3],
    /// Scatter into rows `end..end + spill.len()` (overwritten).
    pub spill: &'a mut [V3],
}

/// Hints the cache to fetch the block `AHEAD` edges on: the edge stream is
/// the largest and the hardware prefetcher alone leaves it partly exposed.
#[inline(always)]
fn prefetch<T>(slice: &[T], at: usize) {
    const AHEAD: usize = 32;
    prefetch_at(slice, at + AHEAD);
}

/// Hints the cache to fetch `slice[at]` (nothing past the end).
#[inline(always)]
fn prefetch_at<T>(slice: &[T], at: usize) {
    #[cfg(target_arch = "x86_64")]
    if let Some(x) = slice.get(at) {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: SSE is part of the x86_64 baseline, and a prefetch only
        // hints the cache: it never faults or changes memory.
        unsafe { _mm_prefetch::<_MM_HINT_T0>((x as *const T).cast::<i8>()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (slice, at);
}

impl<S: Storage> Kernel<S> {
    /// The ring length the step needs: a power of two above span + 1 (the AVX2 pass finishes a row one row late).
    pub fn ring_len(&self) -> usize {
        (self.span + 2).next_power_of_two()
    }

    /// The fused pass over one part's rows.
    ///
    /// Written elementwise on the 9 entries of each block so that the
    /// compiler vectorises it: K u_j accumulates as K (o) [u_j u_j u_j] into a
    /// 3x3 that is reduced once per row, and K^T u_i is the sum of the rows of
    /// K (o) [u_i0 x3, u_i1 x3, u_i2 x3].
    pub fn run_part(&self, inp: &StepInputs<'_>, part: Part<'_>) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            unsafe { avx2::run_part(self, inp, part) };
            return;
        }
        self.run_part_body(inp, part);
    }

    /// Diagonal blocks, row pointers and edge records, for the SIMD path.
    pub(super) fn parts(&self) -> (&[Block<S>], &[u32], &[EdgeBlock<S>]) {
        (&self.diag, &self.row_start, &self.edges)
    }

    /// The pass without the AVX2 dispatch (the path of CPUs without AVX2);
    /// public so tests can check both paths agree bit for bit.
    #[doc(hidden)]
    pub fn run_part_portable(&self, inp: &StepInputs<'_>, part: Part<'_>) {
        self.run_part_body(inp, part);
    }

    #[inline(always)]
    pub(super) fn run_part_body(&self, inp: &StepInputs<'_>, part: Part<'_>) {
        let Part {
            start,
            end,
            deferred_end,
            ring,
            deferred,
            next,
            spill,
        } = part;
        let mask = ring.len() - 1;
        assert!(ring.len().is_power_of_two() && ring.len() > self.span && spill.len() <= self.span);
        // Indexing a slice of exactly mask + 1 with `& mask` lets the
        // compiler drop the bounds check.
        let ring = &mut ring[..=mask];
        let u = inp.u;
        let tile = |v: V3| [v[0], v[1], v[2], v[0], v[1], v[2], v[0], v[1], v[2]];
        for i in start..end {
            inp.prefetch_ahead(i);
            let ui = u[i];
            let ti = [
                ui[0], ui[0], ui[0], ui[1], ui[1], ui[1], ui[2], ui[2], ui[2],
            ];
            let d = widen(&self.diag[i]);
            let tu = tile(ui);
            let mut m = [0.0; 9];
            for q in 0..9 {
                m[q] = d[q] * tu[q];
            }
            let r = self.row(i);
            let first = r.start;
            for (s, e) in self.edges[r].iter().enumerate() {
                prefetch(&self.edges, first + s);
                let j = e.col as usize;
                let k = widen(&e.k);
                let tj = tile(u[j]);
                let mut t = [0.0; 9];
                for q in 0..9 {
                    m[q] += k[q] * tj[q];
                    t[q] = k[q] * ti[q];
                }
                let kt = [t[0] + t[3] + t[6], t[1] + t[4] + t[7], t[2] + t[5] + t[8]];
                // Rows past the part's end also accumulate in the ring (their
                // slots are free: j - i <= span < ring length); they are moved
                // to the spill once the part is done.
                let slot = &mut ring[j & mask];
                for d in 0..3 {
                    slot[d] += kt[d];
                }
            }
            let slot = &mut ring[i & mask];
            let mut acc = [slot[0], slot[1], slot[2]];
            *slot = [0.0; 4];
            add(
                &mut acc,
                [m[0] + m[1] + m[2], m[3] + m[4] + m[5], m[6] + m[7] + m[8]],
            );
            if i < deferred_end {
                deferred[i - start] = acc;
            } else {
                inp.integrate(i, acc, &mut next[i - start]);
            }
        }
        for (r, sp) in spill.iter_mut().enumerate() {
            let slot = &mut ring[(end + r) & mask];
            *sp = [slot[0], slot[1], slot[2]];
            *slot = [0.0; 4];
        }
    }
}

#[cfg(target_arch = "x86_64")]
pub(in crate::tensor_mass) mod avx2;
mod rows;
mod storage;

mod membrane;

#[cfg(test)]
mod tests;
