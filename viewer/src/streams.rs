//! Where the viewer's messages come from: shared memory on the
//! simulation's host, or zenoh through `sim-server bridge` from another
//! host (`viewer --connect ENDPOINT`), touching no shared memory. The
//! session logic ([`crate::session`]) is the same for both.

use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use shared::SessionName;
use shared::protocol::{
    ForceMsg, MeshHeader, PoseMsg, RestHeader, SceneInfo, TelemetryBatch, TopologyHeader,
};
use shared::remote::{Inbox, Link, RemoteError, SliceInbox};
use shared::services::{self, Ipc, ServiceError};
use shared::source::{SliceSource, Source};
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

/// Who else is in the session, as each transport can tell.
pub enum Peers {
    /// Shared memory: the services' publishers are counted.
    Shm {
        /// Keeps the ports' node alive.
        _node: Node<Ipc>,
        /// Telemetry (a daemon publishes it).
        telemetry: PortFactory<Ipc, TelemetryBatch, ()>,
        /// Poses (a daemon, or this viewer driving).
        pose: PortFactory<Ipc, PoseMsg, ()>,
    },
    /// zenoh: the bridge's token says whether a simulation is there.
    Remote(Arc<Link>),
}

/// Every stream the viewer reads.
pub struct Streams {
    /// Vertex positions.
    pub mesh: SliceSource<MeshHeader, [f32; 3]>,
    /// Surface triangles after cuts.
    pub topology: SliceSource<TopologyHeader, [u32; 3]>,
    /// Rest positions and fibres.
    pub rest: SliceSource<RestHeader, [f32; 3]>,
    /// The surface as built.
    pub surface0: SliceSource<TopologyHeader, [u32; 3]>,
    /// Force samples.
    pub force: Source<ForceMsg>,
    /// Haptic telemetry.
    pub telemetry: Source<TelemetryBatch>,
    /// The scene's tools and organ.
    pub scene: Source<SceneInfo>,
    /// Who else is there.
    pub peers: Peers,
}

impl Streams {
    /// Opens (or creates) the session's streams in shared memory.
    pub fn shm(session: &SessionName) -> Result<Self, JoinError> {
        let node = services::node("viewer")?;
        let telemetry = services::telemetry_service(&node, session)?;
        Ok(Self {
            mesh: SliceSource::Shm(services::slice_subscriber(&services::mesh_service(
                &node, session,
            )?)?),
            topology: SliceSource::Shm(services::slice_subscriber(&services::topology_service(
                &node, session,
            )?)?),
            rest: SliceSource::Shm(services::slice_subscriber(&services::rest_service(
                &node, session,
            )?)?),
            surface0: SliceSource::Shm(services::slice_subscriber(&services::surface0_service(
                &node, session,
            )?)?),
            force: Source::Shm(services::subscriber_with_buffer(
                &services::force_service(&node, session)?,
                services::FORCE_BUFFER_LATEST,
            )?),
            telemetry: Source::Shm(services::subscriber(&telemetry)?),
            scene: Source::Shm(services::subscriber(&services::scene_service(
                &node, session,
            )?)?),
            peers: Peers::Shm {
                telemetry,
                pose: services::pose_service(&node, session)?,
                _node: node,
            },
        })
    }

    /// Subscribes through `link` (a bridge answered it).
    pub fn remote(link: Arc<Link>) -> Result<Self, JoinError> {
        use services::stream;
        Ok(Self {
            mesh: SliceSource::Remote(SliceInbox::subscribe(&link, stream::MESH)?),
            topology: SliceSource::Remote(SliceInbox::subscribe(&link, stream::TOPOLOGY)?),
            rest: SliceSource::Remote(SliceInbox::subscribe(&link, stream::REST)?),
            surface0: SliceSource::Remote(SliceInbox::subscribe(&link, stream::SURFACE0)?),
            // A frame's worth and more at 1 kHz: a full inbox refuses the
            // newest, so it must outlast the viewer's frame interval.
            force: Source::Remote(Inbox::subscribe(&link, stream::FORCE, 128)?),
            telemetry: Source::Remote(Inbox::subscribe(&link, stream::TELEMETRY, 128)?),
            scene: Source::Remote(Inbox::subscribe_with_query(&link, stream::SCENE, 2)?),
            peers: Peers::Remote(link),
        })
    }
}

impl Peers {
    /// Pose publishers in the session (None: unknown, through zenoh).
    pub fn pose_publishers(&self) -> Option<usize> {
        match self {
            Peers::Shm { pose, .. } => Some(services::publisher_count(pose)),
            Peers::Remote(_) => None,
        }
    }

    /// Whether a daemon publishes telemetry (None: unknown, through zenoh).
    pub fn daemon_present(&self) -> Option<bool> {
        match self {
            Peers::Shm { telemetry, .. } => Some(services::publisher_count(telemetry) > 0),
            Peers::Remote(_) => None,
        }
    }

    /// The pose service (a viewer drives a tool only on the simulation's
    /// host).
    pub fn pose_port(&self) -> Option<&services::PoseService> {
        match self {
            Peers::Shm { pose, .. } => Some(pose),
            Peers::Remote(_) => None,
        }
    }

    /// Whether the bridge reports a simulation (None on shared memory).
    pub fn remote_sim_alive(&self) -> Option<bool> {
        match self {
            Peers::Shm { .. } => None,
            Peers::Remote(link) => Some(link.sim_alive()),
        }
    }
}
