//! Removing what dead processes left, off the real-time loops.
//!
//! iceoryx2 frees a crashed or killed process's ports and shared memory
//! only when a live process looks for them ([`services::reap_dead_nodes`]),
//! and a publisher that died counts as alive until then. The look lists
//! every node of the machine and parses each one's details file: a few
//! hundred microseconds, which the simulation's loop spent every 20 ms
//! inside its step cycle (7% of its CPU in a profile of the liver under the
//! simulated hand). [`Reaper`] does it on a thread of its own with its own
//! node; the loop then only reads the publisher count, an atomic in shared
//! memory, after each pass ([`Reaper::passes`]).

use crate::services::{self, ServiceError};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// A thread that removes dead nodes' resources every period.
pub struct Reaper {
    stop: Arc<AtomicBool>,
    passes: Arc<AtomicU64>,
    handle: Option<JoinHandle<()>>,
}

impl Reaper {
    /// Starts reaping every `period` with a node named `name`, after one
    /// pass on the calling thread (so that what a crash left is gone when
    /// this returns).
    pub fn spawn(name: &str, period: Duration) -> Result<Self, ServiceError> {
        let node = services::node(name)?;
        services::reap_dead_nodes(&node);
        let stop = Arc::new(AtomicBool::new(false));
        let passes = Arc::new(AtomicU64::new(1));
        let handle = {
            let (stop, passes) = (stop.clone(), passes.clone());
            std::thread::Builder::new()
                .name("reaper".into())
                .spawn(move || {
                    while !stop.load(Ordering::Relaxed) {
                        std::thread::park_timeout(period);
                        services::reap_dead_nodes(&node);
                        passes.fetch_add(1, Ordering::Release);
                    }
                })
                .map_err(|e| ServiceError::Node {
                    name: name.to_string(),
                    reason: format!("cannot start its thread: {e}"),
                })?
        };
        Ok(Self {
            stop,
            passes,
            handle: Some(handle),
        })
    }

    /// Passes completed so far: a count read after this changed reflects
    /// a pass made after the previous read.
    pub fn passes(&self) -> u64 {
        self.passes.load(Ordering::Acquire)
    }
}

impl Drop for Reaper {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            h.thread().unpark();
            let _ = h.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_are_counted_and_the_thread_stops_on_drop() {
        let reaper = Reaper::spawn("reaper-test", Duration::from_millis(1)).expect("node");
        let first = reaper.passes();
        assert!(first >= 1, "the first pass is made before spawn returns");
        let deadline = std::time::Instant::now() + Duration::from_secs(10);
        while reaper.passes() < first + 2 {
            assert!(std::time::Instant::now() < deadline, "no pass in 10 s");
            std::thread::sleep(Duration::from_millis(1));
        }
        drop(reaper);
    }
}
