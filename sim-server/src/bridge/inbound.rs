//! zenoh -> shared memory: a remote daemon's tool poses (each followed by
//! the `pose-ready` event, so the simulation steps on it as on a local
//! one) and its telemetry (for local recorders and viewers). Stamps are
//! already in this host's clock: the remote client maps them.
//!
//! The bridge publishes poses in the session only while a remote daemon
//! holds its liveliness token: when the daemon dies or its link drops, the
//! bridge withdraws its pose publisher, so the simulation sees the
//! publisher gone and the tool lets go at once (as with a local daemon),
//! not only when the last pose grows older than the pose timeout.

use super::BridgeError;
use iceoryx2::identifiers::UniquePublisherId;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use shared::SessionName;
use shared::protocol::{PoseMsg, TelemetryBatch};
use shared::remote::{ALIVE_DAEMON, codec};
use shared::services::{self, Ipc, IpcNode, PoseService};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use zenoh::Wait;
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::Subscriber;
use zenoh::sample::{Locality, Sample, SampleKind};

type Telemetry =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, TelemetryBatch, ()>;

/// Counters of the inbound side.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct InCounts {
    /// Poses published into the session.
    pub poses: u64,
    /// Telemetry batches published into the session.
    pub telemetry: u64,
    /// Messages refused (another protocol version or layout).
    pub refused: u64,
    /// Why the first was refused.
    pub first_refusal: Option<String>,
    /// Times a remote daemon went away and its pose publisher was withdrawn.
    pub daemon_departures: u64,
}

/// Every inbound relay.
pub struct Inbound {
    poses: Subscriber<FifoChannelHandler<Sample>>,
    telemetry: Subscriber<FifoChannelHandler<Sample>>,
    pose_factory: PoseService,
    telemetry_factory: Telemetry,
    pose_publisher: Option<Publisher<Ipc, PoseMsg, ()>>,
    telemetry_publisher: Option<Publisher<Ipc, TelemetryBatch, ()>>,
    ready: Notifier<Ipc>,
    daemon_alive: Arc<AtomicBool>,
    daemon_was_alive: bool,
    _daemon_watch: Subscriber<()>,
    pose_key: String,
    telemetry_key: String,
    counts: InCounts,
}

impl Inbound {
    /// Subscribes to the remote side of `session`.
    pub fn new(
        node: &IpcNode,
        session: &SessionName,
        z: &zenoh::Session,
    ) -> Result<Self, BridgeError> {
        let zerr = |key: &str| {
            let key = key.to_string();
            move |e: zenoh::Error| BridgeError::Zenoh {
                key,
                reason: e.to_string(),
            }
        };
        let pose_key = session.service(services::stream::POSE);
        let telemetry_key = session.service(services::stream::TELEMETRY);
        // Only what other hosts put: the bridge's own puts of local
        // telemetry must not come back.
        let poses = z
            .declare_subscriber(pose_key.clone())
            .allowed_origin(Locality::Remote)
            .wait()
            .map_err(zerr(&pose_key))?;
        let telemetry = z
            .declare_subscriber(telemetry_key.clone())
            .allowed_origin(Locality::Remote)
            .wait()
            .map_err(zerr(&telemetry_key))?;
        let daemon_alive = Arc::new(AtomicBool::new(false));
        let alive = daemon_alive.clone();
        let alive_key = session.service(ALIVE_DAEMON);
        let daemon_watch = z
            .liveliness()
            .declare_subscriber(&alive_key)
            .history(true)
            .callback(move |s| alive.store(s.kind() == SampleKind::Put, Ordering::Relaxed))
            .wait()
            .map_err(zerr(&alive_key))?;
        Ok(Self {
            poses,
            telemetry,
            pose_factory: services::pose_service(node, session)?,
            telemetry_factory: services::telemetry_service(node, session)?,
            pose_publisher: None,
            telemetry_publisher: None,
            ready: services::pose_ready_notifier(node, session)?,
            daemon_alive,
            daemon_was_alive: false,
            _daemon_watch: daemon_watch,
            pose_key,
            telemetry_key,
            counts: InCounts::default(),
        })
    }

    /// Waits up to `timeout` for a remote pose (relaying it at once), then
    /// relays whatever else came.
    pub fn wait_and_pump(&mut self, timeout: Duration) -> Result<(), BridgeError> {
        if let Ok(Some(s)) = self.poses.recv_timeout(timeout) {
            self.pose(&s)?;
        }
        while let Ok(Some(s)) = self.poses.try_recv() {
            self.pose(&s)?;
        }
        while let Ok(Some(s)) = self.telemetry.try_recv() {
            match codec::decode::<TelemetryBatch>(&self.telemetry_key, &s.payload().to_bytes()) {
                Ok(b) => {
                    if self.telemetry_publisher.is_none() {
                        self.telemetry_publisher =
                            Some(services::publisher(&self.telemetry_factory)?);
                    }
                    if let Some(p) = &self.telemetry_publisher
                        && p.send_copy(b).is_ok()
                    {
                        self.counts.telemetry += 1;
                    }
                }
                Err(e) => self.refuse(e),
            }
        }
        Ok(())
    }

    fn pose(&mut self, s: &Sample) -> Result<(), BridgeError> {
        match codec::decode::<PoseMsg>(&self.pose_key, &s.payload().to_bytes()) {
            Ok(p) => {
                if self.pose_publisher.is_none() {
                    self.pose_publisher = Some(services::publisher(&self.pose_factory)?);
                }
                if let Some(publisher) = &self.pose_publisher
                    && publisher.send_copy(p).is_ok()
                {
                    self.counts.poses += 1;
                    let _ = self.ready.notify();
                }
            }
            Err(e) => self.refuse(e),
        }
        Ok(())
    }

    fn refuse(&mut self, e: codec::DecodeError) {
        self.counts.refused += 1;
        if self.counts.first_refusal.is_none() {
            eprintln!("sim-server bridge: refused: {e}");
            self.counts.first_refusal = Some(e.to_string());
        }
    }

    /// Withdraws the local publishers when a remote daemon's token goes
    /// (a publisher without a token, a script say, is left to the pose
    /// timeout).
    pub fn follow_daemon(&mut self) {
        let alive = self.daemon_alive.load(Ordering::Relaxed);
        if self.daemon_was_alive && !alive {
            self.pose_publisher = None;
            self.telemetry_publisher = None;
            self.counts.daemon_departures += 1;
        }
        self.daemon_was_alive = alive;
    }

    /// The bridge's own telemetry publisher (its batches are not relayed back).
    pub fn own_telemetry(&self) -> Option<UniquePublisherId> {
        self.telemetry_publisher.as_ref().map(|p| p.id())
    }

    /// The counters.
    pub fn counts(&self) -> &InCounts {
        &self.counts
    }
}
