//! The device's recent positions, written by the RT thread every tick and
//! read by the thread that sets contact problems up: a problem with the
//! tissue's inertia is stepped through the positions the hand took since
//! the problem's state (`LocalProblem::catch_up`) before the RT thread
//! renders it. A ring of atomics: the writer never waits, allocates or
//! locks; a reader detects entries overwritten while it read them.

use crate::math::V3;
use std::sync::atomic::{AtomicU64, Ordering};

/// Entries kept: half a second at 1 kHz is readable (a reader reads at
/// most half the ring, so the writer cannot reach what it reads unless
/// the reader stalls for that long, which it then detects).
pub const POSE_HISTORY: usize = 1024;

/// The ring (see the module docs).
pub struct PoseHistory {
    /// Entries written so far.
    head: AtomicU64,
    t_ns: Box<[AtomicU64]>,
    /// x, y, z as f64 bits.
    xyz: Box<[[AtomicU64; 3]]>,
}

impl Default for PoseHistory {
    fn default() -> Self {
        Self {
            head: AtomicU64::new(0),
            t_ns: (0..POSE_HISTORY).map(|_| AtomicU64::new(0)).collect(),
            xyz: (0..POSE_HISTORY).map(|_| Default::default()).collect(),
        }
    }
}

impl PoseHistory {
    /// Writer side (one writer: the RT thread): the position at `t_ns`.
    pub fn push(&self, t_ns: u64, position_m: V3) {
        let h = self.head.load(Ordering::Relaxed);
        let i = h as usize % POSE_HISTORY;
        self.t_ns[i].store(t_ns, Ordering::Relaxed);
        for (a, x) in self.xyz[i].iter().zip(position_m) {
            a.store(x.to_bits(), Ordering::Relaxed);
        }
        self.head.store(h + 1, Ordering::Release);
    }

    /// The positions recorded after `after_ns`, oldest first, into `out`
    /// (cleared; at most `max`, the newest ones); false (and `out` empty)
    /// if the writer overwrote some of them while they were read.
    pub fn since(&self, after_ns: u64, max: usize, out: &mut Vec<(u64, V3)>) -> bool {
        out.clear();
        let h = self.head.load(Ordering::Acquire);
        let span = (h as usize).min(POSE_HISTORY / 2).min(max);
        for k in 0..span {
            let i = (h as usize - 1 - k) % POSE_HISTORY;
            let t = self.t_ns[i].load(Ordering::Relaxed);
            if t <= after_ns {
                break;
            }
            let p = [0, 1, 2].map(|c| f64::from_bits(self.xyz[i][c].load(Ordering::Relaxed)));
            out.push((t, p));
        }
        std::sync::atomic::fence(Ordering::Acquire);
        // The oldest entry read is h - len; the writer reaches its slot
        // again at head h - len + POSE_HISTORY.
        let now = self.head.load(Ordering::Relaxed);
        if now >= h - out.len() as u64 + POSE_HISTORY as u64 {
            out.clear();
            return false;
        }
        out.reverse();
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_positions_after_a_time_come_oldest_first() {
        let h = PoseHistory::default();
        let mut out = Vec::new();
        assert!(h.since(0, 100, &mut out) && out.is_empty());
        for k in 1..=10u64 {
            h.push(k * 1000, [k as f64, 0.0, -(k as f64)]);
        }
        assert!(h.since(7000, 100, &mut out));
        assert_eq!(
            out,
            vec![
                (8000, [8.0, 0.0, -8.0]),
                (9000, [9.0, 0.0, -9.0]),
                (10000, [10.0, 0.0, -10.0])
            ]
        );
        // At most `max`: the newest.
        assert!(h.since(0, 2, &mut out));
        assert_eq!(
            out.iter().map(|e| e.0).collect::<Vec<_>>(),
            vec![9000, 10000]
        );
        // Around the ring: still the newest, in order.
        for k in 11..=3000u64 {
            h.push(k * 1000, [k as f64; 3]);
        }
        assert!(h.since(2995 * 1000, 100, &mut out));
        assert_eq!(
            out.iter().map(|e| e.0).collect::<Vec<_>>(),
            vec![2996000, 2997000, 2998000, 2999000, 3000000]
        );
        // No more than half the ring is read back.
        assert!(h.since(0, usize::MAX, &mut out));
        assert_eq!(out.len(), POSE_HISTORY / 2);
    }
}
