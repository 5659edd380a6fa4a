//! A dense LU solve with partial pivoting whose buffers live across
//! solves: faer's blocked, vectorised factorisation in place, for the
//! Newton systems of the precomputed backend's penalty contact (a few tens
//! to 192 unknowns, several times a step). The hand-written elimination
//! of [`crate::math::solve_in_place`] ran at about 2 GFLOP/s there and was
//! the largest single cost of such a step (`perf`, docs/results/precomputed-contact.md); faer's
//! in-place API takes its scratch from a buffer kept here, so a solve
//! allocates nothing once the largest size has been seen.

use crate::math::Real;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::{factor, solve};
use faer::perm::PermRef;
use faer::reborrow::{IntoConst, ReborrowMut};
use faer::{MatMut, MatRef, Par};

/// Reused buffers of [`DenseLu::solve_row_major`].
#[derive(Default)]
pub(crate) struct DenseLu {
    perm: Vec<usize>,
    perm_inv: Vec<usize>,
    /// Scratch for the factorisation and the solve, sized for `capacity`.
    scratch: Option<MemBuffer>,
    capacity: usize,
}

impl DenseLu {
    /// Solves M x = b in place (M n x n row-major, overwritten by its
    /// factors; x written into b); false if M has a pivot below 1e-300
    /// (singular or not finite), b then unspecified.
    pub(crate) fn solve_row_major(&mut self, m: &mut [Real], b: &mut [Real], n: usize) -> bool {
        debug_assert!(m.len() == n * n && b.len() == n);
        if n == 0 {
            return true;
        }
        if self.scratch.is_none() || self.capacity < n {
            let req =
                factor::lu_in_place_scratch::<usize, Real>(n, n, Par::Seq, Default::default()).or(
                    solve::solve_transpose_in_place_scratch::<usize, Real>(n, 1, Par::Seq),
                );
            match MemBuffer::try_new(req) {
                Ok(buffer) => self.scratch = Some(buffer),
                Err(_) => return false,
            }
            self.capacity = n;
        }
        self.perm.resize(n, 0);
        self.perm_inv.resize(n, 0);
        let Some(scratch) = self.scratch.as_mut() else {
            return false;
        };
        // M row-major is M^T column-major: factor P M^T = L U, and solve
        // M x = b as (M^T)^T x = b with the transposed solve.
        let mut lu = MatMut::from_column_major_slice_mut(m, n, n);
        let (_, perm) = factor::lu_in_place(
            lu.rb_mut(),
            &mut self.perm,
            &mut self.perm_inv,
            Par::Seq,
            MemStack::new(scratch),
            Default::default(),
        );
        let lu = lu.into_const();
        let pivot_ok = |x: Real| x.is_finite() && x.abs() >= 1e-300;
        if (0..n).any(|i| !pivot_ok(lu[(i, i)])) {
            return false;
        }
        let rhs = MatMut::from_column_major_slice_mut(b, n, 1);
        solve::solve_transpose_in_place(lu, lu, perm, rhs, Par::Seq, MemStack::new(scratch));
        true
    }
}

impl DenseLu {
    /// Solves M x = b again (x written into b) with the factors that the
    /// last successful [`DenseLu::solve_row_major`] of the same size left
    /// in `factors`: a new right side for the same matrix at O(n^2).
    /// False where the sizes do not match that solve.
    pub(crate) fn resolve(&mut self, factors: &[Real], b: &mut [Real], n: usize) -> bool {
        if self.perm.len() != n || factors.len() != n * n || b.len() != n || n == 0 {
            return false;
        }
        let Some(scratch) = self.scratch.as_mut() else {
            return false;
        };
        let lu = MatRef::from_column_major_slice(factors, n, n);
        let perm = PermRef::new_checked(&self.perm, &self.perm_inv, n);
        let rhs = MatMut::from_column_major_slice_mut(b, n, 1);
        solve::solve_transpose_in_place(lu, lu, perm, rhs, Par::Seq, MemStack::new(scratch));
        true
    }
}

/// M x for M n x n row-major.
#[cfg(test)]
fn apply(m: &[Real], x: &[Real], n: usize) -> Vec<Real> {
    (0..n)
        .map(|i| (0..n).map(|j| m[i * n + j] * x[j]).sum())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A non-symmetric matrix that needs pivoting (a zero first pivot
    /// beyond 1 x 1).
    fn matrix(n: usize) -> Vec<Real> {
        let mut m = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                m[i * n + j] = (1.3 * i as Real + 0.7 * ((i + 1) * j) as Real).sin()
                    + if i == j { 1.0 } else { 0.0 };
            }
        }
        if n > 1 {
            m[0] = 0.0;
        }
        m
    }

    #[test]
    fn solves_row_major_systems_of_every_size_with_one_set_of_buffers() {
        let mut lu = DenseLu::default();
        for n in [1, 2, 3, 37, 5, 96, 192, 10] {
            let m = matrix(n);
            let x: Vec<Real> = (0..n).map(|i| (i as Real * 0.37).sin() + 1.0).collect();
            let mut b = apply(&m, &x, n);
            let mut factors = m.clone();
            assert!(lu.solve_row_major(&mut factors, &mut b, n), "n = {n}");
            let err = (b.iter().zip(&x)).fold(0.0 as Real, |e, (a, b)| e.max((a - b).abs()));
            assert!(err < 1e-8, "n = {n}: error {err}");
            // The factors serve another right side.
            let y: Vec<Real> = (0..n).map(|i| (i as Real * 0.11).cos()).collect();
            let mut c = apply(&m, &y, n);
            assert!(lu.resolve(&factors, &mut c, n));
            let err = (c.iter().zip(&y)).fold(0.0 as Real, |e, (a, b)| e.max((a - b).abs()));
            assert!(err < 1e-8, "n = {n}: error {err} on the second right side");
            assert!(
                !lu.resolve(&factors, &mut c[..n - 1], n - 1),
                "another size"
            );
            // The same answer as the hand-written elimination.
            let (mut m2, mut b2) = (m.clone(), apply(&m, &x, n));
            assert!(crate::math::solve_in_place(&mut m2, &mut b2, n, 1));
            let diff = (b.iter().zip(&b2)).fold(0.0 as Real, |e, (a, b)| e.max((a - b).abs()));
            assert!(diff < 1e-8, "n = {n}: {diff}");
        }
    }

    #[test]
    fn a_singular_or_nan_matrix_is_refused() {
        let mut lu = DenseLu::default();
        let mut singular = vec![1.0, 2.0, 2.0, 4.0];
        assert!(!lu.solve_row_major(&mut singular, &mut [1.0, 1.0], 2));
        let mut nan = vec![Real::NAN, 0.0, 0.0, 1.0];
        assert!(!lu.solve_row_major(&mut nan, &mut [1.0, 1.0], 2));
        let mut fine = vec![2.0, 0.0, 0.0, 4.0];
        let mut b = [2.0, 2.0];
        assert!(lu.solve_row_major(&mut fine, &mut b, 2));
        assert_eq!(b, [1.0, 0.5]);
    }
}
