//! Lock-free hand-over between the real-time thread and the I/O thread:
//! the latest pose in atomics (a sequence counter brackets the writes, so a
//! reader detects a torn read and retries), and flags. No locks, no
//! allocation, no `unsafe`.

use crate::math::V3;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// The latest device pose of tool 0, written every tick by the RT thread.
#[derive(Default)]
pub struct PoseSlot {
    seq: AtomicU64,
    words: [AtomicU64; 7],
}

/// A consistent copy of the slot.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PoseSnapshot {
    /// Write counter (even = stable).
    pub seq: u64,
    /// Device time (ns).
    pub t_ns: u64,
    /// Tip position (m).
    pub position_m: V3,
    /// Jaw opening.
    pub jaw: f64,
    /// Buttons.
    pub buttons: u32,
}

impl PoseSlot {
    /// Writer side (one writer only).
    pub fn write(&self, t_ns: u64, position_m: V3, jaw: f64, buttons: u32) {
        let s = self.seq.load(Ordering::Relaxed);
        self.seq.store(s + 1, Ordering::Release);
        std::sync::atomic::fence(Ordering::Release);
        let w = [
            t_ns,
            position_m[0].to_bits(),
            position_m[1].to_bits(),
            position_m[2].to_bits(),
            jaw.to_bits(),
            buttons as u64,
            0,
        ];
        for (a, v) in self.words.iter().zip(w) {
            a.store(v, Ordering::Relaxed);
        }
        self.seq.store(s + 2, Ordering::Release);
    }

    /// Reader side: retries until it sees a write that was not in progress.
    /// `None` before the first write.
    pub fn read(&self) -> Option<PoseSnapshot> {
        loop {
            let s1 = self.seq.load(Ordering::Acquire);
            if s1 == 0 {
                return None;
            }
            if s1 % 2 == 1 {
                std::hint::spin_loop();
                continue;
            }
            let w: [u64; 7] = std::array::from_fn(|k| self.words[k].load(Ordering::Relaxed));
            std::sync::atomic::fence(Ordering::Acquire);
            if self.seq.load(Ordering::Relaxed) == s1 {
                return Some(PoseSnapshot {
                    seq: s1,
                    t_ns: w[0],
                    position_m: [
                        f64::from_bits(w[1]),
                        f64::from_bits(w[2]),
                        f64::from_bits(w[3]),
                    ],
                    jaw: f64::from_bits(w[4]),
                    buttons: w[5] as u32,
                });
            }
        }
    }
}

/// Flags shared by the threads.
#[derive(Default)]
pub struct Flags {
    /// Stop requested (signal, duration, error).
    pub stop: AtomicBool,
    /// The RT thread has zeroed the device and left its loop.
    pub rt_done: AtomicBool,
    /// A simulation publishes force samples (I/O thread's view).
    pub peer_alive: AtomicBool,
    /// A force sample of another protocol version arrived (and was ignored).
    pub version_mismatch: AtomicBool,
    /// `CLOCK_MONOTONIC` (ns) at which the RT thread last started a tick
    /// (0 before the first): a value that stops moving means the device
    /// call of that tick blocks.
    pub heartbeat_ns: AtomicU64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn reads_are_never_torn() {
        let slot = Arc::new(PoseSlot::default());
        assert!(slot.read().is_none());
        let writer = {
            let slot = slot.clone();
            std::thread::spawn(move || {
                for k in 1..200_000u64 {
                    let x = k as f64;
                    slot.write(k, [x, x, x], x, k as u32);
                }
            })
        };
        let mut last = 0;
        while !writer.is_finished() {
            if let Some(p) = slot.read() {
                let x = p.t_ns as f64;
                assert_eq!(p.position_m, [x, x, x], "torn read");
                assert_eq!(p.jaw, x);
                assert!(p.seq >= last);
                last = p.seq;
            }
        }
        writer.join().unwrap();
    }
}
