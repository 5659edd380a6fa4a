//! The I/O thread (not real time): publishes the pose the RT thread left in
//! its slot, drains the telemetry queue into statistics, the record CSV and
//! telemetry batches, and watches whether a simulation is publishing.
//!
//! It sleeps parked (at most 1 ms) and the RT thread unparks it after each
//! pose write, so a pose is published one thread wake-up after the device
//! read; it then notifies the session's `pose-ready` event, which wakes a
//! simulation waiting for its next step. With a spin window
//! ([`IoSpin`], `haptic-daemon run --io-spin-us`) it instead wakes shortly
//! before the next pose is due and polls the slot, so the pose reaches the
//! simulation after one wake-up (the simulation's), at the cost of the
//! window's CPU every period.

use crate::daemon::Shared;
use crate::transport::{IoPorts, Transport, TransportError};
use shared::SessionName;
use shared::loop_stats::LoopHistogram;
use shared::protocol::{
    PROTOCOL_VERSION, PoseMsg, TELEMETRY_BATCH, TOOL_PRESENT, TelemetryBatch, TelemetryTick,
};
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use thiserror::Error;

/// Statistics the I/O thread keeps for the status line and the summary.
#[derive(Default)]
pub struct Stats {
    /// Ticks seen.
    pub ticks: u64,
    /// Lateness histogram.
    pub lateness: LoopHistogram,
    /// Largest |force| sent (N).
    pub max_force_n: f64,
    /// Last force sent (N).
    pub last_force_n: [f64; 3],
    /// Last sample age (ns; u64::MAX = none).
    pub last_age_ns: u64,
    /// Last safety state code.
    pub last_state: u32,
    /// Rows written to the record.
    pub recorded: u64,
    /// Gaps in the tick sequence seen by the I/O thread (queue overflow).
    pub gaps: u64,
    /// First and last tick times (ns).
    pub first_t_ns: u64,
    /// Last tick time (ns).
    pub last_t_ns: u64,
}

impl Stats {
    /// Ticks per second over the ticks seen (0 before two ticks).
    pub fn rate_hz(&self) -> f64 {
        let span_s = self.last_t_ns.saturating_sub(self.first_t_ns) as f64 * 1e-9;
        if span_s > 0.0 {
            self.ticks.saturating_sub(1) as f64 / span_s
        } else {
            0.0
        }
    }
}

/// I/O thread failures.
#[derive(Debug, Error)]
pub enum IoError {
    /// A service could not be opened.
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// The record file failed.
    #[error("record {file}: {reason}")]
    Record {
        /// The file.
        file: String,
        /// The OS error.
        reason: std::io::Error,
    },
}

/// How long a device call may block before the daemon gives up (ns).
pub const DEVICE_STALL_NS: u64 = 250_000_000;
/// A gap in this thread's own wake-ups that restarts the stall watch (ns).
const STALL_IO_GAP_NS: u64 = 50_000_000;
/// The exit status after a blocked device.
pub const DEVICE_STALL_EXIT_CODE: i32 = 3;

/// The record CSV's header (columns listed in the architecture page, then
/// extras). `method` and `safety_state` are names (`local-problem`,
/// `active`: [`crate::daemon::method_name`], [`crate::daemon::state_name`]),
/// not the telemetry's codes.
pub const RECORD_HEADER: &str = "t_ns,seq,pos_x_m,pos_y_m,pos_z_m,force_x_n,force_y_n,force_z_n,sample_age_ns,lateness_ns,method,safety_state";

pub(crate) fn write_row(w: &mut impl Write, t: &TelemetryTick) -> std::io::Result<()> {
    let age = if t.sample_age_ns == u64::MAX {
        String::new()
    } else {
        t.sample_age_ns.to_string()
    };
    writeln!(
        w,
        "{},{},{},{},{},{},{},{},{},{},{},{}",
        t.t_ns,
        t.seq,
        t.position_m[0],
        t.position_m[1],
        t.position_m[2],
        t.force_n[0],
        t.force_n[1],
        t.force_n[2],
        age,
        t.lateness_ns,
        crate::daemon::method_name(t.method),
        crate::daemon::state_name(t.safety_state)
    )
}

/// Polling for the next pose around the time it is due.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IoSpin {
    /// The RT loop's period (ns): the next pose is due a period after the
    /// last one's device read.
    pub period_ns: u64,
    /// The window (ns): polling starts half of it before the pose is due
    /// and gives up at its end (then the thread parks as without it).
    pub window_ns: u64,
}

impl IoSpin {
    /// Polls `seq` until it differs from `last` or the window around
    /// `last_read_ns + period` ends; sleeps (parked) until the window
    /// opens. Returns whether a new pose came within it.
    fn wait(&self, last_read_ns: u64, last: u64, seq: impl Fn() -> u64) -> bool {
        let due = last_read_ns.saturating_add(self.period_ns);
        let (open, close) = (
            due.saturating_sub(self.window_ns / 2),
            due.saturating_add(self.window_ns / 2),
        );
        let now = shared::monotonic_ns();
        if now < open {
            // An unpark (the pose came early) ends this sleep too.
            std::thread::park_timeout(Duration::from_nanos(open - now));
        }
        while shared::monotonic_ns() < close {
            if seq() != last {
                return true;
            }
            std::hint::spin_loop();
        }
        seq() != last
    }
}

/// Where the I/O thread publishes.
pub struct IoConfig {
    /// Shared memory or zenoh.
    pub transport: Transport,
    /// The session.
    pub session: SessionName,
    /// The record CSV.
    pub record: Option<PathBuf>,
    /// Poll for poses around their due time instead of waiting to be woken.
    pub spin: Option<IoSpin>,
}

/// Runs until the RT thread is done and the queue is drained.
pub fn run_io(shared: Arc<Shared>, cfg: IoConfig, stats: Arc<Mutex<Stats>>) -> Result<(), IoError> {
    let IoConfig {
        transport,
        session,
        record,
        spin,
    } = cfg;
    let ports = IoPorts::open(&transport, &session)?;
    // From here on the RT thread wakes this thread after each pose.
    let _ = shared.io_thread.set(std::thread::current());
    let mut writer = match &record {
        Some(path) => {
            let err = |source| IoError::Record {
                file: path.display().to_string(),
                reason: source,
            };
            let file = std::fs::File::create(path).map_err(err)?;
            let mut w = std::io::BufWriter::new(file);
            writeln!(w, "{RECORD_HEADER}").map_err(err)?;
            Some(w)
        }
        None => None,
    };
    let record_err = |source| IoError::Record {
        file: record
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_default(),
        reason: source,
    };
    let mut batch = TelemetryBatch::default();
    let mut batches = 0u64;
    let mut last_pose_seq = 0u64;
    let mut last_read_ns = 0u64;
    let mut pose_msgs = 0u64;
    let mut next_seq = 0u64;
    let mut last_wake_ns = shared::monotonic_ns();
    let mut watch_from_ns = last_wake_ns;
    loop {
        let done = shared.flags.rt_done.load(Ordering::Acquire);
        if let Some(p) = shared.pose.read()
            && p.seq != last_pose_seq
        {
            last_pose_seq = p.seq;
            last_read_ns = p.t_ns;
            // Pose seq starts at 1: a force sample's pose_seq 0 means "no pose".
            pose_msgs += 1;
            let mut msg = PoseMsg {
                version: PROTOCOL_VERSION,
                tool_count: 1,
                seq: pose_msgs,
                t_ns: p.t_ns,
                ..PoseMsg::default()
            };
            msg.tools[0].tip_m = p.position_m;
            msg.tools[0].jaw_opening = p.jaw;
            msg.tools[0].buttons = p.buttons;
            msg.tools[0].flags = TOOL_PRESENT;
            ports.send_pose(msg);
        }
        {
            let mut s = stats.lock().expect("stats lock");
            while let Some(t) = shared.telemetry.pop() {
                if t.seq != next_seq {
                    s.gaps += 1;
                }
                next_seq = t.seq + 1;
                if s.ticks == 0 {
                    s.first_t_ns = t.t_ns;
                }
                s.ticks += 1;
                s.last_t_ns = t.t_ns;
                s.lateness.record_ns(t.lateness_ns);
                let f = (t.force_n[0].powi(2) + t.force_n[1].powi(2) + t.force_n[2].powi(2)).sqrt();
                s.max_force_n = s.max_force_n.max(f);
                s.last_force_n = t.force_n;
                s.last_age_ns = t.sample_age_ns;
                s.last_state = t.safety_state;
                if let Some(w) = writer.as_mut() {
                    write_row(w, &t).map_err(record_err)?;
                    s.recorded += 1;
                }
                batch.ticks[batch.count as usize] = t;
                batch.count += 1;
                if batch.count as usize == TELEMETRY_BATCH {
                    batch.seq = batches;
                    batches += 1;
                    ports.send_telemetry(batch);
                    batch.count = 0;
                }
            }
        }
        // A device call that never returns leaves the RT thread unable to
        // command the device at all: report it and exit, so the driver's
        // own disconnect handling zeroes the device. The stall only counts
        // while this thread was itself running (a stopped process is not a
        // blocked device).
        let now = shared::monotonic_ns();
        if now.saturating_sub(last_wake_ns) > STALL_IO_GAP_NS {
            watch_from_ns = now;
        }
        last_wake_ns = now;
        let beat = shared.flags.heartbeat_ns.load(Ordering::Relaxed);
        if beat != 0 && !done && now.saturating_sub(beat.max(watch_from_ns)) > DEVICE_STALL_NS {
            if let Some(w) = writer.as_mut() {
                let _ = w.flush();
            }
            eprintln!(
                "haptic-daemon: the device has not returned from a call for {} ms (a blocking plugin or driver): the loop cannot command it; exiting so that the driver zeroes it on disconnect",
                now.saturating_sub(beat) / 1_000_000
            );
            std::process::exit(DEVICE_STALL_EXIT_CODE);
        }
        // Whether anyone publishes forces: an atomic read either way (a
        // reaper thread removes dead peers' publishers, shared memory; the
        // bridge's token, zenoh), so at every wake-up.
        shared
            .flags
            .peer_alive
            .store(ports.sim_alive(), Ordering::Relaxed);
        if done && shared.telemetry.is_empty() {
            break;
        }
        match spin {
            // Poll around the next pose's due time (once a pose came).
            Some(spin) if last_read_ns != 0 && !done => {
                let seq = || shared.pose.read().map_or(last_pose_seq, |p| p.seq);
                if !spin.wait(last_read_ns, last_pose_seq, seq) {
                    std::thread::park_timeout(Duration::from_millis(1));
                }
            }
            // Until the RT thread's next pose (or 1 ms).
            _ => std::thread::park_timeout(Duration::from_millis(1)),
        }
    }
    if batch.count > 0 {
        batch.seq = batches;
        ports.send_telemetry(batch);
    }
    if let Some(mut w) = writer {
        w.flush().map_err(record_err)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    const MS: u64 = 1_000_000;

    #[test]
    fn the_spin_returns_when_the_pose_changes_within_the_window() {
        let spin = IoSpin {
            period_ns: MS,
            window_ns: 10 * MS,
        };
        // Due now: the window is open; the slot changes at the third look.
        let polls = Cell::new(0u64);
        let seq = || {
            polls.set(polls.get() + 1);
            if polls.get() >= 3 { 8 } else { 7 }
        };
        let last_read = shared::monotonic_ns() - MS;
        assert!(spin.wait(last_read, 7, seq));
        assert_eq!(polls.get(), 3);
    }

    #[test]
    fn the_spin_gives_up_at_the_window_end_and_does_not_wait_for_a_past_one() {
        let spin = IoSpin {
            period_ns: MS,
            window_ns: 2 * MS,
        };
        // A window long past: one look, no wait.
        let polls = Cell::new(0u64);
        let seq = || {
            polls.set(polls.get() + 1);
            7
        };
        assert!(!spin.wait(shared::monotonic_ns() - 100 * MS, 7, seq));
        assert_eq!(polls.get(), 1);
        // A window open now: it polls until the window closes, then gives up.
        let start = shared::monotonic_ns();
        assert!(!spin.wait(start - MS, 7, || 7));
        assert!(shared::monotonic_ns() >= start + MS - MS / 10);
    }
}
