//! The responses of a contact step's rows (the vertices its springs read)
//! to the loaded contact vertices, gathered once and kept while the rows
//! stay the same, for [`Compliance::step_rows`](crate::backend::Compliance::step_rows).
//!
//! Each Newton direction of the penalty contact applies the precomputed
//! map at the rows: for every loaded vertex and axis, one response column
//! (all vertices, 24 bytes each) read at the rows only. Those reads are
//! scattered through a matrix of tens to hundreds of megabytes, one cache
//! line per value: a broad tool (a 30 mm tip over 2 mm cells, ~70 loaded
//! vertices and ~200 rows) spent 65% of its 7-9 ms steps there (`perf`),
//! several times a step on the same values. Here they are read once into
//! a dense block per loaded vertex, and each application is a contiguous
//! sweep adding the same products in the same order (the same sums to the
//! bit).

use crate::math::Vec3;

/// No block: the vertex's responses are not gathered.
const NONE: u32 = u32::MAX;

/// Values kept at most (24 bytes each: 48 MB); past it a vertex's
/// responses are read from the columns each time, as before.
const MAX_VALUES: usize = 1 << 21;

/// The gathered responses and the rows' sums.
#[derive(Default)]
pub(super) struct RowResponses {
    /// The rows the blocks are for.
    rows: Vec<u32>,
    /// Per vertex: its block among `gathered`, or [`NONE`].
    slot: Vec<u32>,
    /// The vertices with a block, in the order gathered.
    gathered: Vec<u32>,
    /// Per gathered vertex, per axis, the responses at the rows (3 R).
    values: Vec<Vec3>,
    /// The rows' sums of the last [`RowResponses::superpose`].
    sums: Vec<Vec3>,
}

impl RowResponses {
    /// Per row of `rows` (of `n` vertices): `base[row]` plus, for each
    /// loaded `(vertex, force)` in order, the responses to the force's
    /// three components (`column(vertex, axis)`: every vertex's response to
    /// a unit force along the axis on that vertex), added one product at a
    /// time as the row-by-row sum did.
    pub(super) fn superpose<'c>(
        &mut self,
        n: usize,
        rows: &[u32],
        base: &[Vec3],
        loaded: impl Iterator<Item = (u32, Vec3)>,
        column: impl Fn(u32, usize) -> &'c [Vec3],
    ) -> &[Vec3] {
        if self.slot.len() != n {
            self.slot = vec![NONE; n];
            self.gathered.clear();
            self.values.clear();
        }
        if self.rows != rows {
            for &v in &self.gathered {
                self.slot[v as usize] = NONE;
            }
            self.gathered.clear();
            self.values.clear();
            self.rows.clear();
            self.rows.extend_from_slice(rows);
        }
        let r = rows.len();
        self.sums.clear();
        self.sums.extend(rows.iter().map(|&v| base[v as usize]));
        for (v, f) in loaded {
            let vi = v as usize;
            if self.slot[vi] == NONE && self.values.len() + 3 * r <= MAX_VALUES {
                self.slot[vi] = self.gathered.len() as u32;
                self.gathered.push(v);
                for a in 0..3 {
                    let col = column(v, a);
                    self.values
                        .extend(rows.iter().map(|&row| col[row as usize]));
                }
            }
            let s = self.slot[vi];
            for a in 0..3 {
                if s == NONE {
                    let col = column(v, a);
                    for (sum, &row) in self.sums.iter_mut().zip(rows) {
                        *sum += f[a] * col[row as usize];
                    }
                } else {
                    let at = (3 * s as usize + a) * r;
                    for (sum, x) in self.sums.iter_mut().zip(&self.values[at..at + r]) {
                        *sum += f[a] * *x;
                    }
                }
            }
        }
        &self.sums
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A response matrix of 3 sources x 3 axes over `n` vertices.
    fn columns(n: usize) -> Vec<Vec3> {
        (0..9 * n)
            .map(|i| {
                Vec3::new(
                    (i as f64 * 0.37).sin(),
                    (i as f64 * 0.11).cos(),
                    i as f64 * 1e-3,
                )
            })
            .collect()
    }

    #[test]
    fn the_same_sums_to_the_bit_as_row_by_row_whatever_was_gathered_before() {
        let n = 40;
        let cols = columns(n);
        let column = |v: u32, a: usize| &cols[(3 * (v as usize % 3) + a) * n..][..n];
        let base: Vec<Vec3> = (0..n).map(|i| Vec3::splat(i as f64 * 0.01)).collect();
        let mut cache = RowResponses::default();
        // (rows, loaded vertices with their forces)
        type Case<'a> = (&'a [u32], &'a [(u32, Vec3)]);
        let cases: [Case; 4] = [
            (
                &[3, 7, 8, 20],
                &[(7, Vec3::new(0.1, -0.2, 0.3)), (8, Vec3::X)],
            ),
            (
                &[3, 7, 8, 20],
                &[(8, Vec3::Y), (20, Vec3::new(-1.0, 0.5, 0.25))],
            ),
            (
                &[1, 7, 30],
                &[(7, Vec3::Z), (30, Vec3::new(2.0, 0.0, -1.0))],
            ),
            (&[1, 7, 30], &[]),
        ];
        for (rows, loaded) in cases {
            let got = cache
                .superpose(n, rows, &base, loaded.iter().copied(), column)
                .to_vec();
            let want: Vec<Vec3> = (rows.iter())
                .map(|&row| {
                    let mut u = base[row as usize];
                    for &(v, f) in loaded {
                        for a in 0..3 {
                            u += f[a] * column(v, a)[row as usize];
                        }
                    }
                    u
                })
                .collect();
            assert_eq!(got, want, "rows {rows:?}");
        }
    }
}
