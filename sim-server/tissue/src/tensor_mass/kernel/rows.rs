//! One row of the kernel's product K u, computed alone in exactly the
//! fused pass's order of additions: for the predicted step's local
//! corrector (`explicit/predicted/`) and the membrane's capsule rows
//! ([`super::membrane`]), each of which must equal the whole pass to the
//! bit.

#[cfg(target_arch = "x86_64")]
use super::avx2::{lanes, load3};
use super::{Kernel, Storage, V3, widen};
#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// The kernel's edges seen from their column: for each vertex `i`, the
/// rows `j < i` whose stored edge reaches it, ascending (the order in
/// which the pass scatters them into row `i`), with the edge's slot.
#[derive(Clone, Debug, Default)]
pub(in crate::tensor_mass) struct LowerRows {
    start: Vec<u32>,
    /// (row j, edge slot).
    entries: Vec<[u32; 2]>,
}

impl LowerRows {
    /// Built once per kernel: cuts change the tensors' values, never the
    /// edges' places.
    pub(in crate::tensor_mass) fn new<S: Storage>(kernel: &Kernel<S>) -> Self {
        let n = kernel.rows();
        let (_, _, edges) = kernel.parts();
        let mut start = vec![0u32; n + 1];
        for e in edges {
            start[e.col as usize + 1] += 1;
        }
        for i in 0..n {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut entries = vec![[0u32; 2]; edges.len()];
        for j in 0..n {
            for slot in kernel.row(j) {
                let i = edges[slot].col as usize;
                entries[fill[i] as usize] = [j as u32, slot as u32];
                fill[i] += 1;
            }
        }
        Self { start, entries }
    }

    /// Row `i`'s entries: (lower row j, edge slot), ascending j.
    pub(in crate::tensor_mass) fn of(&self, i: usize) -> &[[u32; 2]] {
        &self.entries[self.start[i] as usize..self.start[i + 1] as usize]
    }

    /// Whether it was built for a kernel of `rows` rows.
    pub(in crate::tensor_mass) fn fits(&self, rows: usize) -> bool {
        self.start.len() == rows + 1
    }
}

/// Each vertex's neighbours through the kernel's edges, both directions,
/// as one compact list: the correction's bookkeeping walks these for every
/// row it marks, and reading them from the edge records (40 bytes a block
/// in f32) and the lower rows pulled the whole tensor stream through the
/// cache for four bytes of each record.
#[derive(Clone, Debug, Default)]
pub(in crate::tensor_mass) struct Neighbours {
    start: Vec<u32>,
    of: Vec<u32>,
}

impl Neighbours {
    /// Built once per kernel, beside its [`LowerRows`] (cuts change the
    /// tensors' values, never the edges' places): row `i`'s upper columns
    /// ascending, then its lower rows ascending.
    pub(in crate::tensor_mass) fn new<S: Storage>(kernel: &Kernel<S>, lower: &LowerRows) -> Self {
        let n = kernel.rows();
        let (_, _, edges) = kernel.parts();
        let mut start = Vec::with_capacity(n + 1);
        let mut of = Vec::with_capacity(2 * edges.len());
        start.push(0);
        for i in 0..n {
            of.extend(edges[kernel.row(i)].iter().map(|e| e.col));
            of.extend(lower.of(i).iter().map(|&[j, _]| j));
            start.push(of.len() as u32);
        }
        Self { start, of }
    }

    /// Vertex `i`'s neighbours.
    #[inline]
    pub(in crate::tensor_mass) fn of(&self, i: usize) -> &[u32] {
        &self.of[self.start[i] as usize..self.start[i + 1] as usize]
    }
}

/// (K u)_i, added up exactly as the fused pass does (`Kernel::run_part_body`,
/// which the AVX2 pass equals to the bit): the lower rows' K_ji^T u_j in
/// ascending j into a zeroed accumulator, then the row's own products,
/// entry by entry, reduced once and added.
///
/// With AVX2, the pass's own vectors (`row_product_avx2`, the same bits):
/// a gathered row cost about 3 streamed ones in scalar code, and the
/// predicted step's correction after the pose is all gathered rows.
#[inline]
pub(in crate::tensor_mass) fn row_product<S: Storage>(
    kernel: &Kernel<S>,
    lower: &LowerRows,
    u: &[V3],
    i: usize,
) -> V3 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { row_product_avx2(kernel, lower, u, i) };
    }
    row_product_portable(kernel, lower, u, i)
}

/// [`row_product`] without the AVX2 dispatch (the path of CPUs without
/// AVX2; the tests check both agree bit for bit).
#[inline]
pub(in crate::tensor_mass) fn row_product_portable<S: Storage>(
    kernel: &Kernel<S>,
    lower: &LowerRows,
    u: &[V3],
    i: usize,
) -> V3 {
    let (diag, _, edges) = kernel.parts();
    let mut acc = [0.0; 3];
    for &[j, slot] in lower.of(i) {
        let k = widen(&edges[slot as usize].k);
        let uj = u[j as usize];
        let tj = [
            uj[0], uj[0], uj[0], uj[1], uj[1], uj[1], uj[2], uj[2], uj[2],
        ];
        let mut t = [0.0; 9];
        for q in 0..9 {
            t[q] = k[q] * tj[q];
        }
        acc[0] += t[0] + t[3] + t[6];
        acc[1] += t[1] + t[4] + t[7];
        acc[2] += t[2] + t[5] + t[8];
    }
    let tile = |v: V3| [v[0], v[1], v[2], v[0], v[1], v[2], v[0], v[1], v[2]];
    let d = widen(&diag[i]);
    let tu = tile(u[i]);
    let mut m = [0.0; 9];
    for q in 0..9 {
        m[q] = d[q] * tu[q];
    }
    for e in &edges[kernel.row(i)] {
        let k = widen(&e.k);
        let tj = tile(u[e.col as usize]);
        for q in 0..9 {
            m[q] += k[q] * tj[q];
        }
    }
    acc[0] += m[0] + m[1] + m[2];
    acc[1] += m[3] + m[4] + m[5];
    acc[2] += m[6] + m[7] + m[8];
    acc
}

#[cfg(target_arch = "x86_64")]
/// [`row_product`] with the pass's vectors (`avx2.rs`): the lower rows'
/// K_ji^T u_j added in ascending j into a zeroed accumulator, then the
/// row's own products reduced once, the same operations in the same order
/// as the portable row, so the same bits.
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
unsafe fn row_product_avx2<S: Storage>(
    kernel: &Kernel<S>,
    lower: &LowerRows,
    u: &[V3],
    i: usize,
) -> V3 {
    let (diag, _, edges) = kernel.parts();
    let mut acc = _mm256_setzero_pd();
    for &[j, slot] in lower.of(i) {
        let uj = &u[j as usize];
        // SAFETY: AVX2 is enabled for this function.
        let (k0, k1, k2) = unsafe { S::rows(&edges[slot as usize].k) };
        // (t0 + t3) + t6 and so on: the portable row's order.
        let kt = _mm256_add_pd(
            _mm256_add_pd(
                _mm256_mul_pd(k0, _mm256_set1_pd(uj[0])),
                _mm256_mul_pd(k1, _mm256_set1_pd(uj[1])),
            ),
            _mm256_mul_pd(k2, _mm256_set1_pd(uj[2])),
        );
        acc = _mm256_add_pd(acc, kt);
    }
    let wi = load3(&u[i]);
    // SAFETY: AVX2 is enabled for this function.
    let (d0, d1, d2) = unsafe { S::rows(&diag[i]) };
    let mut m0 = _mm256_mul_pd(d0, wi);
    let mut m1 = _mm256_mul_pd(d1, wi);
    let mut m2 = _mm256_mul_pd(d2, wi);
    for e in &edges[kernel.row(i)] {
        let wj = load3(&u[e.col as usize]);
        // SAFETY: AVX2 is enabled for this function.
        let (k0, k1, k2) = unsafe { S::rows(&e.k) };
        m0 = _mm256_add_pd(m0, _mm256_mul_pd(k0, wj));
        m1 = _mm256_add_pd(m1, _mm256_mul_pd(k1, wj));
        m2 = _mm256_add_pd(m2, _mm256_mul_pd(k2, wj));
    }
    let (s, a, b, c) = (lanes(acc), lanes(m0), lanes(m1), lanes(m2));
    [
        s[0] + (a[0] + a[1] + a[2]),
        s[1] + (b[0] + b[1] + b[2]),
        s[2] + (c[0] + c[1] + c[2]),
    ]
}
