//! zenoh -> shared memory: a remote daemon's tool poses, each followed by
//! the `pose-ready` event, so the simulation steps on it as on a local
//! one. Stamps are already in this host's clock (the remote client maps
//! them).
//!
//! Poses are relayed only while a remote daemon holds its liveliness token
//! (`haptic-daemon run --connect` declares it before its first pose); when
//! the token goes (the daemon died, or its link), the bridge withdraws its
//! pose publisher and drops what was still queued, so the simulation sees
//! the publisher gone and the tool lets go at once, as with a local daemon,
//! not only when the last pose grows older than the pose timeout. A pose
//! the session cannot take (its publisher slots are full: a local daemon
//! and a viewer driving) is refused and counted; nothing a peer sends
//! stops the bridge.

use super::BridgeError;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use shared::SessionName;
use shared::protocol::PoseMsg;
use shared::remote::codec;
use shared::services::{self, Ipc, IpcNode, PoseService};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::Subscriber;
use zenoh::sample::Sample;

/// Counters of the inbound side.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct InCounts {
    /// Poses published into the session.
    pub poses: u64,
    /// Poses refused: another protocol version or layout, or no publisher
    /// slot free in the session.
    pub refused: u64,
    /// Why the first was refused.
    pub first_refusal: Option<String>,
    /// Poses dropped because no remote daemon held its token.
    pub without_daemon: u64,
    /// Times a remote daemon went away and its pose publisher was withdrawn.
    pub daemon_departures: u64,
}

/// The inbound poses.
pub struct Inbound {
    poses: Subscriber<FifoChannelHandler<Sample>>,
    pose_factory: PoseService,
    pose_publisher: Option<Publisher<Ipc, PoseMsg, ()>>,
    ready: Notifier<Ipc>,
    daemon_alive: Arc<AtomicBool>,
    pose_key: String,
    counts: InCounts,
}

impl Inbound {
    /// Subscribes to remote poses of `session`; `daemon_alive`: a remote
    /// daemon's token.
    pub fn new(
        node: &IpcNode,
        session: &SessionName,
        z: &zenoh::Session,
        daemon_alive: Arc<AtomicBool>,
    ) -> Result<Self, BridgeError> {
        let pose_key = session.service(services::stream::POSE);
        Ok(Self {
            poses: super::subscribe_remote(z, &pose_key)?,
            pose_factory: services::pose_service(node, session)?,
            pose_publisher: None,
            ready: services::pose_ready_notifier(node, session)?,
            daemon_alive,
            pose_key,
            counts: InCounts::default(),
        })
    }

    /// Waits up to `timeout` for a remote pose (relaying it at once), then
    /// relays whatever else came.
    pub fn wait_and_pump(&mut self, timeout: Duration) {
        if let Ok(Some(s)) = self.poses.recv_timeout(timeout) {
            self.pose(&s);
        }
        while let Ok(Some(s)) = self.poses.try_recv() {
            self.pose(&s);
        }
    }

    fn pose(&mut self, s: &Sample) {
        if !self.daemon_alive.load(Ordering::Relaxed) {
            self.counts.without_daemon += 1;
            return;
        }
        match codec::decode::<PoseMsg>(&self.pose_key, &s.payload().to_bytes()) {
            Ok(p) => {
                if self.pose_publisher.is_none() {
                    match services::publisher(&self.pose_factory) {
                        Ok(publisher) => self.pose_publisher = Some(publisher),
                        Err(e) => return self.refuse(e.to_string()),
                    }
                }
                if let Some(publisher) = &self.pose_publisher
                    && publisher.send_copy(p).is_ok()
                {
                    self.counts.poses += 1;
                    let _ = self.ready.notify();
                }
            }
            Err(e) => self.refuse(e.to_string()),
        }
    }

    fn refuse(&mut self, why: String) {
        self.counts.refused += 1;
        if self.counts.first_refusal.is_none() {
            eprintln!("sim-server bridge: refused a remote pose: {why}");
            self.counts.first_refusal = Some(why);
        }
    }

    /// Withdraws the pose publisher while no remote daemon holds its token
    /// (and drops poses still queued).
    pub fn follow_daemon(&mut self) {
        if !self.daemon_alive.load(Ordering::Relaxed) && self.pose_publisher.is_some() {
            self.pose_publisher = None;
            self.counts.daemon_departures += 1;
            while let Ok(Some(_)) = self.poses.try_recv() {
                self.counts.without_daemon += 1;
            }
        }
    }

    /// The counters.
    pub fn counts(&self) -> &InCounts {
        &self.counts
    }
}
