//! The iceoryx2 services of a session: names, settings and opening them with
//! the protocol version as a service attribute, so that a peer of another
//! version is refused when it opens a service, with a message saying so.

use crate::SessionName;
use crate::ipc_root::{IpcRoot, IpcRootError, SHM_DIR, ipc_root, make_segments_private};
use crate::protocol::{
    ForceMsg, LocalContactMsg, MeshHeader, PROTOCOL_VERSION, PoseMsg, RestHeader, SceneInfo,
    TelemetryBatch, TopologyHeader,
};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
/// Brings `update_connections` into scope: a publisher that sends rarely
/// (the topology stream) delivers its history to late subscribers with it.
pub use iceoryx2::port::update_connections::UpdateConnections;
pub use iceoryx2::prelude::ZeroCopySend;
use iceoryx2::prelude::*;
use iceoryx2::service::attribute::{AttributeKey, AttributeValue, AttributeVerifier};
use iceoryx2::service::builder::event::{EventOpenError, EventOpenOrCreateError};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use thiserror::Error;

/// The attribute key that carries the protocol version on every service.
pub const VERSION_KEY: &str = "hapsim.protocol";

/// Stream names (suffixes of `hapsim/<session>/`).
pub mod stream {
    /// Daemon -> sim tool poses.
    pub const POSE: &str = "pose";
    /// Sim -> daemon force samples.
    pub const FORCE: &str = "force";
    /// Daemon -> recorder telemetry.
    pub const TELEMETRY: &str = "telemetry";
    /// Sim -> viewer vertex positions.
    pub const MESH: &str = "mesh";
    /// Sim -> viewer surface triangles (on topology changes).
    pub const TOPOLOGY: &str = "topology";
    /// Daemon -> sim event: a pose was just published (optional; the
    /// simulation steps on it instead of waiting for its next step time).
    pub const POSE_READY: &str = "pose-ready";
    /// Sim -> clients: the scene's tools and organ, once (history 1).
    pub const SCENE: &str = "scene";
    /// Sim -> clients: rest positions and fibres, once.
    pub const REST: &str = "rest";
    /// Sim -> clients: the surface as built, before any cut, once.
    pub const SURFACE0: &str = "surface0";
    /// Sim -> daemon: the contact problem around a tool.
    pub const LOCAL_CONTACT: &str = "local-contact";
}

/// Why a service could not be used.
#[derive(Debug, Error)]
pub enum ServiceError {
    /// This user's private root is unusable.
    #[error(transparent)]
    Root(#[from] IpcRootError),
    /// The node could not be created.
    #[error("cannot create the iceoryx2 node {name:?}: {reason}")]
    Node {
        /// Node name.
        name: String,
        /// iceoryx2's error.
        reason: String,
    },
    /// The service exists with another protocol version or payload layout.
    #[error(
        "service {service} speaks another protocol version or payload layout (this program speaks version {PROTOCOL_VERSION}): rebuild both sides from the same release ({reason})"
    )]
    Version {
        /// Service name.
        service: String,
        /// iceoryx2's error.
        reason: String,
    },
    /// The stream already has as many publishers as it takes.
    #[error(
        "{service} already has its {max} publishers (a session's pose stream takes a haptic daemon and a scripted client, say): stop one of them first"
    )]
    Full {
        /// Service name.
        service: String,
        /// Publishers it takes.
        max: usize,
    },
    /// Any other failure to open or create a service or port.
    #[error("cannot open {service}: {reason}")]
    Open {
        /// Service name.
        service: String,
        /// iceoryx2's error.
        reason: String,
    },
}

/// The iceoryx2 service type of the project: inter-process, shared memory.
pub type Ipc = ipc::Service;
/// An iceoryx2 node of the project (for crates that do not use iceoryx2 directly).
pub type IpcNode = Node<Ipc>;
/// The pose service.
pub type PoseService = PortFactory<Ipc, PoseMsg, ()>;
/// The service of a fixed-size stream of `T`.
pub type PortFactoryOf<T> = PortFactory<Ipc, T, ()>;
/// Who published a sample (its header's publisher id).
pub type PublisherId = iceoryx2::identifiers::UniquePublisherId;
/// A pose subscriber.
pub type PoseSubscriber = Subscriber<Ipc, PoseMsg, ()>;
/// A listener on the pose-ready event.
pub type PoseReadyListener = Listener<Ipc>;
/// A force subscriber.
pub type ForceSubscriber = Subscriber<Ipc, ForceMsg, ()>;
/// Publisher of force samples (the simulation's, one per session).
pub type ForcePublisher = Publisher<Ipc, ForceMsg, ()>;
/// Sim -> daemon contact-problem publisher.
pub type LocalContactPublisher = Publisher<Ipc, LocalContactMsg, ()>;
/// Daemon side of the contact-problem stream.
pub type LocalContactSubscriber = Subscriber<Ipc, LocalContactMsg, ()>;
/// Publisher of the scene-info stream.
pub type ScenePublisher = Publisher<Ipc, SceneInfo, ()>;
/// Subscriber of the scene-info stream.
pub type SceneSubscriber = Subscriber<Ipc, SceneInfo, ()>;
/// Publisher of a slice stream (`mesh`, `topology`) with its user header.
pub type SlicePublisher<T, H> = Publisher<Ipc, [T], H>;

/// Creates a node named `name` (shows in iceoryx2's node listings), in this
/// user's private root ([`crate::ipc_root`]). Signal handling stays with
/// the program, which must zero forces itself.
pub fn node(name: &str) -> Result<Node<Ipc>, ServiceError> {
    let err = |reason: String| ServiceError::Node {
        name: name.to_string(),
        reason,
    };
    // iceoryx2 warns on stderr that it runs without a config file; that is
    // the intended set-up here, so only errors are shown.
    set_log_level(LogLevel::Error);
    let (config, root) = private_config()?;
    let node_name = NodeName::new(name).map_err(|e| err(format!("{e:?}")))?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .config(config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Ipc>()
        .map_err(|e| err(format!("{e:?}")))?;
    // The global management segment exists now, 0666 as iceoryx2 makes it.
    make_segments_private(std::path::Path::new(SHM_DIR), &root.prefix, root.uid);
    Ok(node)
}

/// This user's iceoryx2 configuration (root and prefix of
/// [`crate::ipc_root::ipc_root`]), checked once per process.
pub fn private_config() -> Result<&'static (Config, IpcRoot), ServiceError> {
    static CONFIG: std::sync::OnceLock<Result<(Config, IpcRoot), IpcRootError>> =
        std::sync::OnceLock::new();
    CONFIG
        .get_or_init(|| {
            let root = ipc_root()?;
            let bad = |what: &str, e: String| IpcRootError::Io {
                path: root.dir.clone(),
                reason: format!("iceoryx2 refuses it as {what}: {e}"),
            };
            let mut config = Config::default();
            let dir = root.dir.as_os_str().as_encoded_bytes();
            let path =
                iceoryx2::prelude::Path::new(dir).map_err(|e| bad("root", format!("{e:?}")))?;
            config.global.set_root_path(&path);
            config.global.prefix = FileName::new(root.prefix.as_bytes())
                .map_err(|e| bad("prefix", format!("{e:?}")))?;
            Ok((config, root))
        })
        .as_ref()
        .map_err(|e| ServiceError::Root(e.clone()))
}

fn verifier(service: &str) -> Result<AttributeVerifier, ServiceError> {
    let open = |reason: String| ServiceError::Open {
        service: service.to_string(),
        reason,
    };
    let key = AttributeKey::new(VERSION_KEY.as_bytes()).map_err(|e| open(format!("{e:?}")))?;
    let value = AttributeValue::new(PROTOCOL_VERSION.to_string().as_bytes())
        .map_err(|e| open(format!("{e:?}")))?;
    AttributeVerifier::new()
        .require(&key, &value)
        .map_err(|e| open(format!("{e:?}")))
}

/// A publish-subscribe service of `T` in `session`.
fn open<T: std::fmt::Debug + ZeroCopySend>(
    node: &Node<Ipc>,
    session: &SessionName,
    stream: &str,
    buffer: usize,
) -> Result<PortFactory<Ipc, T, ()>, ServiceError> {
    let name = session.service(stream);
    let service_name = ServiceName::new(&name).map_err(|e| name_error(&name, e))?;
    node.service_builder(&service_name)
        .publish_subscribe::<T>()
        .max_publishers(2)
        .max_subscribers(8)
        .history_size(1)
        .subscriber_max_buffer_size(buffer)
        .enable_safe_overflow(true)
        .open_or_create_with_attributes(&verifier(&name)?)
        .map_err(|e| pubsub_error(&name, e))
}

/// Force samples a subscriber may keep: a recorder asks for all of them
/// (a second at 1 kHz), the daemon for [`FORCE_BUFFER_LATEST`].
pub const FORCE_BUFFER_MAX: usize = 1024;
/// The daemon's and viewer's force buffer: only the newest samples matter.
pub const FORCE_BUFFER_LATEST: usize = 4;

/// The force stream (sim -> daemon, recorder, viewer): newest kept on
/// overflow, each subscriber choosing its buffer up to [`FORCE_BUFFER_MAX`].
pub fn force_service(
    node: &Node<Ipc>,
    session: &SessionName,
) -> Result<PortFactory<Ipc, ForceMsg, ()>, ServiceError> {
    open(node, session, stream::FORCE, FORCE_BUFFER_MAX)
}

/// The local-contact service.
pub type LocalContactService = PortFactory<Ipc, LocalContactMsg, ()>;

/// The local-contact stream (sim -> daemon): the contact problem around
/// a tool, newest kept on overflow (the daemon needs only the latest).
pub fn local_contact_service(
    node: &Node<Ipc>,
    session: &SessionName,
) -> Result<LocalContactService, ServiceError> {
    open(node, session, stream::LOCAL_CONTACT, FORCE_BUFFER_LATEST)
}

/// The scene-info stream (sim -> clients): published once at start, kept
/// in history for clients that join later.
pub fn scene_service(
    node: &Node<Ipc>,
    session: &SessionName,
) -> Result<PortFactory<Ipc, SceneInfo, ()>, ServiceError> {
    open(node, session, stream::SCENE, 1)
}

/// The pose stream (daemon -> sim): latest value, so a buffer of one.
pub fn pose_service(
    node: &Node<Ipc>,
    session: &SessionName,
) -> Result<PortFactory<Ipc, PoseMsg, ()>, ServiceError> {
    open(node, session, stream::POSE, 1)
}

/// The telemetry stream (daemon -> recorders): every batch matters, deep buffer.
pub fn telemetry_service(
    node: &Node<Ipc>,
    session: &SessionName,
) -> Result<PortFactory<Ipc, TelemetryBatch, ()>, ServiceError> {
    open(node, session, stream::TELEMETRY, 64)
}

/// The pose-ready event (daemon -> sim): whoever publishes a pose may
/// notify it right after, so that a simulation waiting for its next step
/// wakes at once and steps on the fresh pose (see `docs/protocol.md`). A pose
/// publisher that does not notify still works: the simulation then steps at
/// its own rate.
pub fn pose_ready_service(
    node: &Node<Ipc>,
    session: &SessionName,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<Ipc>, ServiceError> {
    let name = session.service(stream::POSE_READY);
    let service_name = ServiceName::new(&name).map_err(|e| name_error(&name, e))?;
    node.service_builder(&service_name)
        .event()
        .max_notifiers(2)
        .max_listeners(8)
        .open_or_create_with_attributes(&verifier(&name)?)
        .map_err(|e| event_error(&name, e))
}

/// A notifier on the pose-ready event.
pub fn pose_ready_notifier(
    node: &Node<Ipc>,
    session: &SessionName,
) -> Result<Notifier<Ipc>, ServiceError> {
    let factory = pose_ready_service(node, session)?;
    factory
        .notifier_builder()
        .create()
        .map_err(|e| ServiceError::Open {
            service: factory.name().to_string(),
            reason: format!("{e:?}"),
        })
}

/// A listener on the pose-ready event.
pub fn pose_ready_listener(
    node: &Node<Ipc>,
    session: &SessionName,
) -> Result<Listener<Ipc>, ServiceError> {
    let factory = pose_ready_service(node, session)?;
    factory
        .listener_builder()
        .create()
        .map_err(|e| ServiceError::Open {
            service: factory.name().to_string(),
            reason: format!("{e:?}"),
        })
}

/// Waits up to `timeout` for a notification on `listener`, then takes every
/// pending one; true when woken by one (false: timed out, interrupted).
///
/// `ppoll` on the listener's socket, with a nanosecond timeout: iceoryx2's
/// own `timed_wait` sets a socket receive timeout, which the kernel rounds
/// up to its tick (4 ms at 250 Hz) and which blocks for ever when the
/// timeout truncates to zero microseconds.
pub fn wait_notified(listener: &Listener<Ipc>, timeout: std::time::Duration) -> bool {
    use iceoryx2::prelude::FileDescriptorBased;
    // SAFETY: the descriptor stays owned by the listener, which outlives
    // this call; it is only polled here.
    let fd = unsafe { listener.file_descriptor().native_handle() };
    let mut pfd = libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    };
    let ts = libc::timespec {
        tv_sec: timeout.as_secs().min(i32::MAX as u64) as libc::time_t,
        tv_nsec: timeout.subsec_nanos() as libc::c_long,
    };
    // SAFETY: one pollfd and one timespec on the stack, valid for the call;
    // no signal mask.
    let ready = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
    if ready > 0 {
        let _ = listener.try_wait(|_| {});
        true
    } else {
        false
    }
}

/// An error opening or creating a service; a payload type or protocol
/// version attribute that differs from an existing service's (made by a
/// peer of another protocol version) is [`ServiceError::Version`].
fn service_error(service: &str, version_mismatch: bool, reason: String) -> ServiceError {
    let service = service.to_string();
    if version_mismatch {
        ServiceError::Version { service, reason }
    } else {
        ServiceError::Open { service, reason }
    }
}

/// [`service_error`] for a publish-subscribe service.
fn pubsub_error(service: &str, e: PublishSubscribeOpenOrCreateError) -> ServiceError {
    use PublishSubscribeOpenError::{IncompatibleAttributes, IncompatibleTypes};
    let version = matches!(
        e,
        PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
            IncompatibleTypes | IncompatibleAttributes
        )
    );
    service_error(service, version, format!("{e:?}"))
}

/// [`service_error`] for an event service.
fn event_error(service: &str, e: EventOpenOrCreateError) -> ServiceError {
    let version = matches!(
        e,
        EventOpenOrCreateError::EventOpenError(EventOpenError::IncompatibleAttributes)
    );
    service_error(service, version, format!("{e:?}"))
}

/// A service name that iceoryx2 refuses (too long, bad characters).
fn name_error(service: &str, e: impl std::fmt::Debug) -> ServiceError {
    service_error(service, false, format!("{e:?}"))
}

/// A slice service of `T` with user header `H` (history 1: a viewer that
/// joins late still gets the latest frame or topology).
fn open_slice<T: std::fmt::Debug + ZeroCopySend, H: std::fmt::Debug + ZeroCopySend>(
    node: &Node<Ipc>,
    session: &SessionName,
    stream: &str,
) -> Result<PortFactory<Ipc, [T], H>, ServiceError> {
    let name = session.service(stream);
    let service_name = ServiceName::new(&name).map_err(|e| name_error(&name, e))?;
    node.service_builder(&service_name)
        .publish_subscribe::<[T]>()
        .user_header::<H>()
        .max_publishers(2)
        .max_subscribers(8)
        .history_size(1)
        .subscriber_max_buffer_size(2)
        .enable_safe_overflow(true)
        .open_or_create_with_attributes(&verifier(&name)?)
        .map_err(|e| pubsub_error(&name, e))
}

/// The mesh-state stream (sim -> viewer): positions as `[f32; 3]` (m) with a
/// [`MeshHeader`], 30-60 Hz.
pub fn mesh_service(
    node: &Node<Ipc>,
    session: &SessionName,
) -> Result<PortFactory<Ipc, [[f32; 3]], MeshHeader>, ServiceError> {
    open_slice(node, session, stream::MESH)
}

/// The topology stream (sim -> viewer): outward surface triangles as
/// `[u32; 3]` with a [`TopologyHeader`], sent when cuts change the surface.
pub fn topology_service(
    node: &Node<Ipc>,
    session: &SessionName,
) -> Result<PortFactory<Ipc, [[u32; 3]], TopologyHeader>, ServiceError> {
    open_slice(node, session, stream::TOPOLOGY)
}

/// The rest stream (sim -> clients): rest positions and fibres with a
/// [`RestHeader`], published once at start (history 1).
pub fn rest_service(
    node: &Node<Ipc>,
    session: &SessionName,
) -> Result<PortFactory<Ipc, [[f32; 3]], RestHeader>, ServiceError> {
    open_slice(node, session, stream::REST)
}

/// The original-surface stream (sim -> clients): the outward surface
/// triangles as the scene built them, before any cut, with a
/// [`TopologyHeader`] of `topology_version` 1, published once at start
/// (history 1): a viewer tells the faces cuts made from it.
pub fn surface0_service(
    node: &Node<Ipc>,
    session: &SessionName,
) -> Result<PortFactory<Ipc, [[u32; 3]], TopologyHeader>, ServiceError> {
    open_slice(node, session, stream::SURFACE0)
}

/// A subscriber on a slice stream (`mesh`, `topology`, `rest`, `surface0`).
pub fn slice_subscriber<T: std::fmt::Debug + ZeroCopySend, H: std::fmt::Debug + ZeroCopySend>(
    factory: &PortFactory<Ipc, [T], H>,
) -> Result<Subscriber<Ipc, [T], H>, ServiceError> {
    factory
        .subscriber_builder()
        .create()
        .map_err(|e| ServiceError::Open {
            service: factory.name().to_string(),
            reason: format!("{e:?}"),
        })
}

/// A slice publisher able to loan `max_len` elements without reallocating
/// (larger loans grow the pool by powers of two).
pub fn slice_publisher<T: std::fmt::Debug + ZeroCopySend, H: std::fmt::Debug + ZeroCopySend>(
    factory: &PortFactory<Ipc, [T], H>,
    max_len: usize,
) -> Result<Publisher<Ipc, [T], H>, ServiceError> {
    factory
        .publisher_builder()
        .initial_max_slice_len(max_len.max(1))
        .allocation_strategy(AllocationStrategy::PowerOfTwo)
        .create()
        .map_err(|e| ServiceError::Open {
            service: factory.name().to_string(),
            reason: format!("{e:?}"),
        })
}

/// Removes the ports and shared memory of processes that died without
/// cleaning up (SIGKILL, crash), so a restarted peer starts clean.
pub fn reap_dead_nodes(node: &Node<Ipc>) {
    let _ = Node::<Ipc>::list(node.config(), |state| {
        if let NodeState::Dead(view) = state {
            let _ = view.try_remove_stale_resources();
        }
        CallbackProgression::Continue
    });
}

/// Live publishers on `factory`'s service.
pub fn publisher_count<T: std::fmt::Debug + ZeroCopySend>(
    factory: &PortFactory<Ipc, T, ()>,
) -> usize {
    factory.dynamic_config().number_of_publishers()
}

/// Subscribers currently connected to `factory`'s service.
pub fn subscriber_count<T: std::fmt::Debug + ZeroCopySend>(
    factory: &PortFactory<Ipc, T, ()>,
) -> usize {
    factory.dynamic_config().number_of_subscribers()
}

/// A publisher on `factory`.
pub fn publisher<T: std::fmt::Debug + ZeroCopySend>(
    factory: &PortFactory<Ipc, T, ()>,
) -> Result<Publisher<Ipc, T, ()>, ServiceError> {
    factory.publisher_builder().create().map_err(|e| match e {
        iceoryx2::port::publisher::PublisherCreateError::ExceedsMaxSupportedPublishers => {
            ServiceError::Full {
                service: factory.name().to_string(),
                max: factory.static_config().max_publishers(),
            }
        }
        e => ServiceError::Open {
            service: factory.name().to_string(),
            reason: format!("{e:?}"),
        },
    })
}

/// A subscriber on `factory` keeping at most `buffer` unread samples (the
/// oldest dropped first).
pub fn subscriber_with_buffer<T: std::fmt::Debug + ZeroCopySend>(
    factory: &PortFactory<Ipc, T, ()>,
    buffer: usize,
) -> Result<Subscriber<Ipc, T, ()>, ServiceError> {
    factory
        .subscriber_builder()
        .buffer_size(buffer)
        .create()
        .map_err(|e| ServiceError::Open {
            service: factory.name().to_string(),
            reason: format!("{e:?}"),
        })
}

/// A subscriber on `factory` with the service's largest buffer.
pub fn subscriber<T: std::fmt::Debug + ZeroCopySend>(
    factory: &PortFactory<Ipc, T, ()>,
) -> Result<Subscriber<Ipc, T, ()>, ServiceError> {
    factory
        .subscriber_builder()
        .create()
        .map_err(|e| ServiceError::Open {
            service: factory.name().to_string(),
            reason: format!("{e:?}"),
        })
}

#[cfg(test)]
mod tests;
