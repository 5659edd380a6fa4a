//! How the daemon reaches its session: shared memory on the simulation's
//! host (the default), or zenoh through `sim-server bridge` on another host
//! (`--connect ENDPOINT`), touching no shared memory at all. The RT thread
//! reads force samples through [`Source`] either way; the I/O thread's
//! outputs are [`IoPorts`].

use shared::SessionName;
use shared::protocol::{ForceMsg, LocalContactMsg, PoseMsg, SceneInfo, TelemetryBatch};
use shared::reaper::Reaper;
use shared::remote::{Inbox, Link, RemoteError, RemotePublisher};
use shared::services::{self, Ipc, IpcNode, ServiceError};
use shared::source::Source;
use std::sync::Arc;
use std::time::Duration;
use thiserror::Error;

/// How often dead peers' resources are removed (shared memory).
const REAP_EVERY: Duration = Duration::from_millis(20);

/// How long [`Transport::scene_now`] waits for a simulation's scene stream
/// once its force stream is open.
const SCENE_STREAM_WAIT: Duration = Duration::from_millis(100);

/// Force samples a remote daemon's ring holds (64 ms at 1 kHz).
const REMOTE_FORCE_RING: usize = 64;
/// Contact problems a remote daemon's ring holds (problems come at most
/// every 8 ms; the set-up thread, at the lowest priority, takes the newest).
const REMOTE_PROBLEM_RING: usize = 16;

/// Why a port could not be opened.
#[derive(Debug, Error)]
pub enum TransportError {
    /// Shared memory.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// zenoh.
    #[error(transparent)]
    Remote(#[from] RemoteError),
}

/// Shared memory or a zenoh link.
#[derive(Clone)]
pub enum Transport {
    /// iceoryx2 on this host.
    Shm,
    /// zenoh through a bridge.
    Remote(Arc<Link>),
}

impl Transport {
    /// The force samples, for the RT thread (opened on it: iceoryx2 ports
    /// stay on the thread that made them). `node` names the shared-memory
    /// node (unused remotely).
    pub fn force_source(
        &self,
        node: &str,
        session: &SessionName,
        buffer: usize,
    ) -> Result<(Source<ForceMsg>, Option<IpcNode>), TransportError> {
        Ok(match self {
            Transport::Shm => {
                let n = services::node(node)?;
                let sub = services::subscriber_with_buffer(
                    &services::force_service(&n, session)?,
                    buffer,
                )?;
                (Source::Shm(sub), Some(n))
            }
            // A full ring refuses the newest: room for a network burst (the
            // tick drains them all; the newest wins).
            Transport::Remote(link) => (
                Source::Remote(Inbox::subscribe(
                    link,
                    services::stream::FORCE,
                    buffer.max(REMOTE_FORCE_RING),
                )?),
                None,
            ),
        })
    }

    /// The contact problems around tool 0 (newest few).
    pub fn local_contact_source(
        &self,
        session: &SessionName,
    ) -> Result<(Source<LocalContactMsg>, Option<IpcNode>), TransportError> {
        Ok(match self {
            Transport::Shm => {
                let n = services::node("haptic-daemon-local")?;
                let sub = services::subscriber_with_buffer(
                    &services::local_contact_service(&n, session)?,
                    services::FORCE_BUFFER_LATEST,
                )?;
                (Source::Shm(sub), Some(n))
            }
            Transport::Remote(link) => (
                Source::Remote(Inbox::subscribe(
                    link,
                    services::stream::LOCAL_CONTACT,
                    REMOTE_PROBLEM_RING,
                )?),
                None,
            ),
        })
    }

    /// The scene's description, if a simulation is there to give it
    /// within `wait` (it publishes it once at start and keeps it for
    /// clients that join later); `None` at once when no simulation is
    /// there (nobody publishes the stream; remotely: no bridge with a
    /// simulation behind it). On shared memory a simulation opens its
    /// force stream just before its scene stream: with only the former
    /// there, the scene stream is waited for `SCENE_STREAM_WAIT` (a
    /// client publishing forces without a scene, as the tests' stand-ins
    /// do, costs the daemon no more).
    pub fn scene_now(
        &self,
        session: &SessionName,
        wait: Duration,
    ) -> Result<Option<SceneInfo>, TransportError> {
        let start = std::time::Instant::now();
        let (mut source, _node) = match self {
            Transport::Shm => {
                let n = services::node("haptic-daemon-scene")?;
                let service = services::scene_service(&n, session)?;
                let force = services::force_service(&n, session)?;
                loop {
                    if services::publisher_count(&service) > 0 {
                        break;
                    }
                    if services::publisher_count(&force) == 0
                        || start.elapsed() >= SCENE_STREAM_WAIT
                    {
                        return Ok(None);
                    }
                    std::thread::sleep(Duration::from_millis(2));
                }
                (Source::Shm(services::subscriber(&service)?), Some(n))
            }
            Transport::Remote(link) => {
                if !link.sim_alive() {
                    return Ok(None);
                }
                let inbox = Inbox::subscribe_with_query(link, services::stream::SCENE, 2)?;
                (Source::Remote(inbox), None)
            }
        };
        loop {
            if let Some(info) = source.pop() {
                return Ok(Some(info));
            }
            if start.elapsed() >= wait {
                return Ok(None);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// The telemetry batches (a recorder's: every one).
    pub fn telemetry_source(
        &self,
        node: &str,
        session: &SessionName,
    ) -> Result<(Source<TelemetryBatch>, Option<IpcNode>), TransportError> {
        Ok(match self {
            Transport::Shm => {
                let n = services::node(node)?;
                let sub = services::subscriber(&services::telemetry_service(&n, session)?)?;
                (Source::Shm(sub), Some(n))
            }
            Transport::Remote(link) => (
                Source::Remote(Inbox::subscribe(link, services::stream::TELEMETRY, 256)?),
                None,
            ),
        })
    }
}

/// The I/O thread's outputs: poses (with the `pose-ready` event on shared
/// memory), telemetry, and whether a simulation is there.
pub enum IoPorts {
    /// iceoryx2.
    Shm(Box<ShmPorts>),
    /// zenoh: poses and telemetry stamped in the simulation host's clock.
    Remote(Box<RemotePorts>),
}

/// The I/O thread's zenoh ports.
pub struct RemotePorts {
    /// The link.
    link: Arc<Link>,
    /// Poses.
    pose: RemotePublisher,
    /// Telemetry.
    telemetry: RemotePublisher,
    /// Held while this daemon publishes poses: the bridge withdraws its
    /// pose publisher when it goes.
    _token: shared::remote::Token,
}

/// The I/O thread's shared-memory ports.
pub struct ShmPorts {
    /// The node the ports were made from.
    _node: IpcNode,
    /// Removes dead peers' resources every 20 ms on its own thread (the
    /// listing takes ~0.7 ms, which on this thread delayed the poses that
    /// came meanwhile).
    _reaper: Reaper,
    /// Poses.
    pose: iceoryx2::port::publisher::Publisher<Ipc, PoseMsg, ()>,
    /// The simulation's wake-up.
    ready: iceoryx2::port::notifier::Notifier<Ipc>,
    /// Telemetry.
    telemetry: iceoryx2::port::publisher::Publisher<Ipc, TelemetryBatch, ()>,
    /// The force service (its publishers: is a simulation there?).
    force: services::PortFactoryOf<ForceMsg>,
}

impl IoPorts {
    /// Opens the outputs on `transport`.
    pub fn open(transport: &Transport, session: &SessionName) -> Result<Self, TransportError> {
        Ok(match transport {
            Transport::Shm => {
                let node = services::node("haptic-daemon-io")?;
                IoPorts::Shm(Box::new(ShmPorts {
                    pose: services::publisher(&services::pose_service(&node, session)?)?,
                    ready: services::pose_ready_notifier(&node, session)?,
                    telemetry: services::publisher(&services::telemetry_service(&node, session)?)?,
                    force: services::force_service(&node, session)?,
                    _node: node,
                    _reaper: Reaper::spawn("haptic-daemon-reaper", REAP_EVERY)?,
                }))
            }
            Transport::Remote(link) => IoPorts::Remote(Box::new(RemotePorts {
                pose: link.publisher(services::stream::POSE)?,
                telemetry: link.publisher(services::stream::TELEMETRY)?,
                _token: link.declare_daemon()?,
                link: link.clone(),
            })),
        })
    }

    /// Publishes a pose and wakes the simulation.
    pub fn send_pose(&self, msg: PoseMsg) {
        match self {
            IoPorts::Shm(p) => {
                let _ = p.pose.send_copy(msg);
                let _ = p.ready.notify();
            }
            IoPorts::Remote(r) => {
                r.pose.put(msg);
            }
        }
    }

    /// Publishes a telemetry batch.
    pub fn send_telemetry(&self, batch: TelemetryBatch) {
        match self {
            IoPorts::Shm(p) => {
                let _ = p.telemetry.send_copy(batch);
            }
            IoPorts::Remote(r) => {
                r.telemetry.put(batch);
            }
        }
    }

    /// Whether a simulation publishes force samples (shared memory: its
    /// publisher, which a dead simulation keeps until the reaper's next
    /// pass, at most 20 ms later; zenoh: the bridge's token, gone with the
    /// link).
    pub fn sim_alive(&self) -> bool {
        match self {
            // A dead simulation's publisher leaves the count when the
            // reaper's next pass removes it.
            IoPorts::Shm(p) => services::publisher_count(&p.force) > 0,
            IoPorts::Remote(r) => r.link.sim_alive(),
        }
    }
}
