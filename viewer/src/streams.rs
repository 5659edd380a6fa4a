//! Where the viewer's messages come from: shared memory on the
//! simulation's host, or zenoh through `sim-server bridge` from another
//! host (`viewer --connect ENDPOINT`), touching no shared memory. The
//! session logic ([`crate::session`]) is the same for both.

use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use shared::SessionName;
use shared::protocol::{
    ForceMsg, MeshHeader, PoseMsg, RestHeader, SceneInfo, TelemetryBatch, TopologyHeader,
};
use shared::remote::{Link, RemoteError, SliceInbox};
use shared::services::{self, Ipc, ServiceError};
use shared::source::Source;
use std::sync::Arc;
use thiserror::Error;

/// Why the viewer could not join.
#[derive(Debug, Error)]
pub enum JoinError {
    /// Shared memory.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// zenoh.
    #[error(transparent)]
    Remote(#[from] RemoteError),
}

/// The slice streams on shared memory.
pub struct ShmSlices {
    /// Keeps the ports' node alive.
    _node: Node<Ipc>,
    mesh: Subscriber<Ipc, [[f32; 3]], MeshHeader>,
    topology: Subscriber<Ipc, [[u32; 3]], TopologyHeader>,
    rest: Subscriber<Ipc, [[f32; 3]], RestHeader>,
    surface0: Subscriber<Ipc, [[u32; 3]], TopologyHeader>,
    telemetry_factory: PortFactory<Ipc, TelemetryBatch, ()>,
    pose_factory: PortFactory<Ipc, PoseMsg, ()>,
}

/// The slice streams on zenoh.
pub struct RemoteSlices {
    link: Arc<Link>,
    mesh: SliceInbox<MeshHeader, [f32; 3]>,
    topology: SliceInbox<TopologyHeader, [u32; 3]>,
    rest: SliceInbox<RestHeader, [f32; 3]>,
    surface0: SliceInbox<TopologyHeader, [u32; 3]>,
}

/// The header-and-slice streams, by transport.
pub enum Slices {
    /// Same host.
    Shm(ShmSlices),
    /// Through a bridge.
    Remote(RemoteSlices),
}

/// Every stream the viewer reads.
pub struct Streams {
    /// Mesh, topology, rest, original surface (and, on shared memory, the
    /// ports the viewer counts publishers on).
    pub slices: Slices,
    /// Force samples.
    pub force: Source<ForceMsg>,
    /// Haptic telemetry.
    pub telemetry: Source<TelemetryBatch>,
    /// The scene's tools and organ.
    pub scene: Source<SceneInfo>,
}

impl Streams {
    /// Opens (or creates) the session's streams in shared memory.
    pub fn shm(session: &SessionName) -> Result<Self, JoinError> {
        let node = services::node("viewer")?;
        let telemetry_factory = services::telemetry_service(&node, session)?;
        Ok(Self {
            force: Source::Shm(services::subscriber_with_buffer(
                &services::force_service(&node, session)?,
                services::FORCE_BUFFER_LATEST,
            )?),
            telemetry: Source::Shm(services::subscriber(&telemetry_factory)?),
            scene: Source::Shm(services::subscriber(&services::scene_service(
                &node, session,
            )?)?),
            slices: Slices::Shm(ShmSlices {
                mesh: services::slice_subscriber(&services::mesh_service(&node, session)?)?,
                topology: services::slice_subscriber(&services::topology_service(&node, session)?)?,
                rest: services::slice_subscriber(&services::rest_service(&node, session)?)?,
                surface0: services::slice_subscriber(&services::surface0_service(&node, session)?)?,
                telemetry_factory,
                pose_factory: services::pose_service(&node, session)?,
                _node: node,
            }),
        })
    }

    /// Subscribes through `link` (a bridge answered it).
    pub fn remote(link: Arc<Link>) -> Result<Self, JoinError> {
        use services::stream;
        let inbox = |s| shared::remote::Inbox::subscribe(&link, s, 128);
        Ok(Self {
            // A frame's worth and more at 1 kHz: a full inbox refuses the
            // newest, so it must outlast the viewer's frame interval.
            force: Source::Remote(shared::remote::Inbox::subscribe(&link, stream::FORCE, 128)?),
            telemetry: Source::Remote(inbox(stream::TELEMETRY)?),
            scene: Source::Remote(shared::remote::Inbox::subscribe_with_query(
                &link,
                stream::SCENE,
                2,
            )?),
            slices: Slices::Remote(RemoteSlices {
                mesh: SliceInbox::subscribe(&link, stream::MESH)?,
                topology: SliceInbox::subscribe(&link, stream::TOPOLOGY)?,
                rest: SliceInbox::subscribe(&link, stream::REST)?,
                surface0: SliceInbox::subscribe(&link, stream::SURFACE0)?,
                link,
            }),
        })
    }
}

/// One header and its slice, handed to the session.
pub type Visit<'a, H, T> = &'a mut dyn FnMut(&H, &[T]);

impl Slices {
    /// Every new topology (shared memory: all of them; zenoh: the newest).
    pub fn topology(&self, f: Visit<'_, TopologyHeader, [u32; 3]>) {
        match self {
            Slices::Shm(s) => {
                while let Ok(Some(m)) = s.topology.receive() {
                    f(m.user_header(), m.payload());
                }
            }
            Slices::Remote(r) => {
                if let Some((h, v)) = r.topology.take() {
                    f(&h, &v);
                }
            }
        }
    }

    /// Every new mesh frame (zenoh: the newest).
    pub fn mesh(&self, f: Visit<'_, MeshHeader, [f32; 3]>) {
        match self {
            Slices::Shm(s) => {
                while let Ok(Some(m)) = s.mesh.receive() {
                    f(m.user_header(), m.payload());
                }
            }
            Slices::Remote(r) => {
                if let Some((h, v)) = r.mesh.take() {
                    f(&h, &v);
                }
            }
        }
    }

    /// The rest positions and fibres, when (re)published.
    pub fn rest(&self, f: Visit<'_, RestHeader, [f32; 3]>) {
        match self {
            Slices::Shm(s) => {
                while let Ok(Some(m)) = s.rest.receive() {
                    f(m.user_header(), m.payload());
                }
            }
            Slices::Remote(r) => {
                if let Some((h, v)) = r.rest.take() {
                    f(&h, &v);
                }
            }
        }
    }

    /// The original surface, when (re)published.
    pub fn surface0(&self, f: Visit<'_, TopologyHeader, [u32; 3]>) {
        match self {
            Slices::Shm(s) => {
                while let Ok(Some(m)) = s.surface0.receive() {
                    f(m.user_header(), m.payload());
                }
            }
            Slices::Remote(r) => {
                if let Some((h, v)) = r.surface0.take() {
                    f(&h, &v);
                }
            }
        }
    }

    /// Pose publishers in the session (None: unknown, through zenoh).
    pub fn pose_publishers(&self) -> Option<usize> {
        match self {
            Slices::Shm(s) => Some(s.pose_factory.dynamic_config().number_of_publishers()),
            Slices::Remote(_) => None,
        }
    }

    /// Whether a daemon publishes telemetry (None: unknown, through zenoh).
    pub fn daemon_present(&self) -> Option<bool> {
        match self {
            Slices::Shm(s) => Some(s.telemetry_factory.dynamic_config().number_of_publishers() > 0),
            Slices::Remote(_) => None,
        }
    }

    /// The shared-memory node and pose service (a viewer drives a tool
    /// only on the simulation's host).
    pub fn pose_port(&self) -> Option<&services::PoseService> {
        match self {
            Slices::Shm(s) => Some(&s.pose_factory),
            Slices::Remote(_) => None,
        }
    }

    /// Whether the bridge reports a simulation (None on shared memory).
    pub fn remote_sim_alive(&self) -> Option<bool> {
        match self {
            Slices::Shm(_) => None,
            Slices::Remote(r) => Some(r.link.sim_alive()),
        }
    }
}
