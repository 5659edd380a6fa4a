//! `CLOCK_MONOTONIC` in nanoseconds: the time base of every payload (`t_ns`).
//!
//! All processes of a session run on one host, so their monotonic clocks agree
//! and a sample's age is a plain subtraction.

/// Nanoseconds in one second.
pub const NS_PER_S: u64 = 1_000_000_000;

/// The current `CLOCK_MONOTONIC` time in nanoseconds.
///
/// Allocation-free and lock-free (a vDSO call), so the haptic loop may call it.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec and CLOCK_MONOTONIC is always
    // available on Linux, so the call cannot fail or write out of bounds.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    debug_assert_eq!(rc, 0);
    (ts.tv_sec as u64) * NS_PER_S + ts.tv_nsec as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_never_goes_back_and_tracks_sleep() {
        let a = monotonic_ns();
        std::thread::sleep(std::time::Duration::from_millis(2));
        let b = monotonic_ns();
        assert!(
            b >= a + 2_000_000,
            "slept 2 ms but clock advanced {} ns",
            b - a
        );
    }
}
