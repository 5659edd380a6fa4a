//! Tool poses in: the newest pose, whether it may still drive the tools
//! (fresh, and its publisher alive), and the wait for the next step that
//! ends early when a fresh pose arrives.
//!
//! A pose older than the timeout (its `t_ns`, the device read, against the
//! simulation's clock) or one whose publisher is gone (no publisher on the
//! pose service after the resources of dead processes were removed) no
//! longer drives any tool: the tools it drove let go, as when the pose
//! publisher says `TOOL_PRESENT` is off. A new pose takes them again.

use super::RunError;
use shared::protocol::PoseMsg;
use shared::reaper::Reaper;
use shared::services::{self, IpcNode, PoseReadyListener, PoseService, PoseSubscriber};
use shared::{SessionName, monotonic_ns};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// The default pose timeout (ns): 50 ms.
pub const DEFAULT_POSE_TIMEOUT_NS: u64 = 50_000_000;
/// How often dead processes' ports are removed (by [`Reaper`], off the
/// loop), after which the pose publishers are counted again.
const PUBLISHER_CHECK: Duration = Duration::from_millis(20);

/// Whether a pose read at `pose_t_ns` may still drive a tool at `now_ns`.
pub fn is_fresh(pose_t_ns: u64, now_ns: u64, timeout_ns: u64) -> bool {
    now_ns.saturating_sub(pose_t_ns) <= timeout_ns
}

/// Why the wait for a step ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WaitEnd {
    /// The step was due.
    Due,
    /// A pose is waiting inside the early window: `on_arrival` when it
    /// came while the loop waited in the window (its age is then the
    /// transport alone), not before the window opened.
    Pose {
        /// It woke the waiting loop.
        on_arrival: bool,
    },
    /// Stop requested.
    Stop,
}

/// The pose side of the loop.
pub struct PoseIntake {
    factory: PoseService,
    subscriber: PoseSubscriber,
    /// Wakes the wait when a pose publisher says it published (optional).
    listener: Option<PoseReadyListener>,
    timeout_ns: u64,
    latest: Option<PoseMsg>,
    publishers: usize,
    reaper: Reaper,
    /// The reaper's passes at the last count.
    counted_after: u64,
    was_active: bool,
    /// Who sent the last pose, who sent poses before that one, and
    /// whether poses alternating between two were told.
    last_publisher: Option<shared::services::PublisherId>,
    previous_publisher: Option<shared::services::PublisherId>,
    told_two_publishers: bool,
    /// Pose messages received.
    pub received: u64,
    /// Times the tools were let go because the pose went stale or its
    /// publisher died.
    pub timeouts: u64,
}

impl PoseIntake {
    /// Subscribes to `session`'s poses (and their ready event).
    pub fn new(node: &IpcNode, session: &SessionName, timeout_ns: u64) -> Result<Self, RunError> {
        let factory = services::pose_service(node, session)?;
        let subscriber = services::subscriber(&factory)?;
        // Without the event the loop still works, stepping at its own rate.
        let listener = services::pose_ready_listener(node, session)
            .inspect_err(|e| {
                eprintln!("sim-server: no pose-ready event ({e}); stepping on the clock only")
            })
            .ok();
        let reaper = Reaper::spawn("sim-server-reaper", PUBLISHER_CHECK)?;
        Ok(Self {
            publishers: services::publisher_count(&factory),
            counted_after: reaper.passes(),
            reaper,
            factory,
            subscriber,
            listener,
            timeout_ns,
            latest: None,
            was_active: false,
            last_publisher: None,
            previous_publisher: None,
            told_two_publishers: false,
            received: 0,
            timeouts: 0,
        })
    }

    /// Takes every pose that arrived (the newest wins).
    pub fn drain(&mut self) -> Result<(), RunError> {
        while let Some(p) = self
            .subscriber
            .receive()
            .map_err(|e| super::publish_err("pose receive")(format!("{e:?}")))?
        {
            shared::protocol::check_version("pose", p.version)?;
            let from = p.header().publisher_id();
            if self.last_publisher.is_some_and(|last| last != from) {
                // Back to the publisher before the last: two live ones
                // alternate (a restart moves from one to the next only).
                // Each pose carries every tool, so they take turns at all
                // of them, which no one asks for knowingly.
                if self.previous_publisher == Some(from) && !self.told_two_publishers {
                    self.told_two_publishers = true;
                    eprintln!(
                        "sim-server: poses alternate between two publishers (two haptic daemons, or a daemon and a scripted client?); each pose drives every tool, so they take turns: stop one"
                    );
                }
                self.previous_publisher = self.last_publisher;
            }
            self.last_publisher = Some(from);
            self.latest = Some(*p);
            self.received += 1;
        }
        Ok(())
    }

    /// After each pass of the reaper (every 20 ms, on its own thread:
    /// what dead processes left removed, their publishers among it):
    /// counts the pose publishers; with none, the last pose is forgotten.
    pub fn check_publishers(&mut self) {
        let passes = self.reaper.passes();
        if passes == self.counted_after {
            return;
        }
        self.counted_after = passes;
        self.publishers = services::publisher_count(&self.factory);
        if self.publishers == 0 {
            self.latest = None;
        }
    }

    /// The pose that drives the tools at `now_ns`: the newest, if fresh and
    /// its publisher was alive at the last check. Counts a timeout when a
    /// pose that drove the tools stops doing so.
    pub fn active(&mut self, now_ns: u64) -> Option<PoseMsg> {
        let active = self
            .latest
            .filter(|p| self.publishers > 0 && is_fresh(p.t_ns, now_ns, self.timeout_ns));
        if self.was_active && active.is_none() {
            self.timeouts += 1;
        }
        self.was_active = active.is_some();
        active
    }

    /// Waits until `due_ns`, or from `earliest_ns` on until a pose is
    /// waiting (it then steps on it at once), or until `stop` is set.
    pub fn wait(&self, earliest_ns: u64, due_ns: u64, stop: &AtomicBool) -> WaitEnd {
        // Whether the last wait ended on a notification inside the window.
        let mut woken_in_window = false;
        loop {
            if stop.load(Ordering::Relaxed) {
                return WaitEnd::Stop;
            }
            let now = monotonic_ns();
            if now >= due_ns {
                return WaitEnd::Due;
            }
            if now >= earliest_ns && self.subscriber.has_samples().unwrap_or(false) {
                return WaitEnd::Pose {
                    on_arrival: woken_in_window,
                };
            }
            let until = if now < earliest_ns {
                earliest_ns
            } else {
                due_ns
            };
            let left = Duration::from_nanos(until - now);
            // A notification ends the wait early; a wait that returns
            // without one (timed out, interrupted, failed) sleeps out the
            // rest, so the loop never spins or steps early.
            let notified = self
                .listener
                .as_ref()
                .is_some_and(|l| services::wait_notified(l, left));
            woken_in_window = notified && now >= earliest_ns;
            if !notified {
                let now = monotonic_ns();
                if now < until {
                    std::thread::sleep(Duration::from_nanos(until - now));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pose_is_fresh_up_to_the_timeout() {
        let ms = 1_000_000;
        assert!(is_fresh(100 * ms, 150 * ms, 50 * ms));
        assert!(!is_fresh(100 * ms, 150 * ms + 1, 50 * ms));
        // A stamp slightly in the future (another thread's clock read) is fresh.
        assert!(is_fresh(200 * ms, 150 * ms, 50 * ms));
    }
}
