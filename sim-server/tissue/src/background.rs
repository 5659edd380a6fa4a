//! Background threads (factor rebuilds, the contact stiffness) run under
//! `SCHED_IDLE`: they get only the CPU time no normal thread wants. At
//! normal priority, or even at nice 19, a background thread woken by the
//! stepping thread (a job handed over) took its core for 1.4-4.4 ms (the
//! scheduler lets a woken thread run at least its minimum granularity
//! before preempting it again): those were the live simulation's longest
//! steps. The simulation idles most of each haptic period (a 0.25 ms step
//! per 1 ms on the liver), so idle time is plentiful.

/// Moves the calling thread to `SCHED_IDLE` (Linux; on a thread, policy
/// calls with pid 0 apply to the calling thread only), or to nice 19 if
/// that is refused. Best effort: where both fail the thread runs at
/// normal priority, which is correct, only less kind to the step.
pub fn lower_this_thread() {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: `param` is a valid sched_param that outlives the call; the
    // other calls take and read only integers.
    unsafe {
        if libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) != 0 {
            let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
            libc::setpriority(libc::PRIO_PROCESS, tid, 19);
        }
    }
}
