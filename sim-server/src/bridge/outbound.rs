//! Shared memory -> zenoh: every stream the simulation publishes, relayed
//! as it arrives, in two parts on two threads so that a slow viewer link
//! never holds up a haptic one. [`LiveOut`] (the bridge's main loop): force
//! samples and the contact problem, at zenoh's real-time priority, dropped
//! rather than queued when the link is congested (a late sample is worth
//! nothing to a haptic loop; sequence gaps are counted). [`BulkOut`] (its
//! own thread): mesh frames (dropped under congestion) and the
//! once-published streams (`scene`, `rest`, `surface0`, `topology`), sent
//! reliably, their newest message kept to answer a client that joins later.

use super::BridgeError;
use shared::SessionName;
use shared::protocol::{
    ForceMsg, LocalContactMsg, MeshHeader, RestHeader, SceneInfo, TopologyHeader,
};
use shared::remote::codec;
use shared::services::{self, Ipc, IpcNode, ZeroCopySend};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use zenoh::Wait;
use zenoh::qos::{CongestionControl, Priority};

use iceoryx2::identifiers::UniquePublisherId;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

/// The newest bytes of each once-published stream, by key.
pub type Kept = Arc<Mutex<HashMap<String, Vec<u8>>>>;

/// How a stream goes on zenoh.
#[derive(Clone, Copy)]
pub(super) struct Qos {
    priority: Priority,
    congestion: CongestionControl,
    express: bool,
}

/// Samples on time or not at all.
const LIVE: Qos = Qos {
    priority: Priority::RealTime,
    congestion: CongestionControl::Drop,
    express: true,
};
/// Frames and telemetry: dropped under congestion, not hurried.
pub(super) const BULK: Qos = Qos {
    priority: Priority::Data,
    congestion: CongestionControl::Drop,
    express: false,
};
/// What a client must not miss.
const RELIABLE: Qos = Qos {
    priority: Priority::Data,
    congestion: CongestionControl::Block,
    express: false,
};

pub(super) fn declare(
    z: &zenoh::Session,
    key: &str,
    qos: Qos,
) -> Result<zenoh::pubsub::Publisher<'static>, BridgeError> {
    z.declare_publisher(key.to_string())
        .priority(qos.priority)
        .congestion_control(qos.congestion)
        .express(qos.express)
        .wait()
        .map_err(|e| shared::remote::RemoteError::declare(key, e).into())
}

/// A relay of one fixed-size stream.
pub(super) struct Relay<T: std::fmt::Debug + ZeroCopySend + 'static> {
    subscriber: Subscriber<Ipc, T, ()>,
    publisher: zenoh::pubsub::Publisher<'static>,
    seq_of: Option<fn(&T) -> u64>,
    last_seq: Option<u64>,
    /// Messages relayed.
    pub sent: u64,
    /// Sequence numbers skipped before the bridge saw them.
    pub gaps: u64,
}

impl<T: std::fmt::Debug + ZeroCopySend + bytemuck::Pod> Relay<T> {
    pub(super) fn new(
        factory: &PortFactory<Ipc, T, ()>,
        buffer: usize,
        z: &zenoh::Session,
        qos: Qos,
        seq_of: Option<fn(&T) -> u64>,
    ) -> Result<Self, BridgeError> {
        Ok(Self {
            subscriber: services::subscriber_with_buffer(factory, buffer)?,
            publisher: declare(z, factory.name().as_str(), qos)?,
            seq_of,
            last_seq: None,
            sent: 0,
            gaps: 0,
        })
    }

    /// Relays what arrived, skipping `own`'s messages (the bridge's own
    /// publisher of the remote side's messages); how many went.
    pub(super) fn pump(&mut self, own: Option<UniquePublisherId>, kept: Option<&Kept>) -> u64 {
        let mut n = 0;
        while let Ok(Some(sample)) = self.subscriber.receive() {
            if own.is_some_and(|id| sample.origin() == id) {
                continue;
            }
            if let Some(seq_of) = self.seq_of {
                let seq = seq_of(&sample);
                match self.last_seq {
                    Some(last) if seq > last + 1 => self.gaps += seq - last - 1,
                    _ => {}
                }
                self.last_seq = Some(seq);
            }
            let bytes = codec::encode(&*sample);
            if let Some(k) = kept
                && let Ok(mut k) = k.lock()
            {
                k.insert(self.publisher.key_expr().to_string(), bytes.clone());
            }
            if self.publisher.put(bytes).wait().is_ok() {
                n += 1;
            }
        }
        self.sent += n;
        n
    }

    /// Puts `bytes` (an encoded message from elsewhere) on the stream.
    pub(super) fn put_bytes(&self, bytes: Vec<u8>) {
        let _ = self.publisher.put(bytes).wait();
    }
}

/// A relay of a header-and-slice stream.
struct SliceRelay<
    H: std::fmt::Debug + ZeroCopySend + 'static,
    T: std::fmt::Debug + ZeroCopySend + 'static,
> {
    subscriber: Subscriber<Ipc, [T], H>,
    publisher: zenoh::pubsub::Publisher<'static>,
    keep: bool,
    sent: u64,
}

impl<H, T> SliceRelay<H, T>
where
    H: std::fmt::Debug + ZeroCopySend + bytemuck::Pod,
    T: std::fmt::Debug + ZeroCopySend + bytemuck::Pod,
{
    fn new(
        factory: &PortFactory<Ipc, [T], H>,
        z: &zenoh::Session,
        qos: Qos,
        keep: bool,
    ) -> Result<Self, BridgeError> {
        Ok(Self {
            subscriber: services::slice_subscriber(factory)?,
            publisher: declare(z, factory.name().as_str(), qos)?,
            keep,
            sent: 0,
        })
    }

    fn pump(&mut self, kept: &Kept) -> u64 {
        let mut n = 0;
        while let Ok(Some(sample)) = self.subscriber.receive() {
            let bytes = codec::encode_slice(sample.user_header(), sample.payload());
            if self.keep
                && let Ok(mut k) = kept.lock()
            {
                k.insert(self.publisher.key_expr().to_string(), bytes.clone());
            }
            if self.publisher.put(bytes).wait().is_ok() {
                n += 1;
            }
        }
        self.sent += n;
        n
    }
}

/// Counters of the outbound side.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct OutCounts {
    /// Force samples relayed.
    pub force: u64,
    /// Force samples the simulation sent that the bridge never saw (its
    /// buffer overflowed).
    pub force_gaps: u64,
    /// Contact problems relayed.
    pub local_contact: u64,
    /// Mesh frames relayed.
    pub mesh: u64,
    /// Topology, scene, rest and original-surface messages relayed.
    pub scene_streams: u64,
}

/// The haptic streams (the bridge's main loop).
pub struct LiveOut {
    force_factory: PortFactory<Ipc, ForceMsg, ()>,
    force: Relay<ForceMsg>,
    local_contact_factory: PortFactory<Ipc, LocalContactMsg, ()>,
    local_contact_publisher: zenoh::pubsub::Publisher<'static>,
    /// Subscribed only while a remote client wants contact problems (the
    /// simulation computes them only while someone subscribes).
    local_contact: Option<Subscriber<Ipc, LocalContactMsg, ()>>,
    local_contact_sent: u64,
}

impl LiveOut {
    /// Opens the force and contact-problem streams of `session`.
    pub fn new(
        node: &IpcNode,
        session: &SessionName,
        z: &zenoh::Session,
    ) -> Result<Self, BridgeError> {
        let force_factory = services::force_service(node, session)?;
        Ok(Self {
            force: Relay::new(
                &force_factory,
                services::FORCE_BUFFER_MAX,
                z,
                LIVE,
                Some(|m: &ForceMsg| m.seq),
            )?,
            force_factory,
            local_contact_factory: services::local_contact_service(node, session)?,
            local_contact_publisher: declare(
                z,
                &session.service(services::stream::LOCAL_CONTACT),
                LIVE,
            )?,
            local_contact: None,
            local_contact_sent: 0,
        })
    }

    /// Relays what arrived.
    pub fn pump(&mut self) {
        self.force.pump(None, None);
        if let Some(sub) = &self.local_contact {
            while let Ok(Some(sample)) = sub.receive() {
                if self
                    .local_contact_publisher
                    .put(codec::encode(&*sample))
                    .wait()
                    .is_ok()
                {
                    self.local_contact_sent += 1;
                }
            }
        }
    }

    /// Subscribes to the contact problems while a remote client wants them,
    /// and lets go when none does (a failure is retried at the next check).
    pub fn follow_local_contact_interest(&mut self) {
        let wanted = self
            .local_contact_publisher
            .matching_status()
            .wait()
            .is_ok_and(|m| m.matching());
        match (&self.local_contact, wanted) {
            (None, true) => {
                self.local_contact = services::subscriber_with_buffer(
                    &self.local_contact_factory,
                    services::FORCE_BUFFER_LATEST,
                )
                .ok()
            }
            (Some(_), false) => self.local_contact = None,
            _ => {}
        }
    }

    /// Whether a simulation publishes force samples in the session.
    pub fn sim_present(&self) -> bool {
        services::publisher_count(&self.force_factory) > 0
    }

    /// The counters (the bulk ones zero).
    pub fn counts(&self) -> OutCounts {
        OutCounts {
            force: self.force.sent,
            force_gaps: self.force.gaps,
            local_contact: self.local_contact_sent,
            ..OutCounts::default()
        }
    }
}

/// The viewer's streams (a thread of their own).
pub struct BulkOut {
    scene: Relay<SceneInfo>,
    mesh: SliceRelay<MeshHeader, [f32; 3]>,
    topology: SliceRelay<TopologyHeader, [u32; 3]>,
    rest: SliceRelay<RestHeader, [f32; 3]>,
    surface0: SliceRelay<TopologyHeader, [u32; 3]>,
    /// The once-published streams' newest bytes.
    pub kept: Kept,
}

impl BulkOut {
    /// Opens the scene and mesh streams of `session`.
    pub fn new(
        node: &IpcNode,
        session: &SessionName,
        z: &zenoh::Session,
        kept: Kept,
    ) -> Result<Self, BridgeError> {
        Ok(Self {
            scene: Relay::new(
                &services::scene_service(node, session)?,
                1,
                z,
                RELIABLE,
                None,
            )?,
            mesh: SliceRelay::new(&services::mesh_service(node, session)?, z, BULK, false)?,
            topology: SliceRelay::new(
                &services::topology_service(node, session)?,
                z,
                RELIABLE,
                true,
            )?,
            rest: SliceRelay::new(&services::rest_service(node, session)?, z, RELIABLE, true)?,
            surface0: SliceRelay::new(
                &services::surface0_service(node, session)?,
                z,
                RELIABLE,
                true,
            )?,
            kept,
        })
    }

    /// Relays what arrived.
    pub fn pump(&mut self) {
        self.scene.pump(None, Some(&self.kept));
        self.mesh.pump(&self.kept);
        self.topology.pump(&self.kept);
        self.rest.pump(&self.kept);
        self.surface0.pump(&self.kept);
    }

    /// The counters (the live ones zero).
    pub fn counts(&self) -> OutCounts {
        OutCounts {
            mesh: self.mesh.sent,
            scene_streams: self.scene.sent
                + self.topology.sent
                + self.rest.sent
                + self.surface0.sent,
            ..OutCounts::default()
        }
    }
}
