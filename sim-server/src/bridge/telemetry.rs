//! Telemetry both ways (on the bulk thread): a local daemon's batches out
//! to zenoh; a remote daemon's batches into shared memory (for local
//! recorders and viewers) and back out to the other zenoh clients (zenoh
//! peers do not forward one client's messages to another, and clients
//! listen nowhere, so the bridge is their only path).

use super::BridgeError;
use super::outbound::{BULK, Relay};
use iceoryx2::port::publisher::Publisher;
use shared::SessionName;
use shared::protocol::TelemetryBatch;
use shared::remote::codec;
use shared::services::{self, Ipc, IpcNode};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::Subscriber;
use zenoh::sample::Sample;

/// Counters of the telemetry relay.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct TelemetryCounts {
    /// A local daemon's batches sent to zenoh.
    pub out: u64,
    /// Batches skipped before the bridge saw them.
    pub out_gaps: u64,
    /// A remote daemon's batches published into the session.
    pub r#in: u64,
    /// Remote batches refused (another protocol version or layout).
    pub refused: u64,
    /// Remote batches dropped because no remote daemon held its token.
    pub without_daemon: u64,
}

/// The telemetry relay.
pub struct TelemetryRelay {
    out: Relay<TelemetryBatch>,
    remote: Subscriber<FifoChannelHandler<Sample>>,
    factory: services::PortFactoryOf<TelemetryBatch>,
    publisher: Option<Publisher<Ipc, TelemetryBatch, ()>>,
    daemon_alive: Arc<AtomicBool>,
    key: String,
    counts: TelemetryCounts,
}

impl TelemetryRelay {
    /// Opens both directions; `daemon_alive`: a remote daemon's token.
    pub fn new(
        node: &IpcNode,
        session: &SessionName,
        z: &zenoh::Session,
        daemon_alive: Arc<AtomicBool>,
    ) -> Result<Self, BridgeError> {
        let factory = services::telemetry_service(node, session)?;
        let key = session.service(services::stream::TELEMETRY);
        let remote = super::subscribe_remote(z, &key)?;
        Ok(Self {
            out: Relay::new(&factory, 64, z, BULK, Some(|b: &TelemetryBatch| b.seq))?,
            remote,
            factory,
            publisher: None,
            daemon_alive,
            key,
            counts: TelemetryCounts::default(),
        })
    }

    /// Relays what arrived both ways.
    pub fn pump(&mut self) {
        let own = self.publisher.as_ref().map(|p| p.id());
        self.out.pump(own, None);
        let alive = self.daemon_alive.load(Ordering::Relaxed);
        if !alive {
            // The remote daemon went: its publisher leaves the session.
            self.publisher = None;
        }
        while let Ok(Some(s)) = self.remote.try_recv() {
            let bytes = s.payload().to_bytes();
            match codec::decode::<TelemetryBatch>(&self.key, &bytes) {
                Ok(b) if alive => {
                    if self.publisher.is_none() {
                        self.publisher = services::publisher(&self.factory).ok();
                    }
                    if let Some(p) = &self.publisher
                        && p.send_copy(b).is_ok()
                    {
                        self.counts.r#in += 1;
                    }
                    // To the other zenoh clients.
                    self.out.put_bytes(bytes.into_owned());
                }
                Ok(_) => self.counts.without_daemon += 1,
                Err(_) => self.counts.refused += 1,
            }
        }
    }

    /// The counters.
    pub fn counts(&self) -> TelemetryCounts {
        TelemetryCounts {
            out: self.out.sent,
            out_gaps: self.out.gaps,
            ..self.counts
        }
    }
}
