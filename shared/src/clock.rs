//! `CLOCK_MONOTONIC` in nanoseconds: the time base of every payload (`t_ns`);
//! and the calling thread's CPU time, for what a loop's work costs apart from
//! the machine.
//!
//! All processes of a session run on one host, so their monotonic clocks agree
//! and a sample's age is a plain subtraction.

/// Nanoseconds in one second.
pub const NS_PER_S: u64 = 1_000_000_000;

/// The current `CLOCK_MONOTONIC` time in nanoseconds.
///
/// Allocation-free and lock-free (a vDSO call), so the haptic loop may call it.
pub fn monotonic_ns() -> u64 {
    read_ns(libc::CLOCK_MONOTONIC)
}

/// CPU time the calling thread has run, in nanoseconds
/// (`CLOCK_THREAD_CPUTIME_ID`): time it waited, slept or was preempted
/// (by another thread, or by the hypervisor where the kernel accounts
/// steal time) does not count, so the difference of two readings is what
/// the code between them cost the core, apart from what the machine did.
///
/// Allocation-free; a system call on most kernels (no vDSO for this clock),
/// so read it per step, not per element.
pub fn thread_cpu_ns() -> u64 {
    read_ns(libc::CLOCK_THREAD_CPUTIME_ID)
}

/// `clock` in nanoseconds.
#[inline]
fn read_ns(clock: libc::clockid_t) -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec, and both clocks this
    // module reads (CLOCK_MONOTONIC, CLOCK_THREAD_CPUTIME_ID) exist on every
    // Linux this project supports, so the call cannot fail or write out of
    // bounds.
    let rc = unsafe { libc::clock_gettime(clock, &mut ts) };
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

    #[test]
    fn thread_cpu_time_counts_work_not_sleep() {
        let a = thread_cpu_ns();
        std::thread::sleep(std::time::Duration::from_millis(20));
        let b = thread_cpu_ns();
        // Sleeping costs the thread next to no CPU (the 20 ms would show).
        assert!(b - a < 10_000_000, "sleep counted {} ns of CPU", b - a);
        let start = monotonic_ns();
        let mut x = 0u64;
        while monotonic_ns() - start < 20_000_000 {
            x = std::hint::black_box(x.wrapping_add(1));
        }
        let c = thread_cpu_ns();
        // Spinning for 20 ms of wall time runs at least a few ms on a
        // loaded machine, and never more than the wall time it spanned.
        assert!(c - b > 2_000_000, "20 ms of spinning counted {} ns", c - b);
        assert!(c - b <= monotonic_ns() - a + 1_000_000, "{} ns", c - b);
    }
}
