//! Real-time scheduling for the threads that pace the system: the haptic
//! daemon's RT thread and, when asked, the simulation's stepping loop.
//! Each call is best effort and says why it failed (the caller reports it
//! with the fix), so a machine without the privilege still runs.

/// Puts the calling thread under SCHED_FIFO at `priority` (1-99), with
/// `SCHED_RESET_ON_FORK`: threads it starts later begin at normal priority
/// (a background worker spawned from the stepping loop must not inherit
/// a real-time policy and take the loop's core).
pub fn set_fifo(priority: i32) -> Result<i32, String> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: `param` is valid for the call; pid 0 = the calling thread.
    let rc = unsafe {
        libc::sched_setscheduler(0, libc::SCHED_FIFO | libc::SCHED_RESET_ON_FORK, &param)
    };
    if rc == 0 {
        Ok(priority)
    } else {
        Err(std::io::Error::last_os_error().to_string())
    }
}

/// Puts the calling thread under SCHED_IDLE: it runs only on a core that
/// nothing else wants, so background work (making a refined mesh while the
/// tools move) never preempts the stepping loop or the haptic thread on a
/// machine with few cores.
pub fn background() -> Result<(), String> {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: `param` is valid for the call; pid 0 = the calling thread.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error().to_string())
    }
}

/// Puts the calling thread under SCHED_OTHER at nice 0, the default: for
/// threads started by a [`background`] thread, which inherit SCHED_IDLE
/// but do a loop's work (the step workers of a mesh made in the
/// background).
pub fn normal() -> Result<(), String> {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: `param` is valid for the call; pid 0 = the calling thread.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_OTHER, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error().to_string())
    }
}

/// Sets the calling thread's timer slack to 1 ns: by default Linux may wake
/// a normal thread up to 50 us after its deadline to batch wake-ups (real-
/// time threads already get none).
pub fn minimal_timer_slack() -> Result<(), String> {
    // SAFETY: plain prctl with integer arguments.
    let rc = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error().to_string())
    }
}

/// What to tell the user when SCHED_FIFO was refused, and how to grant it.
pub fn fifo_refused_hint(reason: &str) -> String {
    format!(
        "SCHED_FIFO refused ({reason}): running at normal priority, expect larger lateness; grant CAP_SYS_NICE (setcap cap_sys_nice+ep) or an rtprio limit"
    )
}
