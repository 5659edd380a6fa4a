//! Tool holds on precomputed surface responses, shared by the precomputed
//! backend and the precomputed part of the hybrid.
//!
//! A held source k must sit at its imposed displacement d_k. With C the
//! responses of the held sources to each other (C[(i, a), (j, b)] =
//! displacement along a of source i under a unit force along b on source
//! j), the holding forces F solve C F = d - u_free. C changes only when a
//! hold begins or ends, not when a held vertex moves, so it is factorised
//! then and each step is one back-substitution into a reused buffer: no
//! allocation while the hold set is unchanged.

use crate::math::{Real, Vec3};
use nalgebra::{DMatrix, DVector, Dyn, LU};

/// The held sources and the factorisation of their mutual responses.
pub(super) struct Holds {
    sources: Vec<u32>,
    dirty: bool,
    lu: Option<LU<Real, Dyn, Dyn>>,
    rhs: DVector<Real>,
}

impl Holds {
    /// No holds.
    pub fn new() -> Self {
        Self {
            sources: Vec::new(),
            dirty: false,
            lu: None,
            rhs: DVector::zeros(0),
        }
    }

    /// A hold began or ended: refactorise before the next solve.
    pub fn changed(&mut self) {
        self.dirty = true;
    }

    /// Held sources at the last refresh.
    pub fn len(&self) -> usize {
        self.sources.len()
    }

    /// Whether [`Holds::changed`] was called since the last refresh.
    pub fn is_dirty(&self) -> bool {
        self.dirty
    }

    /// Rebuilds the list from `held` (the held sources) and factorises C,
    /// `response(i, j, b)` being the displacement of held source `i` under
    /// a unit force along `b` on held source `j`.
    pub fn refresh(
        &mut self,
        held: impl IntoIterator<Item = u32>,
        response: impl Fn(u32, u32, usize) -> Vec3,
    ) {
        self.dirty = false;
        self.sources.clear();
        self.sources.extend(held);
        let c = self.sources.len();
        self.rhs = DVector::zeros(3 * c);
        self.lu = (c > 0).then(|| {
            let mut t = DMatrix::<Real>::zeros(3 * c, 3 * c);
            for (i, &si) in self.sources.iter().enumerate() {
                for (j, &sj) in self.sources.iter().enumerate() {
                    for b in 0..3 {
                        let r = response(si, sj, b);
                        for a in 0..3 {
                            t[(3 * i + a, 3 * j + b)] = r[a];
                        }
                    }
                }
            }
            t.lu()
        });
    }

    /// Solves for the holding forces: `gap(s)` is d_s - u_free at held
    /// source `s`; `apply(s, f)` receives each force. Returns false (and
    /// applies nothing) when there is no hold or C is singular.
    pub fn solve(&mut self, gap: impl Fn(u32) -> Vec3, mut apply: impl FnMut(u32, Vec3)) -> bool {
        let Some(lu) = &self.lu else {
            return false;
        };
        for (k, &s) in self.sources.iter().enumerate() {
            let g = gap(s);
            for a in 0..3 {
                self.rhs[3 * k + a] = g[a];
            }
        }
        if !lu.solve_mut(&mut self.rhs) {
            return false;
        }
        for (k, &s) in self.sources.iter().enumerate() {
            apply(
                s,
                Vec3::new(self.rhs[3 * k], self.rhs[3 * k + 1], self.rhs[3 * k + 2]),
            );
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two sources coupled by a known symmetric response: the solved forces
    /// reproduce the gaps, and a refresh follows the hold set.
    #[test]
    fn holding_forces_close_the_gaps() {
        // C = diag(2) + 0.5 off-diagonal coupling between the two sources,
        // isotropic per block.
        let response = |i: u32, j: u32, b: usize| {
            let mut r = Vec3::ZERO;
            r[b] = if i == j { 2.0 } else { 0.5 };
            r
        };
        let mut holds = Holds::new();
        assert!(!holds.solve(|_| Vec3::ONE, |_, _| panic!("no holds yet")));
        holds.changed();
        assert!(holds.is_dirty());
        holds.refresh([3, 7], response);
        assert!(!holds.is_dirty());
        let gaps = |s: u32| {
            if s == 3 {
                Vec3::new(1.0, 0.0, -1.0)
            } else {
                Vec3::new(0.0, 2.0, 0.5)
            }
        };
        let mut forces = Vec::new();
        assert!(holds.solve(gaps, |s, f| forces.push((s, f))));
        assert_eq!(forces.iter().map(|x| x.0).collect::<Vec<_>>(), [3, 7]);
        for &(i, _) in &forces {
            let mut got = Vec3::ZERO;
            for &(j, f) in &forces {
                for b in 0..3 {
                    got += f[b] * response(i, j, b);
                }
            }
            assert!((got - gaps(i)).length() < 1e-12, "{got} vs {}", gaps(i));
        }
        holds.refresh([], response);
        assert!(!holds.solve(gaps, |_, _| panic!("holds ended")));
    }
}
