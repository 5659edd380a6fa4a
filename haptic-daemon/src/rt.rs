//! Real-time plumbing: absolute-deadline pacing with `clock_nanosleep`,
//! memory locking, SCHED_FIFO and CPU affinity (each tried, each reported),
//! and a preallocated lateness histogram.

use shared::monotonic_ns;
pub use shared::rt::{minimal_timer_slack, set_fifo};

/// Paces a loop on absolute deadlines: drift-free, and a late tick does not
/// make the next ones early (missed deadlines are skipped and counted).
pub struct Pacer {
    period_ns: u64,
    next_ns: u64,
    overruns: u64,
    spin_ns: u64,
}

impl Pacer {
    /// First deadline one period after `start_ns`.
    pub fn new(period_ns: u64, start_ns: u64) -> Self {
        Self {
            period_ns,
            next_ns: start_ns + period_ns,
            overruns: 0,
            spin_ns: 0,
        }
    }

    /// Sleeps until `spin_ns` before each deadline and spins the rest, which
    /// removes the wake-up latency of the timer (tens of microseconds on a
    /// VM) at the cost of that much CPU per tick. Capped at half a period:
    /// never spin a whole period (the kernel throttles RT spinners).
    pub fn with_spin(mut self, spin_ns: u64) -> Self {
        self.spin_ns = spin_ns.min(self.period_ns / 2);
        self
    }

    /// Sleeps until the next deadline and returns (deadline, lateness_ns):
    /// how long after the deadline the thread woke. Allocation-free; the only
    /// system call is `clock_nanosleep(TIMER_ABSTIME)`.
    pub fn wait(&mut self) -> (u64, i64) {
        let deadline = self.next_ns;
        let wake = deadline - self.spin_ns;
        let ts = libc::timespec {
            tv_sec: (wake / 1_000_000_000) as libc::time_t,
            tv_nsec: (wake % 1_000_000_000) as libc::c_long,
        };
        loop {
            // SAFETY: `ts` is a valid timespec; a null remainder is allowed
            // with TIMER_ABSTIME.
            let rc = unsafe {
                libc::clock_nanosleep(
                    libc::CLOCK_MONOTONIC,
                    libc::TIMER_ABSTIME,
                    &ts,
                    std::ptr::null_mut(),
                )
            };
            if rc != libc::EINTR {
                break;
            }
        }
        let mut now = monotonic_ns();
        while now < deadline {
            std::hint::spin_loop();
            now = monotonic_ns();
        }
        let lateness = now as i64 - deadline as i64;
        self.next_ns += self.period_ns;
        if now >= self.next_ns {
            // More than a period late: skip the missed deadlines instead of
            // running a burst of ticks.
            let missed = (now - self.next_ns) / self.period_ns + 1;
            self.overruns += missed;
            self.next_ns += missed * self.period_ns;
        }
        (deadline, lateness)
    }

    /// Deadlines skipped because a tick ran more than a period late.
    pub fn overruns(&self) -> u64 {
        self.overruns
    }
}

/// What the real-time setup achieved (each item: Ok or the reason it failed).
#[derive(Debug, Default)]
pub struct RtReport {
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)`.
    pub mlockall: Option<Result<(), String>>,
    /// SCHED_FIFO at the given priority.
    pub sched_fifo: Option<Result<i32, String>>,
    /// CPU affinity.
    pub affinity: Option<Result<usize, String>>,
}

impl RtReport {
    /// Human-readable warnings for whatever failed, with the fix.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if let Some(Err(e)) = &self.mlockall {
            w.push(format!(
                "mlockall failed ({e}): pages may fault during the loop; raise the memlock limit (ulimit -l unlimited, or LimitMEMLOCK=infinity)"
            ));
        }
        if let Some(Err(e)) = &self.sched_fifo {
            w.push(shared::rt::fifo_refused_hint(e));
        }
        if let Some(Err(e)) = &self.affinity {
            w.push(format!(
                "CPU affinity refused ({e}): the loop may migrate between cores"
            ));
        }
        w
    }
}

fn errno_string() -> String {
    std::io::Error::last_os_error().to_string()
}

/// Locks memory (process-wide).
pub fn lock_memory() -> Result<(), String> {
    // SAFETY: plain system call with constant flags.
    let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
    if rc == 0 { Ok(()) } else { Err(errno_string()) }
}

/// Gives the calling thread the lowest normal priority (nice 19): it runs
/// on the time the RT and I/O threads leave, never taking a core from them
/// when the RT thread has no SCHED_FIFO (an unprivileged container).
pub fn lowest_priority() -> Result<(), String> {
    // SAFETY: plain system calls with integer arguments; the thread id is
    // the caller's own.
    let rc = unsafe {
        let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
        libc::setpriority(libc::PRIO_PROCESS, tid, 19)
    };
    if rc == 0 { Ok(()) } else { Err(errno_string()) }
}

/// Pins the calling thread to `cpu`.
pub fn pin_to_cpu(cpu: usize) -> Result<usize, String> {
    // SAFETY: cpu_set_t is plain data; CPU_SET writes inside it for cpu <
    // CPU_SETSIZE (checked); pid 0 = the calling thread.
    unsafe {
        if cpu >= libc::CPU_SETSIZE as usize {
            return Err(format!("cpu {cpu} is out of range"));
        }
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0 {
            Ok(cpu)
        } else {
            Err(errno_string())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pacer_keeps_absolute_deadlines() {
        let start = monotonic_ns();
        let mut p = Pacer::new(1_000_000, start);
        let mut last = 0;
        for k in 1..=20u64 {
            let (deadline, lateness) = p.wait();
            assert!(lateness >= 0, "woke {lateness} ns before its deadline");
            if p.overruns() == 0 {
                assert_eq!(deadline, start + k * 1_000_000);
            }
            assert!(deadline > last);
            last = deadline;
        }
    }
}
