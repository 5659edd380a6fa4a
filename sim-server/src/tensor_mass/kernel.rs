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

use super::model::{CutChange, ElasticModel};
use crate::math::{Mat3, Real};

/// Storage precision of the kernel's tensors. State (displacements, forces)
/// is always `f64`.
pub trait Storage: Copy + Default + Send + Sync + std::fmt::Debug + 'static {
    /// `"f32"` or `"f64"`.
    const NAME: &'static str;
    /// Rounds from f64.
    fn from_real(x: Real) -> Self;
    /// Widens to f64.
    fn to_real(self) -> Real;
}

impl Storage for f32 {
    const NAME: &'static str = "f32";
    #[inline(always)]
    fn from_real(x: Real) -> Self {
        x as f32
    }
    #[inline(always)]
    fn to_real(self) -> Real {
        self as Real
    }
}

impl Storage for f64 {
    const NAME: &'static str = "f64";
    #[inline(always)]
    fn from_real(x: Real) -> Self {
        x
    }
    #[inline(always)]
    fn to_real(self) -> Real {
        self
    }
}

/// A 3-vector of state.
pub type V3 = [Real; 3];

/// A 3x3 block, row-major.
pub type Block<S> = [S; 9];

fn pack<S: Storage>(m: &Mat3) -> Block<S> {
    let r = m.transpose().to_cols_array();
    r.map(S::from_real)
}

/// y = K x for a row-major block.
#[inline(always)]
fn mul<S: Storage>(k: &Block<S>, x: &V3) -> V3 {
    let k = k.map(S::to_real);
    [
        k[0] * x[0] + k[1] * x[1] + k[2] * x[2],
        k[3] * x[0] + k[4] * x[1] + k[5] * x[2],
        k[6] * x[0] + k[7] * x[1] + k[8] * x[2],
    ]
}

/// y = K^T x for a row-major block.
#[inline(always)]
fn mul_t<S: Storage>(k: &Block<S>, x: &V3) -> V3 {
    let k = k.map(S::to_real);
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

/// The stiffness in compressed upper rows.
#[derive(Clone, Debug)]
pub struct Kernel<S: Storage> {
    diag: Vec<Block<S>>,
    row_start: Vec<u32>,
    col: Vec<u32>,
    val: Vec<Block<S>>,
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
            diag: model.vertex_tensors().iter().map(pack).collect(),
            row_start,
            col: edges.iter().map(|[_, b]| b.0).collect(),
            val: model.edge_tensors().iter().map(pack).collect(),
        }
    }

    /// Copies the 4 vertex and 6 edge tensors a cut changed.
    pub fn update(&mut self, model: &ElasticModel, change: &CutChange) {
        for v in change.vertices {
            self.diag[v.idx()] = pack(&model.vertex_tensors()[v.idx()]);
        }
        for e in change.edges {
            self.val[e.idx()] = pack(&model.edge_tensors()[e.idx()]);
        }
    }

    /// Number of rows (vertices).
    pub fn rows(&self) -> usize {
        self.diag.len()
    }

    /// Number of stored edge blocks.
    pub fn blocks(&self) -> usize {
        self.val.len()
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
            self.col[r.end - 1] as usize
        }
    }

    /// Bytes of tensor and index data the kernel streams per pass.
    pub fn bytes(&self) -> usize {
        let block = 9 * std::mem::size_of::<S>();
        self.diag.len() * block
            + self.row_start.len() * 4
            + self.col.len() * 4
            + self.val.len() * block
    }

    /// K u into `out` (a plain, unfused product, for tests and power iteration).
    pub fn apply(&self, u: &[V3], out: &mut [V3]) {
        for (i, o) in out.iter_mut().enumerate() {
            *o = mul(&self.diag[i], &u[i]);
        }
        for i in 0..self.rows() {
            for s in self.row(i) {
                let j = self.col[s] as usize;
                let a = mul(&self.val[s], &u[j]);
                add(&mut out[i], a);
                let b = mul_t(&self.val[s], &u[i]);
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
}

impl StepInputs<'_> {
    /// Finishes vertex `i`: `ku` is its final (K U)_i, `next` holds U_i(t-1)
    /// on entry and U_i(t+1) on exit.
    #[inline(always)]
    pub fn integrate(&self, i: usize, ku: V3, next: &mut V3) {
        match self.kind[i] {
            kind::FREE => {
                let [a, b, c] = self.coef[i];
                let u = self.u[i];
                let fe = self.fext.get(i).copied().unwrap_or([0.0; 3]);
                for d in 0..3 {
                    next[d] = a * (fe[d] - ku[d]) + b * u[d] - c * next[d];
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
    /// K U accumulators of rows `start..end` (zero on entry except for
    /// scatter from this part, left zero on exit except deferred rows).
    pub ku: &'a mut [V3],
    /// U(t-1) on entry, U(t+1) on exit, rows `start..end`.
    pub next: &'a mut [V3],
    /// Scatter into rows `end..end + spill.len()`.
    pub spill: &'a mut [V3],
}

impl<S: Storage> Kernel<S> {
    /// The fused pass over one part's rows.
    pub fn run_part(&self, inp: &StepInputs<'_>, part: Part<'_>) {
        let Part {
            start,
            end,
            deferred_end,
            ku,
            next,
            spill,
        } = part;
        let u = inp.u;
        for i in start..end {
            let li = i - start;
            let ui = u[i];
            let mut acc = ku[li];
            add(&mut acc, mul(&self.diag[i], &ui));
            for s in self.row(i) {
                let j = self.col[s] as usize;
                let k = &self.val[s];
                add(&mut acc, mul(k, &u[j]));
                let t = mul_t(k, &ui);
                if j < end {
                    add(&mut ku[j - start], t);
                } else {
                    add(&mut spill[j - end], t);
                }
            }
            if i < deferred_end {
                ku[li] = acc;
            } else {
                ku[li] = [0.0; 3];
                inp.integrate(i, acc, &mut next[li]);
            }
        }
    }
}
