//! The nonlinear elements as blocks of lanes: their rest data, the pass
//! over them (split into tasks on the pool, each leaf a run of blocks) and
//! where each block's forces go (per-block slots summed by one sweep, or,
//! for one task of eight f32 lanes with AVX2, straight onto per-vertex
//! accumulators). A part of [`super`], which owns the elements.

use super::super::corotational_lanes::{Q, corotational_block};
use super::super::kernel::V3;
#[cfg(target_arch = "x86_64")]
use super::super::lanes::as_f32x8;
#[cfg(target_arch = "x86_64")]
use super::super::lanes::avx2 as lanes_avx2;
use super::super::lanes::{Acc, L, LaneBlock, Scalar};
use super::super::stvk_lanes::stvk_block;
use super::{Element, PassReport, element};
use crate::material::MaterialModel;
use crate::math::Real;
use glam::DQuat;

/// One block's corner forces, lane-wise: `[corner][coordinate][lane]`.
pub(super) type BlockForces<S, const N: usize> = [[L<S, N>; 3]; 4];

/// One element's four corner forces into lane `l` of its block.
pub(super) fn store_lane<S: Scalar, const N: usize>(
    block: &mut BlockForces<S, N>,
    l: usize,
    f: &[V3; 4],
) {
    for (k, fk) in f.iter().enumerate() {
        for (c, x) in fk.iter().enumerate() {
            block[k][c][l] = S::of(*x);
        }
    }
}

/// The elements as blocks of N lanes, their forces block by block (a pass
/// in tasks stores each block's forces with a few vector writes; the sweep
/// reads them in the same order; one task of eight f32 lanes adds them to
/// `acc` instead) and the corotational blocks' rotations.
#[derive(Clone, Debug)]
pub(super) struct LaneSet<S: Scalar, const N: usize> {
    /// Block k holds elements kN..(k+1)N (a last, short block is scalar).
    pub(super) blocks: Vec<Block<S, N>>,
    pub(super) forces: Vec<BlockForces<S, N>>,
    /// Per block: the corotational lanes' rotations (x, y, z, w), kept in
    /// lanes between passes (the scalar elements keep theirs as `DQuat`s).
    pub(super) quats: Vec<Q<S, N>>,
    /// Per vertex: the sum of its element forces while the AVX2 sweep adds
    /// them (eight f32 lanes only; empty otherwise).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub(super) acc: Vec<Acc>,
}

impl<S: Scalar, const N: usize> LaneSet<S, N> {
    pub(super) fn of(elements: &[Element]) -> Self {
        let blocks: Vec<Block<S, N>> = elements.chunks(N).map(Block::of).collect();
        let identity = [
            [S::default(); N],
            [S::default(); N],
            [S::default(); N],
            [S::of(1.0); N],
        ];
        let eight_f32 = N == 8 && std::any::TypeId::of::<S>() == std::any::TypeId::of::<f32>();
        let vertex_count = elements
            .iter()
            .flat_map(|e| e.vertices)
            .max()
            .map_or(0, |v| v as usize + 1);
        Self {
            acc: vec![Acc::default(); if eight_f32 { vertex_count } else { 0 }],
            forces: vec![[[[S::default(); N]; 3]; 4]; blocks.len()],
            quats: vec![identity; blocks.len()],
            blocks,
        }
    }

    /// Element `i`'s lane afresh: zero forces, the identity rotation.
    pub(super) fn forget(&mut self, i: usize) {
        store_lane(&mut self.forces[i / N], i % N, &[[0.0; 3]; 4]);
        let q = &mut self.quats[i / N];
        for (k, c) in q.iter_mut().enumerate() {
            c[i % N] = S::of(if k == 3 { 1.0 } else { 0.0 });
        }
    }

    /// Element `i`'s rotation if it is in a corotational lane block.
    #[cfg(test)]
    pub(super) fn rotation(&self, i: usize) -> Option<DQuat> {
        matches!(self.blocks[i / N], Block::Corotational(_)).then(|| {
            let q = &self.quats[i / N];
            let [x, y, z, w] = [0, 1, 2, 3].map(|k| q[k][i % N].real());
            DQuat::from_xyzw(x, y, z, w)
        })
    }

    /// out[v] = the sum of v's element forces (zeroed first for the
    /// `touched` vertices), added in element order.
    fn add_to_vertices(&mut self, elements: &[Element], touched: &[u32], out: &mut [V3]) {
        #[cfg(target_arch = "x86_64")]
        if N == 8
            && std::any::TypeId::of::<S>() == std::any::TypeId::of::<f32>()
            && std::arch::is_x86_feature_detected!("avx2")
        {
            // SAFETY: AVX2 is present (checked just above).
            unsafe { self.add_to_vertices_avx2(elements, touched, out) };
            return;
        }
        self.add_to_vertices_portable(elements, touched, out);
    }

    /// [`LaneSet::add_to_vertices`] one value at a time (every CPU; what
    /// the AVX2 sweep is tested equal to).
    pub(super) fn add_to_vertices_portable(
        &self,
        elements: &[Element],
        touched: &[u32],
        out: &mut [V3],
    ) {
        for &v in touched {
            out[v as usize] = [0.0; 3];
        }
        for (k, (block, f)) in self.blocks.iter().zip(&self.forces).enumerate() {
            let count = N.min(elements.len() - k * N);
            for l in 0..count {
                let vertices = match block {
                    Block::Stvk(b) | Block::Corotational(b) => &b.vertices[l],
                    Block::Scalar => &elements[k * N + l].vertices,
                };
                for (corner, &v) in vertices.iter().enumerate() {
                    let o = &mut out[v as usize];
                    for c in 0..3 {
                        o[c] += f[corner][c][l].real();
                    }
                }
            }
        }
    }

    /// [`LaneSet::add_to_vertices`] for eight f32 lanes: each block's
    /// stored forces through the one-task pass's sink ([`AddTo`]), the same
    /// sums to the bit.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn add_to_vertices_avx2(&mut self, elements: &[Element], touched: &[u32], out: &mut [V3]) {
        let (blocks, forces) = (&self.blocks, &self.forces);
        through_accumulators(&mut self.acc, touched, out, |acc| {
            let mut sink = AddTo(acc);
            for (k, (block, f)) in blocks.iter().zip(forces).enumerate() {
                let count = N.min(elements.len() - k * N);
                let vertices = match block {
                    Block::Stvk(b) | Block::Corotational(b) => b.vertices,
                    Block::Scalar => scalar_vertices(&elements[k * N..k * N + count]),
                };
                sink.take(k, &vertices, count, f);
            }
        });
    }

    /// Element `i`'s forces from its lane.
    #[cfg(test)]
    pub(super) fn load(&self, i: usize) -> [V3; 4] {
        let block = &self.forces[i / N];
        std::array::from_fn(|k| std::array::from_fn(|c| block[k][c][i % N].real()))
    }

    /// The pass over all elements, then the per-vertex sums into `out` at
    /// the `touched` vertices.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn pass(
        &mut self,
        elements: &[Element],
        alive: &[bool],
        rotations: &mut [DQuat],
        u: &[V3],
        min: usize,
        whole: bool,
        touched: &[u32],
        out: &mut [V3],
    ) -> PassReport {
        let range = Range {
            whole,
            elements,
            alive,
            rotations,
            blocks: &self.blocks,
            quats: &mut self.quats,
        };
        #[cfg(target_arch = "x86_64")]
        if elements.len() <= min
            && !self.acc.is_empty()
            && std::arch::is_x86_feature_detected!("avx2")
        {
            // One task of eight f32 lanes: forces added as they come.
            return through_accumulators(&mut self.acc, touched, out, |acc| {
                // SAFETY: the CPU supports AVX2 (checked just above).
                unsafe { leaf_avx2(range, u, &mut AddTo(acc)) }
            });
        }
        let report = element_range(range, &mut self.forces, u, min);
        self.add_to_vertices(elements, touched, out);
        report
    }
}

/// N consecutive elements as lanes, when they share a model.
#[derive(Clone, Debug)]
pub(super) enum Block<S: Scalar, const N: usize> {
    Stvk(LaneBlock<S, N>),
    Corotational(LaneBlock<S, N>),
    /// Mixed models: one element at a time.
    Scalar,
}

impl<S: Scalar, const N: usize> Block<S, N> {
    fn of(chunk: &[Element]) -> Self {
        let model = chunk[0].model;
        if chunk.len() < N || chunk.iter().any(|e| e.model != model) {
            return Block::Scalar;
        }
        match model {
            MaterialModel::Stvk => Block::Stvk(block(chunk)),
            MaterialModel::Corotational => Block::Corotational(block(chunk)),
            MaterialModel::Linear => Block::Scalar,
        }
    }
}

/// A contiguous range of whole blocks: their elements, blocks and lane
/// rotations, and the scalar elements' rotations.
struct Range<'a, S: Scalar, const N: usize> {
    /// Whole forces (P), not corrections (P - sigma_lin).
    whole: bool,
    elements: &'a [Element],
    alive: &'a [bool],
    rotations: &'a mut [DQuat],
    blocks: &'a [Block<S, N>],
    quats: &'a mut [Q<S, N>],
}

/// The elements of one range, split in halves (whole blocks) on the pool
/// down to `min`.
fn element_range<S: Scalar, const N: usize>(
    r: Range<'_, S, N>,
    forces: &mut [BlockForces<S, N>],
    u: &[V3],
    min: usize,
) -> PassReport {
    let half_blocks = r.blocks.len() / 2;
    let mid = half_blocks * N;
    if r.elements.len() > min && half_blocks > 0 {
        let (ea, eb) = r.elements.split_at(mid);
        let (la, lb) = r.alive.split_at(mid);
        let (ra, rb) = r.rotations.split_at_mut(mid);
        let (ba, bb) = r.blocks.split_at(half_blocks);
        let (fa, fb) = forces.split_at_mut(half_blocks);
        let (qa, qb) = r.quats.split_at_mut(half_blocks);
        let (a, b) = rayon::join(
            || {
                let range = Range {
                    whole: r.whole,
                    elements: ea,
                    alive: la,
                    rotations: ra,
                    blocks: ba,
                    quats: qa,
                };
                element_range(range, fa, u, min)
            },
            || {
                let range = Range {
                    whole: r.whole,
                    elements: eb,
                    alive: lb,
                    rotations: rb,
                    blocks: bb,
                    quats: qb,
                };
                element_range(range, fb, u, min)
            },
        );
        return a.join(b);
    }
    let mut sink = Store(forces);
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { leaf_avx2(r, u, &mut sink) };
    }
    leaf(r, u, &mut sink)
}

/// [`leaf`] compiled for AVX2 (the lanes become one 256-bit operation).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn leaf_avx2<S: Scalar, const N: usize, K: Sink<S, N>>(
    r: Range<'_, S, N>,
    u: &[V3],
    sink: &mut K,
) -> PassReport {
    leaf(r, u, sink)
}

/// Where a leaf puts each block's corner forces.
trait Sink<S: Scalar, const N: usize> {
    /// Block `k` of the leaf's range: `count` elements at `vertices`.
    fn take(&mut self, k: usize, vertices: &[[u32; 4]; N], count: usize, f: &BlockForces<S, N>);
}

/// Into the per-block force slots (tasks on several threads; the sweep
/// adds them up afterwards).
struct Store<'a, S: Scalar, const N: usize>(&'a mut [BlockForces<S, N>]);

impl<S: Scalar, const N: usize> Sink<S, N> for Store<'_, S, N> {
    #[inline(always)]
    fn take(&mut self, k: usize, _: &[[u32; 4]; N], _: usize, f: &BlockForces<S, N>) {
        self.0[k] = *f;
    }
}

/// Zeroes the `touched` vertices' accumulators, lets `fill` add the
/// element forces to them, and writes their sums to `out`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn through_accumulators<R>(
    acc: &mut [Acc],
    touched: &[u32],
    out: &mut [V3],
    fill: impl FnOnce(&mut [Acc]) -> R,
) -> R {
    for &v in touched {
        acc[v as usize] = Acc::default();
    }
    let result = fill(acc);
    for &v in touched {
        let [x, y, z, _] = acc[v as usize].0;
        out[v as usize] = [x, y, z];
    }
    result
}

/// The vertices of a scalar block's elements, lane by lane (the lanes past
/// them unused).
#[inline(always)]
fn scalar_vertices<const N: usize>(elements: &[Element]) -> [[u32; 4]; N] {
    let mut vertices = [[0; 4]; N];
    for (v, e) in vertices.iter_mut().zip(elements) {
        *v = e.vertices;
    }
    vertices
}

/// Straight onto the vertices' accumulators, in element order (one task
/// of eight f32 lanes with AVX2: the forces never go through memory; at
/// 1M tetrahedra the slots were 96 of the pass's ~240 bytes an element).
#[cfg(target_arch = "x86_64")]
struct AddTo<'a>(&'a mut [Acc]);

#[cfg(target_arch = "x86_64")]
impl<S: Scalar, const N: usize> Sink<S, N> for AddTo<'_> {
    #[inline(always)]
    fn take(&mut self, _: usize, vertices: &[[u32; 4]; N], count: usize, f: &BlockForces<S, N>) {
        let (Some(vertices), Some(f)) = (
            as_f32x8::<S, N, _, [[u32; 4]; 8]>(vertices),
            as_f32x8::<S, N, _, [[[f32; 8]; 3]; 4]>(f),
        ) else {
            unreachable!("used for eight f32 lanes only")
        };
        // SAFETY: used inside the AVX2 leaf only (the CPU has AVX2).
        unsafe { lanes_avx2::add_block(vertices, count, f, self.0) };
    }
}

/// One task's blocks: N StVK or N corotational elements as lanes, the
/// others one at a time.
// A scalar block's element l indexes four parallel buffers and a lane.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn leaf<S: Scalar, const N: usize, K: Sink<S, N>>(
    r: Range<'_, S, N>,
    u: &[V3],
    sink: &mut K,
) -> PassReport {
    let mut report = PassReport::default();
    // The lane blocks' largest bounds, reduced once at the end.
    let mut bound: L<S, N> = [S::default(); N];
    for (k, (block, q)) in r.blocks.iter().zip(r.quats.iter_mut()).enumerate() {
        let i = k * N;
        let alive = || std::array::from_fn(|l| r.alive[i + l]);
        let mut forces: BlockForces<S, N> = [[[S::default(); N]; 3]; 4];
        let count = N.min(r.elements.len() - i);
        match &block {
            Block::Stvk(b) => {
                report.collapsed += stvk_block(b, alive(), u, r.whole, &mut forces, &mut bound);
                sink.take(k, &b.vertices, count, &forces);
            }
            Block::Corotational(b) => {
                corotational_block(b, alive(), q, u, r.whole, &mut forces, &mut bound);
                sink.take(k, &b.vertices, count, &forces);
            }
            Block::Scalar => {
                for l in 0..count {
                    let mut f = [[0.0; 3]; 4];
                    if r.alive[i + l] {
                        let e = element(
                            &r.elements[i + l],
                            &mut r.rotations[i + l],
                            &mut f,
                            u,
                            r.whole,
                        );
                        report = report.join(e);
                    }
                    store_lane(&mut forces, l, &f);
                }
                let vertices = scalar_vertices(&r.elements[i..i + count]);
                sink.take(k, &vertices, count, &forces);
            }
        }
    }
    let lanes = PassReport {
        lambda: bound.iter().map(|b| b.real()).fold(0.0, Real::max),
        collapsed: 0,
    };
    report.join(lanes)
}

/// N elements' rest data as lanes.
pub(super) fn block<S: Scalar, const N: usize>(chunk: &[Element]) -> LaneBlock<S, N> {
    let lanes =
        |f: &dyn Fn(&Element) -> Real| -> [S; N] { std::array::from_fn(|k| S::of(f(&chunk[k]))) };
    let fiber = |e: &Element| e.elastic.fiber;
    LaneBlock {
        vertices: std::array::from_fn(|k| chunk[k].vertices),
        m: std::array::from_fn(|k| std::array::from_fn(|c| lanes(&|e| e.geom.shape[k + 1][c]))),
        volume: lanes(&|e| e.geom.volume_m3),
        lambda: lanes(&|e| e.elastic.lambda_pa),
        mu: lanes(&|e| e.elastic.mu_pa),
        dir: std::array::from_fn(|c| lanes(&|e| fiber(e).map_or(0.0, |f| f.dir[c]))),
        stretch: lanes(&|e| fiber(e).map_or(0.0, |f| f.stretch_pa)),
        cross: lanes(&|e| fiber(e).map_or(0.0, |f| f.cross_pa)),
        shear: lanes(&|e| fiber(e).map_or(0.0, |f| f.shear_pa)),
        rest_lambda: lanes(&|e| e.rest_lambda),
        geometric: lanes(&|e| e.geometric_per_pa),
    }
}
