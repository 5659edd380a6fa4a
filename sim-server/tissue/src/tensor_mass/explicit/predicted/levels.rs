//! The multirate partition as a predicted step reads it: which sub-steps
//! are fine, which vertices fast, where a slow vertex's U(t - H) is kept,
//! and the interface's interpolation (the plain step's arithmetic).

use crate::math::Real;
use crate::tensor_mass::explicit::multirate::Multirate;
use crate::tensor_mass::kernel::V3;

/// The multirate partition as a predicted step reads it (`m == 1`: one
/// step for all, every vertex fast).
pub(in crate::tensor_mass) struct Levels<'a> {
    /// Fine sub-steps per coarse one.
    pub m: usize,
    /// Per vertex: fast (empty when `m == 1`).
    pub is_fast: &'a [bool],
    /// Fast vertices, ascending.
    pub fast: &'a [u32],
    /// Slow vertices next to a fast one.
    pub interface: &'a [u32],
    /// Their U(t + H) while they hold interpolated values (`interface`'s length).
    pub saved: &'a mut [V3],
    /// The fast set's generation (`Multirate::generation`; 0 for one step
    /// for all).
    pub generation: u64,
}

impl Levels<'_> {
    /// One step for all.
    pub(in crate::tensor_mass) fn uniform() -> Levels<'static> {
        Levels {
            m: 1,
            is_fast: &[],
            fast: &[],
            interface: &[],
            saved: &mut [],
            generation: 0,
        }
    }

    /// Whether sub-step `k` recomputes the fast rows alone.
    pub(super) fn fine(&self, k: usize) -> bool {
        self.m > 1 && !k.is_multiple_of(self.m)
    }

    pub(super) fn is_fast(&self, i: usize) -> bool {
        self.m == 1 || self.is_fast[i]
    }

    /// The slot a slow vertex's U(t - H) is in at coarse sub-step `k`
    /// (U(t_k - h) of every vertex at `k`: slot `k`). Between two coarse
    /// sub-steps a slow vertex's slots are copies, so m slots back holds
    /// its value before the last coarse pass; the step's first sub-step
    /// reads the state's own U(t - H) (slot 0).
    pub(super) fn slow_prev(&self, k: usize) -> usize {
        if k >= self.m { k + 1 - self.m } else { 0 }
    }

    /// The coarse sub-step `k`'s U(t_k - h) of every vertex by its own
    /// step, into `out`.
    pub(super) fn coarse_prev(&self, before: &[Vec<V3>], k: usize, out: &mut [V3]) {
        out.copy_from_slice(&before[self.slow_prev(k)]);
        if self.m > 1 {
            for &i in self.fast {
                out[i as usize] = before[k][i as usize];
            }
        }
    }

    /// Fine sub-step `k`: the interface vertices of slot `k + 1` set to
    /// their values at the fraction of the coarse sub-step (the plain
    /// step's `interpolate_interface`, the same arithmetic), U(t + H) kept.
    pub(super) fn interpolate(&mut self, before: &mut [Vec<V3>], k: usize) {
        let k0 = k - k % self.m;
        let s = (k % self.m) as Real / self.m as Real;
        let (base, rest) = before.split_at_mut(k + 1);
        let (start, now) = (&base[k0 + 1], &mut rest[0]);
        for (saved, &j) in self.saved.iter_mut().zip(self.interface) {
            let j = j as usize;
            *saved = now[j];
            for d in 0..3 {
                now[j][d] = start[j][d] + s * (now[j][d] - start[j][d]);
            }
        }
    }

    /// The interface's U(t + H) back into `now`.
    pub(super) fn restore(&self, now: &mut [V3]) {
        for (saved, &j) in self.saved.iter().zip(self.interface) {
            now[j as usize] = *saved;
        }
    }
}

/// The partition's levels for `m` fine sub-steps per coarse one.
pub(super) fn levels(m: usize, plan: Option<&mut Multirate>) -> Levels<'_> {
    match plan {
        Some(p) if m > 1 => Levels {
            m,
            is_fast: &p.is_fast,
            fast: &p.fast,
            interface: &p.interface,
            saved: &mut p.saved,
            generation: p.generation,
        },
        _ => Levels::uniform(),
    }
}
